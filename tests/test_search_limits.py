"""Search files at their limits: deep or huge formulas, a space with nothing to vary, and
requirements whose robustness is infinite, each refused in one line or reported.

No simulation: the runs are scored by a stand-in executor that evaluates the real STL
formulas (:mod:`search.stl`) on a closed-form deviation, so the loop, the results and
the report are the search's own.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from helpers import SMALL

from core.errors import run_cli
from search import evaluate as EV
from search import stl
from search.__main__ import main as search_main
from search.report import plot
from search.run import run_search
from search.spec import load_search
from sweep.study import StudyError

SEARCH = """
name = "limits"
base = "small.toml"
seed = 3

[search]
budget = 6
baseline = 4
batch = 4
minimise_steps = 1

[[requirements]]
name = "req"
formula = "{formula}"
{params}
"""
PARAMS = """
[params]
"followers[1].p0" = { uniform = [0.0, 3.0], size = 2 }
"""
SIGNALS = {"deviation", "u"}


def write(tmp_path, formula="always[0.5, 1](deviation <= 1)", params=PARAMS):
    (tmp_path / "small.toml").write_text(SMALL.replace("horizon = 0.5", "horizon = 1.0"))
    path = tmp_path / "s.toml"
    path.write_text(SEARCH.format(formula=formula, params=params))
    return path


@pytest.mark.parametrize(
    "formula",
    [
        "(" * 5000 + "deviation <= 1" + ")" * 5000,
        "not " * 5000 + "deviation <= 1",
        "always[0, 1] " * 3000 + "deviation <= 1",
    ],
)
def test_deep_formulas_are_refused_by_the_depth_limit(formula):
    with pytest.raises(stl.FormulaError, match=f"nested more than {stl.MAX_DEPTH} levels"):
        stl.parse(formula, SIGNALS)


def test_formula_at_the_depth_limit_parses_and_evaluates():
    d = stl.MAX_DEPTH
    t = np.linspace(0, 1, 11)
    x = np.linspace(0, 2, 11)
    node = stl.parse("not " * (d - 1) + "deviation <= 1", SIGNALS)  # the comparison: level d
    expect = (1 - x[0]) * (-1) ** (d - 1)  # each not negates
    assert stl.robustness(node, t, {"deviation": x}) == pytest.approx(expect)
    with pytest.raises(stl.FormulaError, match="nested"):
        stl.parse("not " * (d - 1) + "(deviation <= 1)", SIGNALS)


def test_long_chains_are_flat_and_exact():
    """400 conjuncts: one node, the least of the comparisons (a direct numpy minimum)."""
    cs = np.linspace(-1, 3, 400)
    node = stl.parse(" and ".join(f"deviation <= {float(c)!r}" for c in cs), SIGNALS)
    assert node.op == "and" and len(node.args) == 400
    t = np.linspace(0, 1, 5)
    x = np.array([0.25, 1, 2, 3, 4])
    assert stl.robustness(node, t, {"deviation": x}) == pytest.approx(np.min(cs - x[0]))
    node = stl.parse(" or ".join(f"deviation <= {float(c)!r}" for c in cs), SIGNALS)
    assert stl.robustness(node, t, {"deviation": x}) == pytest.approx(np.max(cs - x[0]))


def test_twenty_thousand_atoms_are_refused_before_any_folder(tmp_path, capsys):
    formula = " and ".join(["deviation <= 1"] * 20_000)
    path = write(tmp_path, formula=formula)
    out = tmp_path / "out"
    assert run_cli(search_main, ["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "requirements[1].formula" in err and "characters" in err
    assert not out.exists()
    path.write_text(SEARCH.format(formula=" and ".join(["deviation <= 1"] * 600), params=PARAMS))
    with pytest.raises(StudyError, match=f"more than {stl.MAX_ATOMS} comparisons"):
        load_search(path)


def test_nothing_to_vary_is_refused_at_load(tmp_path, capsys):
    path = write(tmp_path, params="")
    out = tmp_path / "out"
    assert run_cli(search_main, ["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "nothing to vary" in err and "[params]" in err
    assert not out.exists()


def _scored(search, points, folder):
    """Rows as :func:`search.evaluate.evaluate` makes them, the deviation in closed form:
    d(t) = |u| e^{-t} on 0..1 s, scored by the search's own formulas."""
    t = np.linspace(0.0, 1.0, 21)
    rows = []
    for p in points:
        u = np.asarray(p.get("u") or [0.5], float)
        values = {"deviation": float(np.linalg.norm(u)) * np.exp(-t)}
        row = {
            "id": EV.row_id(p["arm"], p["eval"]),
            "arm": p["arm"],
            "eval": p["eval"],
            "name": f"{search.name}-{p['arm']}-{p['eval']:04d}",
            "target": p.get("target", ""),
            **{f"u:{k}": float(x) for k, x in enumerate(p.get("u") or ())},
        }
        for r in search.requirements:
            row[f"rob:{r.name}"] = stl.robustness(r.node, t, values) / r.scale
        row["robustness"] = min(row[f"rob:{r.name}"] for r in search.requirements)
        row["status"] = EV.unscored(search.requirements, row) or "ok"
        rows.append(row)
    return rows


