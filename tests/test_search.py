"""The worst-case search (search/): loading errors, resume, a planted defect reported as a
falsified guaranteed row with a minimised reproduction, and the Dask path.

The base is test_sim_api's two-follower SMALL scenario with a 1 s horizon (its guaranteed
rows include Theorem 2's comparison-lemma envelope); budgets are a few evaluations.
"""

from __future__ import annotations

import json

import pandas as pd
import pytest
from helpers import SMALL

from core.scenario import load_scenario
from search import evaluate as EV
from search.minimise import MINIMISED, STATE
from search.run import local_executor, run_search
from search.spec import load_search
from sweep.study import StudyError

SEARCH = """
name = "tiny"
base = "small.toml"
seed = 7

[search]
budget = {budget}
baseline = {baseline}
batch = 4
minimise_steps = 2

[[requirements]]
name = "dev"
formula = "always[0.5, 1](deviation <= 100)"
scale = 100

[[requirements]]
name = "guaranteed"
guaranteed = true

[params]
"followers[1].p0" = {{ uniform = [0.0, 3.0], size = 2 }}
"followers[2].p0" = {{ uniform = [0.0, 3.0], size = 2 }}
"""


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory):
    """One build cache for the module: the library is compiled once."""
    return tmp_path_factory.mktemp("search-build")


@pytest.fixture
def root(tmp_path, monkeypatch, build_dir):
    (tmp_path / "small.toml").write_text(SMALL.replace("horizon = 0.5", "horizon = 1.0"))
    monkeypatch.setenv("HITL_BUILD_DIR", str(build_dir))
    monkeypatch.delenv("DASK_SCHEDULER", raising=False)
    return tmp_path


def write(root, budget=4, baseline=4, text=None):
    path = root / "s.toml"
    path.write_text(text if text is not None else SEARCH.format(budget=budget, baseline=baseline))
    return path


class Counting:
    """The local executor, counting the points it runs (and failing on call ``fail_at``)."""

    def __init__(self, fail_at=None):
        self.points, self.calls, self.fail_at = [], 0, fail_at

    def __call__(self, search, points, folder):
        self.calls += 1
        if self.calls == self.fail_at:
            raise KeyboardInterrupt
        self.points += [(p["arm"], p["eval"]) for p in points]
        return local_executor(search, points, folder)


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("budget = 4", "budget = 0", "search.budget"),
        ("budget = 4", "budget = 'x'", "search.budget"),
        ("batch = 4", "batch = 4\nsteps = 2", "search.steps"),
        ("scale = 100", "scale = -1", "requirements[1].scale"),
        ("deviation <= 100", "deviaton <= 100", "requirements[1].formula"),
        ("deviation <= 100", "deviation <=", "requirements[1].formula"),
        ('name = "guaranteed"\n', 'name = "dev"\n', "requirements.name"),
        ("guaranteed = true", "guaranteed = true\nformula = 'u <= 1'", "requirements[2]"),
        ("guaranteed = true", "guaranteed = 1", "requirements[2].guaranteed"),
        ('"followers[2].p0"', '"followers[3].p0"', 'params."followers[3].p0"'),
        ("[search]", "[searc]", "searc"),
    ],
)
def test_bad_fields_are_refused_in_one_line_naming_the_field(root, old, new, field):
    text = SEARCH.format(budget=4, baseline=4)
    assert old in text
    path = write(root, text=text.replace(old, new, 1))
    with pytest.raises(StudyError) as exc:
        load_search(path)
    msg = str(exc.value)
    assert field in msg and "\n" not in msg, msg


def test_missing_requirements_and_search_table(root):
    text = SEARCH.format(budget=4, baseline=4)
    with pytest.raises(StudyError, match="requirements"):
        load_search(
            write(
                root,
                text=text.split("[[requirements]]")[0]
                + text.split("[params]")[1].join(["[params]", ""]),
            )
        )
    with pytest.raises(StudyError, match="search"):
        load_search(
            write(
                root,
                text=text.replace("[search]", "[set]").replace(
                    "budget = 4\nbaseline = 4\nbatch = 4\nminimise_steps = 2\n", ""
                ),
            )
        )


