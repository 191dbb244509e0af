"""The study runner: one row per sample on Dask, atomic batches, resume, refusals, schedulers.

The study is the two-follower SMALL scenario of test_sim_api (horizon 0.3 s) with random
initial positions p0 only: runtime values, so every sample runs the same compiled library.
"""

from __future__ import annotations

import tomllib

import pandas as pd
import pytest

from sweep.run import run_study
from sweep.sampler import samples
from sweep.study import load_study
from tests.test_sim_api import SMALL

STUDY = """
name = "tiny"
base = "small.toml"
count = 4
seed = 7

[params]
"followers[1].p0" = { uniform = [0.0, 1.0], size = 2 }
"followers[2].p0" = { uniform = [0.0, 1.0], size = 2 }
"""

#: columns that differ between two runs of the same sample (timing, not results)
TIMING = ["wall_s", "finished_utc"]


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    root = tmp_path_factory.mktemp("sweep")
    (root / "small.toml").write_text(SMALL.replace("horizon = 0.5", "horizon = 0.3"))
    (root / "study.toml").write_text(STUDY)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HITL_BUILD_DIR", str(root / "build"))  # inherited by the worker processes
        mp.delenv("DASK_SCHEDULER", raising=False)
        partial = run_study(root / "study.toml", out_root=root / "out", ids=[0, 2], batch=1)
        first = pd.read_parquet(partial)
        full = pd.read_parquet(run_study(root / "study.toml", out_root=root / "out", batch=3))
        yield {"root": root, "first": first, "full": full, "mp": mp}


def test_one_ok_row_per_sample_with_the_drawn_values(setup):
    full = setup["full"]
    assert sorted(full["id"]) == [0, 1, 2, 3]
    assert (full["status"] == "ok").all(), full["status"].tolist()
    # p0 is a runtime value: one library for the whole study
    assert full["library"].nunique() == 1 and len(full["library"].iloc[0]) == 64
    study = load_study(setup["root"] / "study.toml")
    for s in samples(study):
        row = full[full["id"] == s.id].iloc[0]
        assert row["seed"] == str(s.seed)
        for key, vals in s.params.items():
            assert [row[f"param:{key}[{k + 1}]"] for k in range(len(vals))] == vals
        # the written scenario file is the sample (read back by TOML, not by our code)
        written = tomllib.loads(
            (setup["root"] / f"out/tiny/samples/{row['name']}.toml").read_text()
        )
        assert written["followers"][0]["p0"] == s.params["followers[1].p0"]
    assert (full["steps"] > 0).all() and full["guaranteed_held"].all()
    assert (full["n_guaranteed"] >= 1).all()  # the T1 floor inequality row is guaranteed here


def test_resume_runs_only_the_missing_samples(setup):
    first, full = setup["first"], setup["full"]
    assert sorted(first["id"]) == [0, 2]
    assert full["id"].is_unique and len(full) == 4
    kept = full[full["id"].isin([0, 2])].reset_index(drop=True)
    # identical rows, timing included: the two finished samples were not recomputed
    pd.testing.assert_frame_equal(kept[first.columns], first.reset_index(drop=True))
    assert not list((setup["root"] / "out/tiny").glob("*.tmp"))
    report = (setup["root"] / "out/tiny/report.md").read_text()
    assert "| ok | 4 |" in report and "| failed | 0 |" in report


def test_rerun_of_a_finished_study_changes_nothing(setup):
    again = pd.read_parquet(run_study(setup["root"] / "study.toml", out_root=setup["root"] / "out"))
    pd.testing.assert_frame_equal(again, setup["full"])


def test_refused_sample_is_recorded_and_the_study_goes_on(setup):
    root = setup["root"]
    # alpha = 0.5 is below |u0| = |2 cos t| at t = 0: the loader refuses that sample
    text = STUDY.replace('name = "tiny"', 'name = "mixed"').replace("count = 4", "count = 6")
    text += '"leader.alpha" = { choice = [2.0, 0.5] }\n'
    (root / "mixed.toml").write_text(text)
    truth = {s.id: s.reason for s in samples(load_study(root / "mixed.toml"))}
    refused = [k for k, r in truth.items() if r]
    accepted = [k for k, r in truth.items() if not r]
    assert refused and accepted  # seed 7 draws both kinds
    ids = [refused[0], accepted[0]]
    res = pd.read_parquet(run_study(root / "mixed.toml", out_root=root / "out", ids=ids))
    rows = res.set_index("id")
    assert rows.loc[refused[0], "status"] == f"refused: {truth[refused[0]]}"
    assert rows.loc[accepted[0], "status"] == "ok"
    assert not (root / f"out/mixed/samples/mixed-{refused[0]:04d}.toml").exists()
    report = (root / "out/mixed/report.md").read_text()
    assert "| refused | 1 |" in report and f"- id {refused[0]}: refused:" in report


def test_explicit_scheduler_gives_the_same_rows(setup):
    from distributed import LocalCluster

    root = setup["root"]
    with LocalCluster(
        host="127.0.0.1",
        protocol="tcp",
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        dashboard_address=None,
    ) as cluster:
        setup["mp"].setenv("DASK_SCHEDULER", cluster.scheduler_address)
        try:
            res = pd.read_parquet(
                run_study(root / "study.toml", out_root=root / "remote", ids=[1, 3])
            )
        finally:
            setup["mp"].delenv("DASK_SCHEDULER")
    default = setup["full"][setup["full"]["id"].isin([1, 3])].reset_index(drop=True)
    cols = [c for c in default.columns if c not in TIMING]
    pd.testing.assert_frame_equal(res[cols], default[cols], check_exact=True)


def test_cli_bad_id_is_one_line_and_writes_nothing(setup, capsys):
    from core.errors import run_cli
    from sweep.__main__ import main

    root = setup["root"]
    status = run_cli(
        main, ["run", str(root / "study.toml"), "--out", str(root / "bad"), "--ids", "9"]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "--ids" in err[0] and "0..3" in err[0]
    assert not (root / "bad").exists()


def test_integrator_failure_is_recorded_and_the_study_goes_on(setup):
    root = setup["root"]
    # a step budget far below the ~17000 steps these runs take: CVODES gives up
    text = STUDY.replace('name = "tiny"', 'name = "starved"').replace("count = 4", "count = 2")
    text += '"integration.max_steps" = { choice = [10] }\n'
    (root / "starved.toml").write_text(text)
    res = pd.read_parquet(run_study(root / "starved.toml", out_root=root / "out"))
    assert sorted(res["id"]) == [0, 1]
    assert res["status"].str.startswith("failed: IntegrationError").all(), res["status"].tolist()
    report = (root / "out/starved/report.md").read_text()
    assert "| failed | 2 |" in report and "- id 1: failed: IntegrationError" in report


def test_unreachable_scheduler_is_one_error_naming_it(setup):
    import dask

    from core.errors import UsageError

    root = setup["root"]
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        with pytest.raises(UsageError, match=r"tcp://127\.0\.0\.1:1: cannot connect"):
            run_study(root / "study.toml", out_root=root / "nowhere", scheduler="tcp://127.0.0.1:1")
    assert not (root / "nowhere/tiny/results.parquet").exists()
