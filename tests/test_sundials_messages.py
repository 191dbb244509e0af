"""SUNDIALS' warnings and errors go to the run's log, not the terminal.

The native driver (generated/native/common.c) routes SUNDIALS' logger into a file the
run reads back (``Trajectory.sundials_log``); ``generated.api.run`` writes it to
``out/<run>/sundials.log``, counts it in meta.json (``sundials_messages``) and prints
one summary line. Independent truth: SUNDIALS' own "t + h = t" warning, provoked by an
operator step on the paper's loop.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from generated.schedule import output_grid
from generated.sundials_log import sundials_messages
from generated.values import CodegenSettings, IntegratorSettings

ROOT = Path(__file__).resolve().parent.parent


def test_a_quiet_native_run_has_an_empty_log(
    capfd: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """0.2 s of the two-follower test scenario on the per-agent engine: nothing on the
    terminal, an empty log, the temporary log file removed."""
    from helpers import SMALL

    from generated import agents, api

    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    sc = api.load(path)
    gains = api.scenario_gains(sc, "quiet")
    cg = CodegenSettings(optimization="-O0", kernel_optimization="-O0")  # the shared cache
    libs, model = agents.build_models(sc, gains, cg)
    logs = tmp_path / "tmp"
    logs.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(logs))  # where the driver's log file goes
    capfd.readouterr()
    s = IntegratorSettings(method="native", rtol=1e-8, atol=1e-10)
    tr = agents.run(
        [lib.path for lib in libs],
        agents.problem(sc, gains, model),
        agents.initial_state(sc),
        output_grid(0.2, 0.1),
        s,
    )
    err = capfd.readouterr().err
    assert "[WARNING]" not in err and "[ERROR]" not in err, err
    assert tr.complete and tr.sundials_log == ""
    assert list(logs.iterdir()) == []  # the temporary log was read and removed


def test_sundials_messages_counts_and_strips_paths() -> None:
    log = (
        "[WARNING][CVode] Warning: t + h = t on the next step at t = 5.0 (cvode.c:1516)\n"
        "[WARNING][rank 0][/project/build/src/cvode/cvode.c:1516][CVode] t + h = t again\n"
        "[ERROR][CVode] At t = 5, mxstep steps taken before reaching tout. (cvode.c:1400)\n"
        "not a message\n"
    )
    m = sundials_messages(log)
    assert m == {
        "count": 3,
        "warnings": 2,
        "errors": 1,
        "first": "CVode: t + h = t on the next step at t = 5.0",
    }
    assert sundials_messages("") == {"count": 0, "warnings": 0, "errors": 0, "first": None}


def test_operator_step_on_the_paper_goes_to_sundials_log_and_meta(tmp_path: Path) -> None:
    """The paper's loop with a unit step of u0 at t = 5 s (a breakpoint): after the
    restart CVODE warns "t + h = t" (measured 2026-12-02: 9 warnings, 4.6 s per run with
    the library cached). Every line names its level, module and source file without a
    path; the run's temporary log file is removed."""
    out = tmp_path / "out"
    logs = tmp_path / "tmp"
    logs.mkdir()
    env = {**os.environ, "HITL_BUILD_DIR": str(tmp_path / "build"), "TMPDIR": str(logs)}
    argv = [
        sys.executable,
        "-m",
        "generated",
        "sim",
        str(ROOT / "scenarios" / "paper.toml"),
        "--opt=-O0",
        "--out",
        str(out),
        "--no-progress",
        "--set",
        'leader.u0=["1.0*step(t-5) - 1.0*step(t-10)"]',
        "--set",
        "leader.u0_rise=0",  # the raw step (a stepped u0 is shaped by default)
        "--set",
        "integration.horizon=5.5",
    ]
    p = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert "[WARNING]" not in p.stderr and "[rank 0]" not in p.stderr, p.stderr
    (folder,) = [d for d in out.iterdir() if d.is_dir()]
    meta = json.loads((folder / "meta.json").read_text())
    m = meta["sundials_messages"]
    assert meta["method"] == "native" and meta["complete"] is True
    assert m["count"] > 0 and "t + h = t" in m["first"], m
    log = (folder / "sundials.log").read_text()
    assert len(log.splitlines()) == m["count"] and log.count("t + h = t") == m["warnings"]
    line = re.compile(r"^\[(WARNING|ERROR)\]\[\w+\] .+ \(\w+\.c:\d+\)$")
    assert all(line.match(s) for s in log.splitlines()), log
    assert "/" not in log and "/" not in m["first"]  # no build paths of SUNDIALS' CI
    assert not list(logs.glob("hitl-sundials-*"))  # the temporary log was read and removed
    summary = [line for line in p.stderr.splitlines() if line.startswith("SUNDIALS: ")]
    assert len(summary) == 1 and f"{m['warnings']} warnings" in summary[0]
    assert str(folder / "sundials.log") in summary[0]