def test_rows_resume_and_extend(root):
    # one requirement: 4 explored points and 1 baseline point, then one CMA-ES generation
    # of 4 points and the last baseline point
    text = SEARCH.format(budget=8, baseline=2).split('[[requirements]]\nname = "guaranteed"')
    text = text[0] + "[params]" + text[1].split("[params]")[1]
    text = text.replace("batch = 4\n", "batch = 4\nexplore = 0.5\n")
    first = Counting(fail_at=2)  # round 1 (4 explored + 1 baseline), then interrupted
    with pytest.raises(KeyboardInterrupt):
        run_search(write(root, text=text), out_root=root / "out", executor=first)
    results = root / "out/tiny/results.parquet"
    part = pd.read_parquet(results)
    assert sorted(zip(part["arm"], part["eval"], strict=True)) == sorted(first.points)
    assert len(first.points) == 5
    again = Counting()
    run_search(write(root, text=text), out_root=root / "out", executor=again)
    # only the points of round 2 are run (and then the minimisation, if any run violates)
    rounds = [p for p in again.points if p[0] != "minimise"]
    assert sorted(rounds) == [("baseline", 1)] + [("search", k) for k in range(4, 8)]
    full = pd.read_parquet(results)
    ucols = [c for c in full.columns if c.startswith("u:")]
    a = part.set_index(["arm", "eval"]).sort_index()[ucols]
    b = full.set_index(["arm", "eval"]).loc[a.index, ucols]
    assert (a.to_numpy() == b.to_numpy()).all()  # committed rows unchanged
    assert full["id"].is_unique and (full["status"] == "ok").all()
    assert {"rob:dev", "robustness"} <= set(full.columns) and "rob:guaranteed" not in full
    assert (full["rob:dev"].astype(float) == full["robustness"].astype(float)).all()
    targets = full[full["arm"] == "search"].sort_values("eval")["target"].tolist()
    assert targets == ["explore"] * 4 + ["dev"] * 4
    # a rerun of a finished search runs nothing
    idle = Counting()
    run_search(write(root, text=text), out_root=root / "out", executor=idle)
    assert idle.points == []
    assert (root / "out/tiny/report.md").is_file() and (
        root / "out/tiny/figures/robustness.png"
    ).is_file()


def _planted(factor):
    """The bound table with Theorem 2's envelope bound multiplied by ``factor`` < 1 and its
    verdict recomputed: a defect planted in a guaranteed row."""
    real = EV.verify_table

    def table(run):
        t = real(run).copy()
        hit = t["claim_id"].astype(str).str.startswith("t2.chi.envelope") & (
            t["kind"] == "guaranteed"
        )
        assert hit.any()  # the row exists in this scenario
        t.loc[hit, "bound"] = t.loc[hit, "bound"].astype(float) * factor
        t.loc[hit, "holds"] = t.loc[hit, "observed"].astype(float) <= t.loc[hit, "bound"]
        return t

    return table


def test_planted_defect_is_reported_first_with_a_minimised_reproduction(root, monkeypatch):
    path = write(root, budget=4, baseline=4)
    honest = run_search(path, out_root=root / "honest", executor=local_executor)
    clean = pd.read_parquet(honest)
    assert (clean["rob:guaranteed"].astype(float) >= 0).all()
    assert "DEFECT" not in (honest.parent / "report.md").read_text()

    monkeypatch.setattr(EV, "verify_table", _planted(0.01))
    results = run_search(path, out_root=root / "out", executor=local_executor)
    table = pd.read_parquet(results)
    found = table[table["arm"] != "minimise"]
    assert (found["rob:guaranteed"].astype(float) < 0).all()
    assert found["worst_row:guaranteed"].str.contains("envelope").all()
    # round(0.3 * 4) = 1 explored point, then one optimiser per requirement, each a last
    # (partial) generation of 2 for the 3 evaluations left
    targets = found.loc[found["arm"] == "search", "target"].value_counts().to_dict()
    assert targets == {"explore": 1, "dev": 2, "guaranteed": 2}
    report = (results.parent / "report.md").read_text()
    body = report.split("\n## ")
    assert body[1].startswith("DEFECT: a guaranteed row is falsified"), report
    assert "envelope" in body[1] and MINIMISED in body[1]
    state = json.loads((results.parent / STATE).read_text())
    assert state["requirement"] == "guaranteed" and state["robustness"] < 0
    # the reproduction is a scenario file the loader reads; evaluated again (planted
    # defect still in place), it still falsifies the row
    sc = load_scenario(results.parent / MINIMISED)
    assert sc.N == 2
    p0 = [list(map(float, f.p0)) for f in sc.followers]
    base = load_scenario(root / "small.toml")
    # the planted defect fails whatever p0 is: minimisation reverts both groups to the base
    assert state["dropped"] == ["followers[1].p0", "followers[2].p0"]
    assert p0 == [list(map(float, f.p0)) for f in base.followers]
    # a rerun reuses every committed evaluation, the minimisation's steps included
    idle = Counting()
    run_search(path, out_root=root / "out", executor=idle)
    assert idle.points == []