@pytest.mark.parametrize(
    ("formula", "value"),
    [("always[5, 6](deviation <= 1)", "+inf"), ("eventually[5, 6](deviation <= 1)", "-inf")],
)
def test_infinite_robustness_is_reported_not_a_traceback(tmp_path, formula, value):
    path = write(tmp_path, formula=formula)
    results = run_search(path, out_root=tmp_path / "out", executor=_scored, progress=False)
    table = pd.read_parquet(results)
    assert len(table) == 10 and set(table["status"]) == {
        f"unscored: req robustness is {value}: a time window of its formula holds no sample "
        "(past the horizon)"
    }
    report = (results.parent / "report.md").read_text()
    assert "## Runs a requirement cannot score" in report
    assert f"| 10 | req robustness is {value}" in report
    assert (results.parent / "figures" / "robustness.png").stat().st_size > 0
    assert "No evaluation finished." in report


def test_plot_of_rows_with_infinite_robustness(tmp_path):
    """Results of infinite robustness marked ``ok`` (as written before they were unscored)."""
    table = pd.DataFrame(
        {
            "arm": ["search", "baseline"],
            "eval": [0, 0],
            "status": ["ok", "ok"],
            "robustness": [math.inf, math.inf],
        }
    )
    assert plot(table, tmp_path / "r.png").stat().st_size > 0


def test_finite_requirements_still_score(tmp_path):
    path = write(tmp_path)
    results = run_search(path, out_root=tmp_path / "out", executor=_scored, progress=False)
    table = pd.read_parquet(results)
    assert (table["status"] == "ok").all()
    # always[0.5, 1](d <= 1): 1 - max over [0.5, 1] of |u| e^-t = 1 - |u| e^-0.5
    us = table[[c for c in table.columns if c.startswith("u:")]].to_numpy(float)
    expect = 1 - np.linalg.norm(us, axis=1) * np.exp(-0.5)
    ok = table["arm"].isin(["search", "baseline"]).to_numpy()
    np.testing.assert_allclose(table["rob:req"].to_numpy(float)[ok], expect[ok], rtol=1e-12)


def test_an_unreachable_cluster_leaves_no_folder(tmp_path, monkeypatch):
    """The cluster is asked for before ``out/<name>/`` is made: a bad address writes nothing."""
    path = write(tmp_path)
    monkeypatch.setenv("DASK_SCHEDULER", "garbage")
    with pytest.raises(Exception):  # noqa: B017 - the scheduler's own error (sweep.cluster)
        run_search(path, out_root=tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()


def test_an_infinite_constant_is_refused():
    with pytest.raises(stl.FormulaError, match="give a finite number"):
        stl.parse("deviation <= 1e999", SIGNALS)
    with pytest.raises(stl.FormulaError, match="give a finite number"):
        stl.parse("-1e400 < u", SIGNALS)
