"""The study runner: one row per sample on Dask, atomic batches, resume, refusals, schedulers.

The study is the two-follower SMALL scenario of test_sim_api (horizon 0.3 s) with random
initial positions p0 only: runtime values, so every sample runs the same compiled library.
"""

from __future__ import annotations

import os
import tomllib

import pandas as pd
import pytest
from helpers import SMALL

from sweep.run import run_study
from sweep.sampler import samples
from sweep.study import load_study

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
TIMING = ["wall_s", "simulate_s", "checks_s", "finished_utc"]


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    root = tmp_path_factory.mktemp("sweep")
    (root / "small.toml").write_text(SMALL.replace("horizon = 0.5", "horizon = 0.3"))
    (root / "study.toml").write_text(STUDY)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HITL_BUILD_DIR", str(root / "build"))  # inherited by the worker processes
        mp.delenv("DASK_SCHEDULER", raising=False)
        partial = run_study(
            root / "study.toml", out_root=root / "out", ids=[0, 2], batch=1, keep=True
        )
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
        # ids 0 and 2 ran with keep=True: the written scenario file is the sample (read
        # back by TOML, not by our code); 1 and 3 ran in memory and wrote no file
        file = setup["root"] / f"out/tiny/samples/{row['name']}.toml"
        if s.id in (0, 2):
            written = tomllib.loads(file.read_text())
            assert written["followers"][0]["p0"] == s.params["followers[1].p0"]
            assert (setup["root"] / f"out/tiny/runs/{row['name']}/trajectory.csv").is_file()
        else:
            assert (
                not file.exists() and not (setup["root"] / f"out/tiny/runs/{row['name']}").exists()
            )
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


def test_explicit_scheduler_and_written_runs_give_the_same_rows(setup):
    """ids 1, 3 through a scheduler with keep=True (api.run, files), as one task of two
    samples, equal the local in-memory rows of the same samples (one sample per task)."""
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
                run_study(
                    root / "study.toml", out_root=root / "remote", ids=[1, 3], keep=True, chunk=2
                )
            )
        finally:
            setup["mp"].delenv("DASK_SCHEDULER")
    default = setup["full"][setup["full"]["id"].isin([1, 3])].reset_index(drop=True)
    cols = [c for c in default.columns if c not in TIMING]
    pd.testing.assert_frame_equal(res[cols], default[cols], check_exact=True)
    assert len(list((root / "remote/tiny/runs").glob("*/trajectory.csv"))) == 2


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


