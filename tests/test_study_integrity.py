"""A study's results cannot be lost or misread, and its bad input is one line (docs/studies.md).

Two runs of one study into one folder: the folder's lock lets one of them in, the other is
refused in one line, and no row is lost. The folder records the study's identity; a
changed study under the same name is refused. A results file that is not a results table
is refused and kept. Written sample scenarios are plain TOML. A study file every sample
of which would be refused fails at load; a bad flag of ``python -m sweep`` is one line,
exit 2, before any file.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest
from helpers import PAPER, ROOT

import sweep.run
from core.errors import run_cli
from core.scenario import load_scenario
from sweep.__main__ import main
from sweep.identity import check_identity
from sweep.lock import LOCK, StudyLocked, study_lock
from sweep.results import commit_rows, read_results
from sweep.sampler import samples, write_scenario
from sweep.study import load_study, read_study_file

#: every sample refused by the loader (amplitude above leader.alpha = 2): a run of it
#: writes rows without simulating anything
REFUSED = """name = "{name}"
base = "{base}"
count = {count}
seed = {seed}

[operator]
u0 = ["A*cos(t)"]
params = {{ A = {{ uniform = [3.0, {hi}] }} }}
"""


def _study(folder: Path, name: str = "s", count: int = 16, seed: int = 1, hi: float = 4.0) -> Path:
    path = folder / f"{name}-{seed}-{hi}.toml"
    path.write_text(REFUSED.format(name=name, base=PAPER.as_posix(), count=count, seed=seed, hi=hi))
    return path


def _one_line(capsys, code: int, expected: int = 2) -> str:
    """The single stderr line of a command that returned ``code``."""
    err = capsys.readouterr().err
    assert code == expected, err
    assert err.count("\n") == 1 and err.startswith("error: "), err
    return err


def _rows(n_ids: range) -> list[dict]:
    return [{"id": k, "status": "refused: test", "seed": str(k)} for k in n_ids]


def _recorded(tmp_path: Path, study: Path) -> Path:
    """A study folder as a run of ``study`` leaves it: its identity and rows of ids 0..3."""
    folder = tmp_path / "out" / load_study(study).name
    folder.mkdir(parents=True)
    check_identity(folder, load_study(study), has_results=False)
    commit_rows(folder / "results.parquet", pd.DataFrame(), _rows(range(4)), {})
    return folder


# --------------------------------------------------------------------------- lock
@pytest.mark.slow
def test_two_runs_at_once_lose_no_row(tmp_path):
    study = _study(tmp_path)
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "DASK_SCHEDULER"}

    def start(ids: range) -> subprocess.Popen:
        argv = ["run", str(study), "--out", str(out), "--workers", "1", "--ids"]
        return subprocess.Popen(
            [sys.executable, "-m", "sweep", *argv, *map(str, ids)],
            cwd=tmp_path,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    halves = (range(0, 8), range(8, 16))
    procs = [start(h) for h in halves]  # both at once: whichever locks first runs
    done = [p.communicate(timeout=300) for p in procs]
    codes = [p.returncode for p in procs]
    table = read_results(out / "s" / "results.parquet")
    ids = sorted(int(k) for k in table["id"])
    if codes == [0, 0]:  # the second started after the first had finished
        assert ids == list(range(16))
        return
    assert sorted(codes) == [0, 2], done
    loser = codes.index(2)
    err = done[loser][1]
    lines = [x for x in err.splitlines() if x.startswith("error: ")]
    assert len(lines) == 1 and "in use by another run" in lines[0], err
    assert f"PID {procs[1 - loser].pid}" in lines[0] and "--out DIR" in lines[0]
    assert ids == list(halves[1 - loser])  # the winner's rows, each once
    assert not list((out / "s").glob("*.tmp")) and not list((out / "s").glob(".*.tmp"))


def test_second_holder_of_a_study_folder_is_refused_in_one_line(tmp_path, capsys):
    study = _study(tmp_path)
    folder = _recorded(tmp_path, study)
    before = (folder / "results.parquet").read_bytes()
    with study_lock(folder):
        code = run_cli(main, ["run", str(study), "--out", str(tmp_path / "out")])
        err = _one_line(capsys, code)
    assert f"PID {os.getpid()}" in err and "in use by another run" in err and "--out DIR" in err
    assert (folder / "results.parquet").read_bytes() == before


def test_lock_of_a_dead_process_is_reclaimed(tmp_path):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    (tmp_path / LOCK).write_text(f"{gone.pid} somehost\n")
    with study_lock(tmp_path) as path:
        assert path.read_text().split()[0] == str(os.getpid())
        with pytest.raises(StudyLocked, match=f"PID {os.getpid()}"):
            with study_lock(tmp_path):
                pass
    with study_lock(tmp_path):  # released at the end of the block
        pass


def test_writers_of_one_results_file_never_share_a_temporary_file(tmp_path):
    path = tmp_path / "results.parquet"
    errors: list[BaseException] = []
    start = threading.Barrier(6)

    def writer(k: int) -> None:
        start.wait()
        try:
            for j in range(15):
                commit_rows(path, pd.DataFrame(), _rows(range(k * 100, k * 100 + j + 1)), {})
        except BaseException as exc:  # noqa: BLE001 - collected for the assertion
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    last = read_results(path)  # one writer's complete table
    assert len(last) == 15 and len({int(k) // 100 for k in last["id"]}) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.parquet"]


# --------------------------------------------------------------------------- identity
CHANGES = [
    ("seed", {"seed": 2}, "seed 1 -> 2"),
    ("operator range", {"hi": 5.0}, "[operator]"),
]


@pytest.mark.parametrize(("what", "change", "named"), CHANGES, ids=[c[0] for c in CHANGES])
def test_changed_study_under_its_old_name_is_refused(tmp_path, capsys, what, change, named):
    folder = _recorded(tmp_path, _study(tmp_path))
    before = (folder / "results.parquet").read_bytes()
    changed = _study(tmp_path, **change)
    err = _one_line(capsys, run_cli(main, ["run", str(changed), "--out", str(folder.parent)]))
    assert named in err and "--restart" in err and "--out DIR" in err and "`name`" in err
    assert (folder / "results.parquet").read_bytes() == before


def test_changed_params_set_and_base_are_named(tmp_path, capsys):
    base = tmp_path / "base.toml"
    base.write_bytes(PAPER.read_bytes())
    head = f'name = "p"\nbase = "{base.as_posix()}"\ncount = 4\nseed = 1\n'
    first = tmp_path / "first.toml"
    first.write_text(head + '[params]\n"controller.k1" = { uniform = [15.0, 25.0] }\n')
    folder = _recorded(tmp_path, first)
    cases = [
        ('[params]\n"controller.k1" = { uniform = [15.0, 26.0] }\n', "[params]"),
        (
            '[set]\n"controller.k2" = 2.5\n[params]\n"controller.k1" = { uniform = [15.0, 25.0] }\n',
            "[set]",
        ),
    ]
    for body, named in cases:
        other = tmp_path / "other.toml"
        other.write_text(head + body)
        err = _one_line(capsys, run_cli(main, ["run", str(other), "--out", str(folder.parent)]))
        assert named in err, err
    base.write_text(PAPER.read_text() + "\n# edited\n")
    err = _one_line(capsys, run_cli(main, ["run", str(first), "--out", str(folder.parent)]))
    assert "base scenario (SHA-256)" in err


def test_results_without_a_recorded_identity_are_refused(tmp_path, capsys):
    study = _study(tmp_path)
    folder = tmp_path / "out" / "s"
    commit_rows(folder / "results.parquet", pd.DataFrame(), _rows(range(4)), {})
    err = _one_line(capsys, run_cli(main, ["run", str(study), "--out", str(folder.parent)]))
    assert "study.json" in err and "--restart" in err


def _fake_execute(pause: float = 0.0):
    """``sweep.run._execute`` without Dask: each pending id gets a refused row, committed
    two at a time (``pause`` seconds apart) as the real one commits its batches."""

    def execute(study_path, todo, paths, done, info, opts) -> None:  # noqa: ANN001
        for k in range(0, len(todo), 2):
            time.sleep(pause)
            done = commit_rows(paths.results, done, _rows(todo[k : k + 2]), info)
        if not todo:
            commit_rows(paths.results, done, [], info)

    return execute


def test_restart_discards_the_old_results_and_an_unchanged_study_resumes(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr(sweep.run, "_execute", _fake_execute())
    old = _study(tmp_path, count=3)
    out = tmp_path / "out"
    folder = _recorded(tmp_path, old)  # ids 0..3 of the old study
    (folder / "runs").mkdir()
    new = _study(tmp_path, count=3, seed=2)
    argv = ["run", str(new), "--out", str(out)]
    _one_line(capsys, run_cli(main, argv))  # changed: refused
    assert run_cli(main, [*argv, "--restart"]) == 0, capsys.readouterr().err
    table = read_results(folder / "results.parquet")
    assert sorted(int(k) for k in table["id"]) == [0, 1, 2]  # id 3 of the old study is gone
    assert not (folder / "runs").exists()
    # the same study again: accepted, nothing run again
    assert run_cli(main, argv) == 0, capsys.readouterr().err
    assert read_results(folder / "results.parquet")["id"].tolist() == [0, 1, 2]
    # and the old study is now the changed one
    _one_line(capsys, run_cli(main, ["run", str(old), "--out", str(out)]))


def test_two_runs_at_once_in_threads_lose_no_row(tmp_path, monkeypatch):
    monkeypatch.setattr(sweep.run, "_execute", _fake_execute(pause=0.02))
    study = _study(tmp_path)
    outcome: dict[int, object] = {}
    start = threading.Barrier(2)

    def run(k: int, ids: range) -> None:
        start.wait()
        try:
            outcome[k] = sweep.run.run_study(study, tmp_path / "out", ids=ids)
        except StudyLocked as exc:
            outcome[k] = exc

    halves = (range(0, 8), range(8, 16))
    threads = [threading.Thread(target=run, args=(k, h)) for k, h in enumerate(halves)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    ids = sorted(int(k) for k in read_results(tmp_path / "out" / "s" / "results.parquet")["id"])
    refused = [k for k, v in outcome.items() if isinstance(v, StudyLocked)]
    if not refused:
        assert ids == list(range(16))
    else:
        assert len(refused) == 1 and "\n" not in str(outcome[refused[0]])
        assert ids == list(halves[1 - refused[0]])


# --------------------------------------------------------------------------- corrupt results
def _truncated(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _foreign(path: Path) -> None:
    pd.DataFrame({"a": [1, 2], "b": ["x", "y"]}).to_parquet(path)


def _text(path: Path) -> None:
    path.write_text("id,status\n0,ok\n")


@pytest.mark.parametrize("spoil", [_truncated, _foreign, _text])
def test_corrupt_results_are_refused_and_kept(tmp_path, capsys, spoil):
    study = _study(tmp_path)
    folder = _recorded(tmp_path, study)
    spoil(folder / "results.parquet")
    before = (folder / "results.parquet").read_bytes()
    err = _one_line(capsys, run_cli(main, ["run", str(study), "--out", str(folder.parent)]))
    assert "results.parquet" in err and "--restart" in err
    assert (folder / "results.parquet").read_bytes() == before


def test_results_path_that_is_a_fifo_is_refused_unread(tmp_path, capsys):
    study = _study(tmp_path)
    folder = tmp_path / "out" / "s"
    folder.mkdir(parents=True)
    os.mkfifo(folder / "results.parquet")
    err = _one_line(capsys, run_cli(main, ["run", str(study), "--out", str(folder.parent)]))
    assert "FIFO" in err


# --------------------------------------------------------------------------- written scenarios
#: the shipped studies (search files, which hold a [search] table, are not studies)
STUDIES = sorted(p for p in (ROOT / "studies").glob("*.toml") if "search" not in read_study_file(p))


def test_written_scenarios_of_every_shipped_study_are_plain_toml(tmp_path, stored_designs):
    switches = 0
    for path in STUDIES:
        study = load_study(path)
        ids = range(min(4, study.count))
        for s in samples(study, ids):
            if s.scenario is None:
                continue
            file = write_scenario(s, tmp_path / study.name)
            assert tomllib.loads(file.read_text()) == s.scenario_data, file
            assert load_scenario(file).name == s.scenario.name
            switches += len(s.scenario_data.get("graph", {}).get("switches", []))
    assert switches > 0  # a study with link losses wrote restored links' weights


# --------------------------------------------------------------------------- study files
WRONG = [
    ('[params]\n"bogus.x" = { uniform = [1.0, 2.0] }\n', 'params."bogus.x"'),
    ('[params]\n"__class__.__init__" = { uniform = [1.0, 2.0] }\n', 'params."__class__.__init__"'),
    ('[set]\n"integration.horizon" = -2\n', 'set."integration.horizon"'),
    ('[params]\n"followers[1].p0" = { uniform = [1.0, 2.0], size = 3 }\n', "followers[1].p0"),
    ('[params]\n"controller.k1" = { choice = [{ choice = [1.0, 2.0] }] }\n', "controller.k1"),
    ('[params]\n"controller.k1" = { uniform = [-3.0, -1.0] }\n', "controller.k1"),
]


@pytest.mark.parametrize(("body", "key"), WRONG, ids=[k for _, k in WRONG])
def test_study_wrong_as_a_whole_fails_at_load(tmp_path, capsys, body, key):
    path = tmp_path / "w.toml"
    path.write_text(f'base = "{PAPER.as_posix()}"\ncount = 3\nseed = 1\n{body}')
    written = tmp_path / "written"
    code = run_cli(main, ["samples", str(path), "--write-scenarios", str(written)])
    assert key in _one_line(capsys, code)
    assert not written.exists()


def test_a_range_partly_refused_still_loads(tmp_path):
    # k1 > 0 is required: a range across 0 leaves samples the loader accepts
    path = tmp_path / "p.toml"
    path.write_text(
        f'base = "{PAPER.as_posix()}"\ncount = 6\nseed = 1\n'
        '[params]\n"controller.k1" = { uniform = [-1.0, 20.0] }\n'
    )
    got = list(samples(load_study(path)))
    assert any(s.reason is None for s in got)


# --------------------------------------------------------------------------- command lines
def test_bad_scheduler_address_is_one_line_and_writes_nothing(tmp_path, capsys, monkeypatch):
    study = _study(tmp_path)
    for address in ("garbage", "tcp://host:99999", "bogus://host:1"):
        monkeypatch.setenv("DASK_SCHEDULER", address)
        err = _one_line(capsys, run_cli(main, ["run", str(study), "--out", str(tmp_path / "o")]))
        assert "DASK_SCHEDULER" in err
        assert not (tmp_path / "o").exists()


BAD_FLAGS = [
    ["run", "{study}", "--batch", "0"],
    ["run", "{study}", "--workers", "0"],
    ["run", "{study}", "--chunk", "0"],
    ["run", "{study}", "--ids", "16"],
    ["run", "{study}", "--ids", "x"],
    ["run", "{study}", "--out", ""],
    ["run", "{study}", "--bogus"],
    ["run"],
    ["samples", "{study}", "--ids", "-1"],
    ["cost", "{study}", "--ids", "99"],
    ["nope"],
    [],
]


@pytest.mark.parametrize("argv", BAD_FLAGS, ids=[" ".join(a) or "(none)" for a in BAD_FLAGS])
def test_bad_flags_of_sweep_are_one_line_before_any_file(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    study = _study(tmp_path)
    argv = [a.format(study=study) for a in argv]
    if argv[:1] == ["run"] and "--out" not in argv:
        argv += ["--out", "o"]
    _one_line(capsys, run_cli(main, argv))
    assert sorted(p.name for p in tmp_path.iterdir()) == [study.name]


def test_a_bad_theorem1_of_graph_losses_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = (ROOT / "studies" / "topologies.toml").read_text()
    base, old = 'base = "../scenarios/paper.toml"', 'theorem1 = "measured"'
    assert text.count(old) == 1 and text.count(base) == 1
    text = text.replace(base, f'base = "{PAPER.as_posix()}"').replace(old, 'theorem1 = "maybe"')
    study = tmp_path / "t.toml"
    study.write_text(text)
    err = _one_line(capsys, run_cli(main, ["run", str(study), "--out", "o"]))
    assert "graph.losses.theorem1" in err and "required or measured" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]
    study.write_text(text.replace('theorem1 = "maybe"', 'theorem1 = "measured"'))
    err = _one_line(capsys, run_cli(main, ["run", str(study), "--out", "o", "--keep-runs"]))
    assert "--keep-runs" in err and 'theorem1 = "measured"' in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


def test_identity_names_a_measured_theorem1_only_when_set(stored_designs):
    """A study without the new keys keeps the identity it had before them."""
    from sweep.identity import study_identity

    links = study_identity(load_study(ROOT / "studies" / "links.toml"))
    assert "theorem1" not in links["graph"]["losses"]
    topo = study_identity(load_study(ROOT / "studies" / "topologies.toml"))
    assert topo["graph"]["losses"]["theorem1"] == "measured"


def test_scheduler_that_does_not_answer_leaves_no_folder(tmp_path, capsys, monkeypatch):
    import dask

    monkeypatch.setenv("DASK_SCHEDULER", "tcp://127.0.0.1:1")  # nothing listens on port 1
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code = run_cli(main, ["run", str(_study(tmp_path)), "--out", str(tmp_path / "o" / "x")])
    assert "cannot connect" in _one_line(capsys, code)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("plant", ["symlink", "fifo"])
def test_lock_file_that_is_not_a_regular_file_is_refused(tmp_path, plant):
    target = tmp_path / "elsewhere"
    if plant == "symlink":
        (tmp_path / LOCK).symlink_to(target)
    else:
        os.mkfifo(tmp_path / LOCK)
    with pytest.raises(StudyLocked, match="--out DIR"):
        with study_lock(tmp_path):
            pass
    assert not target.exists()
