"""The console on the compiled closed loop, and the replay of a recorded run.

A three-follower version of the paper's scenario is opened as a console (runtime
parameters, nothing recompiled while it runs), driven through the session exactly as
the server drives it (validated messages, ticks of a wall clock, here a clock the test
advances), recorded, and replayed by ``python -m generated sim`` (what ``make sim``
runs) on the scenario the record wrote. Truth: the replay is an independent run of the
scenario file through the loader and the whole pipeline; the leader's states are
compared with the closed-form solution of η̇0 = A0 η0 + B0 u0 for the held command.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from console_fake import running
from helpers import PAPER

from console.app import open_console
from console.protocol import parse_message
from core.errors import ScenarioError
from core.scenario import load_scenario
from sweep.sampler import scenario_toml

FPS = 30.0
CHROMIUM = Path("/usr/bin/chromium")
#: tick -> message the driving page sends before that tick
SCRIPT = {
    5: {"type": "u0", "value": [2.0]},
    20: {"type": "health", "follower": 2, "value": 0.6},
    30: {"type": "u0", "value": [-1.5]},
    40: {"type": "bias", "follower": 1, "value": [2.0, -1.0]},
    50: {"type": "link", "follower": 3, "neighbour": 2, "cut": True},
    60: {"type": "u0", "value": [0.0]},
    70: {"type": "clear", "follower": 1},
    80: {"type": "u0", "value": [1.0]},
    90: {"type": "link", "follower": 3, "neighbour": 2, "cut": False},
}
TICKS = 100


def _three_followers(folder: Path) -> Path:
    """The paper's scenario cut to followers 1-3: leader -> 1, 1 -> 2, {1, 2} -> 3."""
    d = tomllib.loads(PAPER.read_text(encoding="utf-8"))
    d["name"] = "three"
    d["graph"] = {
        "adjacency": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
        "pinning": [1.0, 0.0, 0.0],
    }
    d["followers"] = d["followers"][:3]
    d["integration"]["horizon"] = 5.0
    path = folder / "three.toml"
    path.write_text(scenario_toml(d), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The console run of SCRIPT, its record and the replay's trajectory."""
    tmp = tmp_path_factory.mktemp("console")
    con = open_console(_three_followers(tmp), out_root=tmp / "out")
    now = [0.0]
    s = con.session
    s.clock = lambda: now[0]
    s.last_wall = 0.0
    for k in range(TICKS):
        if k in SCRIPT:
            assert s.handle(parse_message(json.dumps(SCRIPT[k]), con.loop.limits)) is None
        now[0] += 1.0 / FPS
        s.tick()
    assert not con.loop.failure
    saved = s.handle(parse_message('{"type": "save"}', con.loop.limits))
    assert saved["reason"] == "", saved["reason"]
    cmd = [sys.executable, "-m", "generated", "sim", saved["scenario"], "--out", str(tmp / "out")]
    run = subprocess.run([*cmd, "--no-progress"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    name = load_scenario(saved["scenario"]).name
    replay = pd.read_csv(tmp / "out" / name / "trajectory.csv", comment="#")
    logged = pd.read_csv(Path(saved["folder"]) / "console.csv")
    return con, saved, logged, replay


def test_replay_reproduces_the_console_run(recorded) -> None:
    """Every logged state of the console equals the replay's to the scenario's own
    integration tolerance (|Δ| <= rtol |x| + atol, the weights of CVODE's error test), at
    every one of the console's output times, faults and the link cut included."""
    con, saved, logged, replay = recorded
    sc = con.loop.sc
    assert len(logged) == len(replay) and np.array_equal(logged.t, replay.t)
    cols = [c for c in logged.columns if c != "t"]
    a, b = logged[cols].to_numpy(), replay[cols].to_numpy()
    tol = sc.integration.rtol * np.abs(b) + sc.integration.atol
    worst = np.unravel_index(np.argmax(np.abs(a - b) / tol), a.shape)
    assert np.all(np.abs(a - b) <= tol), (
        f"{cols[worst[1]]} at t = {logged.t[worst[0]]}: {a[worst]} vs {b[worst]}"
    )
    kinds = sorted({c.kind for c in con.loop.changes})
    assert kinds == ["bias", "health", "link", "u0"]


def test_leader_follows_the_held_command_in_closed_form(recorded) -> None:
    """η0 of the double integrator under the recorded piecewise-constant u0:
    η0_2' = u0, η0_1' = η0_2, integrated exactly between the changes."""
    con, saved, logged, replay = recorded
    ch = [(c.t, c.values[0]) for c in con.loop.changes if c.kind == "u0"]
    knots = [(0.0, 0.0), *ch]
    t = logged.t.to_numpy()
    pos, vel = np.zeros_like(t), np.zeros_like(t)
    x1 = x2 = 0.0
    for k, (tk, u) in enumerate(knots):
        t_next = knots[k + 1][0] if k + 1 < len(knots) else np.inf
        sel = (t >= tk) & (t < t_next)
        dt = t[sel] - tk
        pos[sel], vel[sel] = x1 + x2 * dt + u * dt**2 / 2, x2 + u * dt
        if np.isfinite(t_next):
            d = t_next - tk
            x1, x2 = x1 + x2 * d + u * d**2 / 2, x2 + u * d
    rtol, atol = con.loop.sc.integration.rtol, con.loop.sc.integration.atol
    assert np.allclose(logged.eta0_1, pos, rtol=10 * rtol, atol=10 * atol)
    assert np.allclose(logged.eta0_2, vel, rtol=10 * rtol, atol=10 * atol)
    assert [c.t for c in con.loop.changes if c.kind == "u0"] == [k[0] for k in ch]
    assert len(ch) == 4 and pos[-1] != 0.0


def test_changes_land_on_quanta_after_their_message(recorded) -> None:
    """Each change is dated at the end of the integrator call after its message (a
    multiple of the quantum), in message order; the replay file lists them."""
    con, saved, logged, replay = recorded
    h = con.loop.quantum
    times = [c.t for c in con.loop.changes]
    assert times == sorted(times)
    assert all(abs(t / h - round(t / h)) < 1e-9 for t in times)
    data = tomllib.loads(Path(saved["scenario"]).read_text(encoding="utf-8"))
    assert data["leader"]["u0_hold"] is True
    assert data["followers"][1]["g"][1][1] == 0.6
    assert [s["weight"] for s in data["graph"]["switches"]] == [0.0, 1.0]
    assert [f["amplitude"] for f in data["followers"][0]["faults"]] == [[2.0, -1.0], [-2.0, 1.0]]


def test_held_trace_keys(tmp_path: Path) -> None:
    """leader.u0_hold holds each row (right-continuous), makes the rows breakpoints, and is
    refused without a trace in one line naming the key."""
    d = tomllib.loads(PAPER.read_text(encoding="utf-8"))
    d["integration"]["horizon"] = 3.0
    d["leader"].pop("u0")
    d["leader"].update(u0_csv="u.csv", u0_hold=True)
    (tmp_path / "u.csv").write_text("t,u0_1\n0,1.0\n1.5,-2.0\n3,-2.0\n", encoding="utf-8")
    (tmp_path / "s.toml").write_text(scenario_toml(d), encoding="utf-8")
    sc = load_scenario(tmp_path / "s.toml")
    assert sc.leader.u0_numpy(np.array([0.0, 1.4999, 1.5, 2.9])).tolist() == [[1, 1, -2, -2]]
    assert sc.breakpoints() == (1.5,)
    d["leader"].pop("u0_csv")
    d["leader"]["u0"] = ["1"]
    (tmp_path / "s.toml").write_text(scenario_toml(d), encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"leader\.u0_hold: applies to u0_csv only"):
        load_scenario(tmp_path / "s.toml")


@pytest.mark.xfail(
    strict=False,
    reason="known defect: an unshaped u0 step from the keyboard can stop the console's integrator "
    "(docs/verification.md, 'Operator steps'); the console does not shape or recover yet",
)
def test_page_drives_the_compiled_loop(recorded, tmp_path: Path) -> None:
    """In headless chromium on the compiled loop: holding → (u0 = +α) moves the leader's
    output y0 = C0 η0 along (1, 2); the followers follow: over the last second of the
    drive each moves with the leader (displacement within 20 % of the leader's); the fault
    buttons set g_2 = 0.6 × 0.95 and cut the link 3 <- 2. The screenshot is docs/console.png
    (HITL_CONSOLE_SCREENSHOT=docs/console.png)."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    if not CHROMIUM.exists():
        pytest.skip(
            f"{CHROMIUM} is missing and could not be installed (make chromium: apt-get as root)"
        )
    con = recorded[0]
    con.session.clock = time.perf_counter
    con.session.handle(parse_message('{"type": "reset"}', con.loop.limits))
    loop = con.loop
    with running(con.hub) as port, sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 720})
            js_errors: list[str] = []
            page.on("pageerror", lambda exc: js_errors.append(str(exc)))
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function(
                "document.getElementById('role').textContent.startsWith('driver')"
            )
            time.sleep(2.0)  # the start-up transient (followers start away from their slots)
            page.keyboard.down("ArrowRight")
            time.sleep(1.0)
            y0a, Pa = _positions(loop)
            time.sleep(1.0)
            y0b, Pb = _positions(loop)
            page.keyboard.up("ArrowRight")
            page.click("button[data-health='2']")  # a health fault: g_2 × 0.6
            page.click("button[data-link='3,2']")  # cut follower 3's link from follower 2
            deadline = time.monotonic() + 20  # changes land after the integrator call

            def landed() -> bool:  # both u0 changes (hold, release) and both faults
                kinds = [c.kind for c in loop.changes]
                return kinds.count("u0") >= 2 and len(kinds) >= 4

            while not landed() and not loop.failure and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(1.0)
            page.screenshot(path=str(tmp_path / "console-live.png"))
            shot = os.environ.get("HITL_CONSOLE_SCREENSHOT")
            if shot:
                shutil.copy(tmp_path / "console-live.png", shot)
            assert js_errors == []  # the page's script ran without an exception
        finally:
            browser.close()
    assert not loop.failure, loop.failure
    u0s = [c.values for c in loop.changes if c.kind == "u0"]
    assert u0s == [(2.0,), (0.0,)], [(c.t, c.kind, c.values) for c in loop.changes]
    faults = [(c.kind, c.follower, c.values) for c in loop.changes if c.kind != "u0"]
    assert ("health", 1, (pytest.approx(0.57),)) in faults and ("link", 2, (0.0,)) in faults
    step = y0b - y0a
    assert step[0] > 0.5 and np.allclose(step[1], 2 * step[0])  # y0 = C0 η0 moves along (1, 2)
    moved = Pb - Pa
    assert np.all(np.linalg.norm(moved - step, axis=1) < 0.2 * np.linalg.norm(step))


def _positions(loop) -> tuple[np.ndarray, np.ndarray]:
    s = loop.signals(loop.x)
    return np.array(s["y0"]), np.array(s["p"])


def test_integrator_failure_on_the_compiled_loop(tmp_path: Path) -> None:
    """With a step limit CVODE cannot meet, the frame carries the integrator's reason, a
    change is refused naming reset, and reset starts again from t = 0 (same library)."""
    from console.protocol import MessageError

    path = _three_followers(tmp_path)
    d = tomllib.loads(path.read_text(encoding="utf-8"))
    d["integration"]["max_steps"] = 20
    path.write_text(scenario_toml(d), encoding="utf-8")
    con = open_console(path, out_root=tmp_path / "out")
    now = [0.0]
    s = con.session
    s.clock, s.last_wall = (lambda: now[0]), 0.0
    now[0] += 0.2
    frame = s.tick()
    assert frame["failure"] and frame["t"] < 0.2
    with pytest.raises(MessageError, match="send reset"):
        s.handle(parse_message('{"type": "u0", "value": [1.0]}', con.loop.limits))
    s.handle(parse_message('{"type": "reset"}', con.loop.limits))
    assert s.frame()["failure"] == "" and s.frame()["t"] == 0.0
