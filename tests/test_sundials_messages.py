"""SUNDIALS' warnings and errors go to the run's log, not the terminal.

The native drivers (generated/native/common.c) route SUNDIALS' logger into a file the
run reads back (``Trajectory.sundials_log``); ``generated.api.run`` writes it to
``out/<run>/sundials.log``, counts it in meta.json (``sundials_messages``) and prints
one summary line. Independent truth: SUNDIALS' own "t + h = t" warning, provoked by a
jump CVODE is not told about (a tiny ODE) and by an operator step on the paper's loop.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from generated import native
from generated.schedule import output_grid
from generated.sundials_log import sundials_messages
from generated.values import CodegenSettings, IntegratorSettings

ROOT = Path(__file__).resolve().parent.parent
E = ca.SX(0, 1)


def jump_ode() -> ca.Function:
    """x' = 1e6 from t = 0.5 on, no breakpoint: at rtol 1e-10 CVODE's step collapses there."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    rhs = ca.if_else(t >= 0.5, 1e6, 0.0) - 1e-3 * x
    return ca.Function("jump", [t, x, E, E, E], [rhs, E, E, E], ca.dyn_in(), ca.dyn_out())


def test_native_run_logs_sundials_messages_instead_of_printing_them(
    capfd: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    lib = native.build(
        jump_ode(), CodegenSettings(optimization="-O0", build_root=str(tmp_path / "b"))
    )
    logs = tmp_path / "tmp"
    logs.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(logs))  # where the driver's log file goes
    capfd.readouterr()
    s = IntegratorSettings(rtol=1e-10, atol=1e-12, max_steps=5000)
    tr = native.run(lib.path, np.zeros(1), output_grid(1.0, 0.1), s)
    err = capfd.readouterr().err
    assert "[WARNING]" not in err and "[ERROR]" not in err and "t + h = t" not in err, err
    assert not tr.complete and "TOO_MUCH_WORK" in tr.message  # stuck at the jump
    m = sundials_messages(tr.sundials_log)
    # CVODE warns (at most mxhnil = 10 times) and then fails (mxstep): both in the log
    assert m["warnings"] >= 2 and m["errors"] >= 1
    assert m["count"] == len(tr.sundials_log.splitlines())
    assert m["first"].startswith("CVode: Internal t = 0.5 and h = ")
    assert "t + h = t" in m["first"] and "/" not in m["first"]
    line = re.compile(r"^\[(WARNING|ERROR)\]\[\w+\] .+ \(\w+\.c:\d+\)$")
    assert all(line.match(s) for s in tr.sundials_log.splitlines()), tr.sundials_log
    assert "/" not in tr.sundials_log  # no build paths of SUNDIALS' CI
    assert list(logs.iterdir()) == []  # the temporary log was read and removed
    # a run without messages has an empty log
    quiet = native.run(lib.path, np.zeros(1), output_grid(0.4, 0.1), s)
    assert quiet.complete and quiet.sundials_log == ""


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
    the library cached)."""
    out = tmp_path / "out"
    env = {**os.environ, "HITL_BUILD_DIR": str(tmp_path / "build")}
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
    summary = [line for line in p.stderr.splitlines() if line.startswith("SUNDIALS: ")]
    assert len(summary) == 1 and f"{m['warnings']} warnings" in summary[0]
    assert str(folder / "sundials.log") in summary[0]