def test_local_cluster_settings_reach_the_workers_and_the_scheduler():
    """LOCAL_CLUSTER_CONFIG reaches the worker processes (through their nannies) and the
    scheduler's own timers: a setting that stayed in the client would change nothing."""
    import dask
    import distributed  # noqa: F401 - loads the distributed.* defaults

    from sweep.cluster import LOCAL_CLUSTER_CONFIG
    from sweep.cluster import close_client as _close
    from sweep.cluster import dask_client as _client

    keys = list(LOCAL_CLUSTER_CONFIG)
    assert (
        dask.config.get("distributed.admin.tick.interval")
        != LOCAL_CLUSTER_CONFIG["distributed.admin.tick.interval"]
    )  # else this test could not tell
    client = _client(None, 1)
    try:
        seen = client.run(lambda: [dask.config.get(k) for k in keys])
        env = client.run(
            lambda: {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")}
        )
        tick = client.cluster.scheduler.periodic_callbacks["tick"].callback_time
    finally:
        _close(client, True)
    assert list(seen.values()) == [[LOCAL_CLUSTER_CONFIG[k] for k in keys]]
    assert tick == 1000  # ms: "1s", not the default 20 ms
    # glibc's dynamic mmap threshold stays on (no trim threshold); one BLAS thread each
    assert list(env.values()) == [{"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1"}]


def test_killed_run_resumes_with_only_the_missing_samples(setup):
    """SIGKILL `python -m sweep run` after some rows are committed, rerun: the committed rows
    stay as they were (timing included), the others run once, none is lost or duplicated,
    and every row equals the uninterrupted run of the same draws."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from helpers import ROOT

    root = setup["root"]
    # same seed and keys as "tiny": ids 0..3 draw what the uninterrupted run drew
    (root / "killed.toml").write_text(
        STUDY.replace('name = "tiny"', 'name = "killed"').replace("count = 4", "count = 10")
    )
    results = root / "out/killed/results.parquet"
    cmd = [sys.executable, "-m", "sweep", "run", str(root / "killed.toml")]
    cmd += ["--out", str(root / "out"), "--batch", "1"]
    proc = subprocess.Popen(
        cmd, cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and proc.poll() is None:
            if results.is_file() and len(pd.read_parquet(results)) >= 2:
                break
            time.sleep(0.2)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the runner and its Dask workers, at once
        proc.wait()
    before = pd.read_parquet(results)
    assert 2 <= len(before) < 10, "the run must be killed part-way"
    assert before["id"].is_unique
    after = pd.read_parquet(run_study(root / "killed.toml", out_root=root / "out"))
    assert sorted(after["id"]) == list(range(10)) and after["id"].is_unique
    kept = after[after["id"].isin(before["id"])].reset_index(drop=True)
    pd.testing.assert_frame_equal(kept[before.columns], before.reset_index(drop=True))
    # the samples finished after the kill ran in the rerun: their finish time is later
    rerun = after[~after["id"].isin(before["id"])]
    assert (rerun["finished_utc"] >= before["finished_utc"].max()).all()
    truth = {s.id: s for s in samples(load_study(root / "killed.toml"))}
    for row in after.itertuples(index=False):
        assert row.seed == str(truth[row.id].seed)
    # identical draws and results to the uninterrupted "tiny" run (names differ)
    full = setup["full"].set_index("id")
    same = [c for c in full.columns if c not in [*TIMING, "name"]]
    got = after.set_index("id").loc[full.index, same]
    pd.testing.assert_frame_equal(got, full[same], check_exact=True)


def _report_table(text: str) -> dict[str, str]:
    """The summary table of report.md: quantity -> value."""
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
        if line.startswith("| ") and len(cells) == 2:
            rows[cells[0].replace("\\|", "|")] = cells[1]
    return rows


def test_report_numbers_and_figures_follow_from_the_results(setup):
    import numpy as np

    folder = setup["root"] / "out/tiny"
    res = pd.read_parquet(folder / "results.parquet")
    rows = _report_table((folder / "report.md").read_text())
    ok = res[res["status"] == "ok"]
    assert rows["samples"] == str(len(res)) and rows["ok"] == str(len(ok))
    # medians recomputed here from the Parquet file, printed to 4 significant digits
    for col, label in [
        ("tail_max_et", "median tail max |e_ti| (max over followers)"),
        ("peak_u_max", "median peak |u_i| (max over followers)"),
        ("steps", "median integrator steps"),
    ]:
        assert float(rows[label]) == pytest.approx(np.median(ok[col].astype(float)), rel=5e-4)
    t2 = ok[[c for c in ok.columns if c.startswith("t2_entry:")]].to_numpy(float).ravel()
    t2 = t2[np.isfinite(t2)]
    assert float(rows["median Theorem 2 entry time [s]"]) == pytest.approx(np.median(t2), rel=5e-4)
    held = int(ok["guaranteed_held"].sum())
    assert rows["ok samples whose guaranteed rows all hold"] == f"{held} of {len(ok)}"
    for fig in ("tail_error.png", "theorem2_entry.png"):
        data = (folder / "figures" / fig).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000


class _Future:
    def __init__(self, key, rows, crash):
        self.key, self._rows, self._crash = key, rows, crash

    def result(self):
        if self._crash:
            raise RuntimeError("worker died")
        return self._rows


class _Stream:
    """as_completed over futures that are already done, in submission order."""

    def __init__(self, futures):
        self._todo = list(futures)

    def add(self, fut):
        self._todo.append(fut)

    def count(self):
        return len(self._todo)

    def __iter__(self):
        while self._todo:
            yield self._todo.pop(0)


class _Client:
    """Runs nothing: a task's rows are its ids, and any task holding ``crash`` dies."""

    def __init__(self, crash):
        self.crash, self.tasks = crash, []

    def nthreads(self):
        return {"w1": 1, "w2": 1}

    def submit(self, fn, study, ids, folder, keep, key, pure):
        self.tasks.append(list(ids))
        rows = [{"id": k, "status": "ok"} for k in ids]
        return _Future(key, rows, self.crash in ids)


def test_a_crashing_chunk_is_rerun_sample_by_sample(tmp_path):
    """Only the sample whose task dies gets a failed row; every other id gets its own row
    once, and the chunk that held the crash is rerun one sample per task."""
    from sweep.results import StudyPaths
    from sweep.run import RunOptions, _results, chunk_size

    client = _Client(crash=6)
    todo = list(range(20))
    opts = RunOptions(chunk=4)
    rows = list(_results(client, _Stream, "s.toml", todo, StudyPaths(tmp_path), opts))
    assert sorted(r["id"] for r in rows) == todo
    bad = [r for r in rows if r["status"] != "ok"]
    assert [r["id"] for r in bad] == [6] and "worker died" in bad[0]["status"]
    assert [4, 5, 6, 7] in client.tasks and all([k] in client.tasks for k in (4, 5, 6, 7))
    assert max(len(t) for t in client.tasks) == 4
    # chunks: at least 4 tasks per worker thread, never more than MAX_CHUNK samples
    assert chunk_size(1000, 2) == 8 and chunk_size(20, 2) == 2 and chunk_size(3, 2) == 1


def test_checks_with_the_integrated_loop_equal_checks_that_bind_their_own(setup):
    """An in-memory sample hands the checks the closed loop it integrated (Run.closed_loop);
    the table equals, bit for bit, the one the checks get by binding the numbers themselves."""
    import dataclasses

    from sweep.results import StudyPaths
    from sweep.sampler import make_sample
    from sweep.worker import run_in_memory
    from verify.pipeline import verify_run

    root = setup["root"]
    sample = make_sample(load_study(root / "study.toml"), 1)
    run = run_in_memory(sample, StudyPaths(root / "bound"))
    assert run.closed_loop is not None and run.gains is not None
    own = verify_run(dataclasses.replace(run, closed_loop=None)).table
    pd.testing.assert_frame_equal(verify_run(run).table, own, check_exact=True)


def test_cost_times_lone_runs_and_study_tasks_of_the_same_samples(setup, tmp_path, capsys):
    """`python -m sweep cost`: one row per timed sample (the first id warms up), each task at
    least its simulating plus checking time; fewer than two valid ids is one line, exit 2."""
    import math

    from core.errors import run_cli
    from sweep.__main__ import main
    from sweep.cost import markdown, measure

    study = setup["root"] / "study.toml"
    costs = measure(study, [0, 1, 2], tmp_path)
    assert [c.id for c in costs] == [1, 2]
    for c in costs:
        assert all(math.isfinite(v) and v > 0 for v in (c.lone_s, c.task_s, c.simulate_s))
        assert c.task_s >= c.simulate_s + c.checks_s
    assert "| samples timed | 2 |" in markdown(costs)
    assert run_cli(main, ["cost", str(study), "--ids", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--ids" in err[0]


def _sweep_cli(argv: list[str], capsys) -> tuple[int, list[str]]:
    """``python -m sweep`` in-process: the exit status and stderr's lines without tqdm's."""
    from core.errors import run_cli
    from sweep.__main__ import main

    status = run_cli(main, argv)
    err = capsys.readouterr().err.replace("\r", "\n").splitlines()
    return status, [e for e in err if e.strip() and not e.startswith("samples:")]


def test_failed_samples_fail_the_command_and_a_rerun_retries_them(setup, capsys):
    """Failed rows make `sweep run` exit 1 with one line; a rerun runs them again (and
    only them), the report says how many; refused and ok rows are final."""
    root = setup["root"]
    good = STUDY.replace('name = "tiny"', 'name = "retry"').replace("count = 4", "count = 3")
    study = root / "retry.toml"
    argv = ["run", str(study), "--out", str(root / "out"), "--workers", "1"]
    study.write_text(good)
    assert _sweep_cli([*argv, "--ids", "0"], capsys) == (0, [])
    first = pd.read_parquet(root / "out/retry/results.parquet")
    # the same study with a build cache the workers cannot use (a file, not a folder):
    # ids 1 and 2 fail (a changed study would be refused: docs/studies.md, 'Identity')
    (root / "not-a-folder").write_text("")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HITL_BUILD_DIR", str(root / "not-a-folder"))  # inherited by the workers
        status, err = _sweep_cli(argv, capsys)
    assert status == 1 and len(err) == 1, err
    assert err[0].startswith("study faults: 2 of 3 samples failed; first (id 1): ")
    assert err[0].endswith(f"rerun `make sweep SWEEP={study}` retries them")
    failed = pd.read_parquet(root / "out/retry/results.parquet").set_index("id")
    assert failed.loc[0, "finished_utc"] == first.loc[0, "finished_utc"]  # ok is final
    report = root / "out/retry/report.md"
    assert "Retried in this run: 0 samples" in report.read_text()
    assert _sweep_cli(argv, capsys) == (0, [])
    again = pd.read_parquet(root / "out/retry/results.parquet").set_index("id")
    assert (again["status"] == "ok").all() and again.index.is_unique and len(again) == 3
    assert again.loc[0, "finished_utc"] == first.loc[0, "finished_utc"]
    assert "Retried in this run: 2 samples" in report.read_text()
    assert _sweep_cli(argv, capsys) == (0, [])  # nothing left to run: nothing retried
    assert "Retried in this run: 0 samples" in report.read_text()


def test_refused_samples_are_final_and_do_not_fail_the_command(setup, capsys):
    root = setup["root"]
    text = STUDY.replace('name = "tiny"', 'name = "allrefused"').replace("count = 4", "count = 2")
    # operator amplitudes above leader.alpha = 2: the loader refuses every drawn sample (a
    # refusal of the study's own keys, e.g. leader.alpha = 0.5 in [params], fails at load)
    operator = '[operator]\nu0 = ["A*cos(t)"]\nparams = { A = { uniform = [3.0, 4.0] } }\n'
    (root / "allrefused.toml").write_text(text + operator)
    argv = ["run", str(root / "allrefused.toml"), "--out", str(root / "out"), "--workers", "1"]
    assert _sweep_cli(argv, capsys) == (0, [])
    rows = pd.read_parquet(root / "out/allrefused/results.parquet")
    assert rows["status"].str.startswith("refused").all()
    assert _sweep_cli(argv, capsys) == (0, [])
    again = pd.read_parquet(root / "out/allrefused/results.parquet")
    pd.testing.assert_frame_equal(again, rows)  # not run again


def _listening_ports(pid: int) -> set[int]:
    import psutil

    conns = psutil.Process(pid).net_connections("inet")
    return {c.laddr.port for c in conns if c.status == psutil.CONN_LISTEN}


def test_local_cluster_serves_no_http():
    """The study's local cluster listens only on Dask's own TCP ports (scheduler, nannies,
    workers), all on 127.0.0.1: no HTTP server, none on 8787, in any of its processes."""
    from sweep.cluster import close_client as _close
    from sweep.cluster import dask_client as _client

    client = _client(None, 2)
    try:
        info = client.scheduler_info()
        workers = info["workers"]
        dask_ports = {int(info["address"].rsplit(":", 1)[1])}
        dask_ports |= {int(a.rsplit(":", 1)[1]) for a in workers}
        dask_ports |= {int(w["nanny"].rsplit(":", 1)[1]) for w in workers.values()}
        pids = [os.getpid(), *client.run(os.getpid).values()]
        seen = set().union(*(_listening_ports(p) for p in pids))
        assert client.submit(sum, [1, 2]).result() == 3
    finally:
        _close(client, True)
    assert seen == dask_ports, seen - dask_ports
    assert all(a.startswith("tcp://127.0.0.1:") for a in [info["address"], *workers])
    assert 8787 not in seen and len(seen) == 1 + 2 * len(workers)