def test_the_dask_path_gives_the_rows_of_the_local_one(root):
    path = write(root, budget=4, baseline=1)
    dask = pd.read_parquet(run_search(path, out_root=root / "dask", workers=1))
    local = pd.read_parquet(run_search(path, out_root=root / "local", executor=local_executor))
    cols = ["arm", "eval", "status", "robustness", "rob:dev", "rob:guaranteed"]
    key = ["arm", "eval"]
    a = dask[cols].sort_values(key, ignore_index=True)
    b = local[cols].sort_values(key, ignore_index=True)
    pd.testing.assert_frame_equal(a, b)


C = [0.9, 0.15, 0.7, 0.35]


def bowl(search, points, folder):
    """An executor with a known minimum (no simulation): robustness is the distance of the
    point from :data:`C` in the unit box."""
    out = []
    for p in points:
        d = sum((a - b) ** 2 for a, b in zip(p["u"], C, strict=True)) ** 0.5
        row = {"id": EV.row_id(p["arm"], p["eval"]), "arm": p["arm"], "eval": p["eval"]}
        row |= {f"u:{k}": x for k, x in enumerate(p["u"])}
        row |= {"target": p.get("target", ""), "status": "ok", "rob:dev": d, "robustness": d}
        out.append(row)
    bowl.points += [(p["arm"], p["eval"]) for p in points]
    return out


def one_requirement(budget, baseline, extra=""):
    text = SEARCH.format(budget=budget, baseline=baseline)
    text = text.split('[[requirements]]\nname = "guaranteed"')
    text = text[0] + "[params]" + text[1].split("[params]")[1]
    return text.replace("batch = 4\n", "batch = 4\n" + extra)


def test_the_optimiser_descends_where_random_search_does_not(root):
    # CMA-ES started at the best explored point must get closer to C than the
    # exploration and than twice as many uniform points
    from search.run import _loop
    from search.space import sobol_points

    bowl.points = []
    search = load_search(write(root, text=one_requirement(120, 240, "sigma = 0.1\n")))
    results = root / "bowl.parquet"
    _loop(search, results, bowl, {}, popsize=8, progress=False)
    rows = pd.read_parquet(results)
    arm = rows.groupby(["arm", "target"])["robustness"].min().to_dict()
    assert (rows["arm"] == "search").sum() == 120 and (rows["arm"] == "baseline").sum() == 240
    assert arm[("search", "dev")] < arm[("search", "explore")]
    assert arm[("search", "dev")] < arm[("baseline", "")] / 2
    # the explored points are the Sobol' prefix of the seed
    explored = rows[rows["target"] == "explore"].sort_values("eval")
    want = sobol_points(7, 0, len(explored), 4)
    assert len(explored) == 36
    assert (explored[[f"u:{k}" for k in range(4)]].to_numpy() == want).all()


def test_a_rerun_with_another_seed_runs_its_own_points(root):
    # rows under the same name but of another seed are not told as this seed's
    from search.run import _known, _loop

    path = write(root, text=one_requirement(16, 8))
    results = root / "seeds.parquet"
    bowl.points = []
    _loop(load_search(path), results, bowl, {}, popsize=4, progress=False)
    first = len(bowl.points)
    bowl.points = []
    _loop(load_search(path, {"seed": 8}), results, bowl, {}, popsize=4, progress=False)
    assert len(bowl.points) == first == 24  # every point again: other coordinates
    rows = pd.read_parquet(results)
    assert len(rows) == 24 and rows["id"].is_unique
    bowl.points = []
    _loop(load_search(path, {"seed": 8}), results, bowl, {}, popsize=4, progress=False)
    assert bowl.points == [] and len(_known(rows)) == 24
    with pytest.raises(StudyError, match="search.batch"):
        load_search(path, {"batch": 8})
