"""The operator console: message validation, pacing under bad input, roles, the page.

The server tests run the real server (Starlette under uvicorn, on a free loopback
port, stopped at the end of each test) around :class:`console_fake.FakeLoop`, whose
leader and followers have closed-form solutions for a held command. The browser test
drives the page with Debian's chromium through Playwright. The compiled closed loop
and the replay of a recorded run are in ``tests/test_console_replay.py``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from pathlib import Path

import numpy as np
import pytest
from console_fake import FakeLoop, fake_hub, running
from websockets.sync.client import connect

from console.engine import Change, desired_formation
from console.protocol import Command, MessageError, parse_message
from console.record import replay_table, u0_rows
from console.server import create_app, is_loopback

CHROMIUM = Path("/usr/bin/chromium")
LIMITS = FakeLoop().limits


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("raw", "field"),
    [
        ("{bad", "not JSON"),
        ("[1, 2]", "not a JSON object"),
        ('{"value": [1]}', "type"),
        ('{"type": "launch"}', "type"),
        ('{"type": "u0", "value": 1.0}', "value"),
        ('{"type": "u0", "value": ["1"]}', "value[0]"),
        ('{"type": "u0", "value": [true]}', "value[0]"),
        ('{"type": "u0", "value": [NaN]}', "value[0]: NaN is not a finite number"),
        ('{"type": "u0", "value": [Infinity]}', "value[0]: Infinity is not a finite number"),
        ('{"type": "u0", "value": [-Infinity]}', "value[0]: -Infinity is not a finite number"),
        ('{"type": "scale", "value": NaN}', "value: NaN is not a finite number"),
        ('{"type": "health", "follower": NaN, "value": 1}', "follower: NaN is not a follower"),
        ('{"type": "u0", "value": [1e999]}', "value[0]: inf is not a finite number"),
        ('{"type": "u0", "value": [%s]}' % ("9" * 400), "value[0]: a 400-digit number is out"),
        ('{"type": "bias", "follower": 1, "value": [1, %s]}' % ("1" * 400), "value[1]: a 400-"),
        ('{"type": "u0", "value": [2.5]}', "out of range"),
        ('{"type": "u0", "value": [2.0000001]}', "value[0]: 2.0000001 is out of range [-2, 2]"),
        ('{"type": "u0", "value": [-2.0000000000000004]}', "-2.0000000000000004 is out"),
        ('{"type": "scale", "value": 20.000001}', "value: 20.000001 is out of range [0.05, 20]"),
        ('{"type": "u0", "value": [1], "speed": 2}', "'speed': unknown field of a 'u0' message"),
        ('{"type": "pause", "now": 1, "all": 0}', "'all', 'now': unknown fields of a 'pause'"),
        ('{"type": "link", "follower": 3, "neighbour": 2, "cut": true, "w": 0}', "'w': unknown"),
        ('{"type": "u0", "value": [1, 1]}', "list of 1 numbers"),
        ('{"type": "health", "follower": 4, "value": 0.8}', "follower"),
        ('{"type": "health", "follower": 0, "value": 0.8}', "follower"),
        ('{"type": "health", "follower": 1.0, "value": 0.8}', "follower"),
        ('{"type": "health", "follower": 1, "value": 0.4}', "out of range"),
        ('{"type": "health", "follower": 1, "value": 1.01}', "out of range"),
        ('{"type": "bias", "follower": 2, "value": [1]}', "list of 2 numbers"),
        ('{"type": "bias", "follower": 2, "value": [1, 11]}', "out of range"),
        ('{"type": "link", "follower": 1, "neighbour": 2, "cut": true}', "not heard"),
        ('{"type": "link", "follower": 3, "neighbour": 2, "cut": 1}', "cut"),
        ('{"type": "scale", "value": 0}', "out of range"),
        ('{"type": "scale", "value": 100}', "out of range"),
        ('{"type": "clear"}', "follower"),
        ("x" * 5000, "bytes"),
    ],
)
def test_bad_messages_are_refused_naming_the_field(raw: str, field: str) -> None:
    """Each malformed message is one MessageError line naming what is wrong."""
    with pytest.raises(MessageError) as exc:
        parse_message(raw, LIMITS)
    text = str(exc.value)
    assert field in text and "\n" not in text


def test_good_messages_parse_to_zero_based_commands() -> None:
    """Followers and neighbours are 1-based in messages, 0-based (leader -1) in commands."""
    assert parse_message('{"type": "u0", "value": [-2]}', LIMITS) == Command("u0", values=(-2.0,))
    assert parse_message(
        '{"type": "link", "follower": 1, "neighbour": 0, "cut": true}', LIMITS
    ) == (Command("link", follower=0, neighbour=-1, cut=True))
    cmd = parse_message('{"type": "bias", "follower": 3, "value": [0.5, -1]}', LIMITS)
    assert cmd == Command("bias", follower=2, values=(0.5, -1.0))
    assert parse_message('{"type": "pause"}', LIMITS).kind == "pause"


def test_loopback_addresses() -> None:
    """IPv4 and IPv6 loopback are local; private and public addresses are not."""
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("127.5.6.7")
    assert not is_loopback("10.0.0.5") and not is_loopback("192.168.1.2")
    assert not is_loopback(None) and not is_loopback("example.org")


def _asgi(app, kind: str, client: str, headers: dict | None = None) -> list[dict]:
    """Call the ASGI app once (an HTTP GET of / or a WebSocket to /ws); what it sent."""
    hdrs = [(k.encode(), v.encode()) for k, v in {"host": "127.0.0.1:1", **(headers or {})}.items()]
    scope = {
        "type": kind,
        "path": "/" if kind == "http" else "/ws",
        "raw_path": b"/",
        "query_string": b"",
        "headers": hdrs,
        "client": (client, 5000),
        "server": ("127.0.0.1", 1),
        "scheme": "http" if kind == "http" else "ws",
        "method": "GET",
        "http_version": "1.1",
        "root_path": "",
        "asgi": {"version": "3.0"},
    }
    first = (
        {"type": "http.request", "body": b""} if kind == "http" else {"type": "websocket.connect"}
    )
    inbox = [first, {"type": "http.disconnect" if kind == "http" else "websocket.disconnect"}]
    sent: list[dict] = []

    async def receive():
        return inbox.pop(0) if inbox else {"type": "websocket.disconnect", "code": 1000}

    async def send(msg):
        sent.append(msg)

    asyncio.run(app(scope, receive, send))
    return sent


def test_non_loopback_peers_are_refused_unless_allowed() -> None:
    """A page or socket from a non-loopback address gets 403 / a closed socket (1008) unless
    the server allows remote peers; a socket from another site's page (Origin) is closed."""
    app = create_app(fake_hub())
    assert _asgi(app, "http", "10.1.2.3")[0]["status"] == 403
    assert _asgi(app, "http", "127.0.0.1")[0]["status"] == 200
    closed = _asgi(app, "websocket", "10.1.2.3")[0]
    assert closed["type"] == "websocket.close" and closed["code"] == 1008
    assert "not a loopback address" in closed["reason"]
    evil = _asgi(app, "websocket", "127.0.0.1", {"origin": "http://evil.example"})
    assert evil[0]["type"] == "websocket.close" and evil[0]["code"] == 1008
    hub = fake_hub()
    hub.allow_remote = True
    assert _asgi(create_app(hub), "http", "10.1.2.3")[0]["status"] == 200
    assert _asgi(create_app(hub), "websocket", "10.1.2.3")[0]["type"] == "websocket.accept"


# --------------------------------------------------------------------------- record
def test_u0_trace_rows_hold_each_command_from_its_change() -> None:
    """Trace rows: the start value, one row per change (last one at a time wins), the end."""
    ch = [
        Change(0.0, "u0", values=(1.0,)),
        Change(0.5, "health", 1, values=(0.7,)),
        Change(1.25, "u0", values=(-2.0,)),
        Change(3.0, "u0", values=(0.5,)),
    ]
    assert u0_rows(ch, [0.0], 2.0) == [[0.0, 1.0], [1.25, -2.0], [2.0, -2.0]]


def test_replay_table_writes_health_tables_and_bias_steps() -> None:
    """Health changes become a g table; bias changes become bias faults of the difference."""
    table = {
        "name": "x",
        "leader": {"u0": ["0"]},
        "graph": {},
        "followers": [{"g": 1.0}, {"g": 0.9}],
    }
    ch = [
        Change(0.5, "health", 1, values=(0.7,)),
        Change(1.0, "bias", 0, values=(1.0, 2.0)),
        Change(2.0, "bias", 0, values=(0.0, 0.5)),
    ]
    data = replay_table(table, ch, [1.0, 0.9], 3.0, 0.01, rise=0.75)
    assert data["leader"] == {"u0_csv": "u0.csv", "u0_hold": True, "u0_rise": 0.75}
    assert data["followers"][0]["g"] == 1.0
    assert data["followers"][1]["g"] == [[0.0, 0.9], [0.5, 0.7]]
    faults = data["followers"][0]["faults"]
    assert [f["onset"] for f in faults] == [1.0, 2.0]
    # the biases add: their sum after each onset is the value the operator set
    assert np.allclose(np.cumsum([f["amplitude"] for f in faults], axis=0), [[1, 2], [0, 0.5]])
    assert data["integration"] == {"horizon": 3.0, "output_step": 0.01}
    assert table["leader"] == {"u0": ["0"]}  # the console's own table is untouched


def test_desired_formation_rotates_by_the_leader_heading() -> None:
    """Slots are y0 + R(τ0) b_i0: heading 90° turns (4, 0) into (0, 4); no heading: b_i0."""
    y0 = np.array([1.0, 2.0])
    slots = desired_formation(y0, np.array([0.0, 3.0]), np.array([[4.0, 0.0]]))
    assert np.allclose(slots, [[1.0, 6.0]])
    assert np.allclose(desired_formation(y0, np.zeros(2), np.array([[4.0, 0.0]])), [[5.0, 2.0]])


# --------------------------------------------------------------------------- server
def _states(ws, seconds: float) -> tuple[list[dict], list[dict]]:
    """Frames and other messages received for ``seconds``."""
    frames, other = [], []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = json.loads(ws.recv(timeout=2))
        (frames if m["type"] == "state" else other).append(m)
    return frames, other


def _drive(ws) -> None:
    ws.send(json.dumps({"type": "drive"}))


def test_bad_messages_get_errors_and_the_loop_keeps_its_pace() -> None:
    """Malformed JSON, wrong types, NaN, an unknown follower and a flood of 1,000 messages.

    Every one is answered with an error, and over the flood the loop keeps running: the
    simulated clock advances and state frames keep arriving with increasing times (no
    wall-clock rate is asserted; rates are load-dependent and belong to benchmarks);
    afterwards a good command still acts.
    """
    hub = fake_hub(deadman=None)  # the client holds u0 without keepalives
    with running(hub) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        _drive(ws)
        _states(ws, 0.3)
        bad = [
            "{not json",
            '{"type": "u0", "value": "fast"}',
            '{"type": "u0", "value": [NaN]}',
            '{"type": "health", "follower": 9, "value": 0.9}',
        ]
        flood = [bad[k % len(bad)] for k in range(1000)]
        t_sim0 = hub.session.loop.t
        for raw in flood:
            ws.send(raw)
        errors, frames = [], []
        while len(errors) < len(flood):
            m = json.loads(ws.recv(timeout=5))
            (errors if m["type"] == "error" else frames).append(m)
        more, _ = _states(ws, 1.0)
        frames += more
        sim = hub.session.loop.t - t_sim0
        times = [f["t"] for f in frames]
        assert all("expected" in e["message"] for e in errors)
        assert sim > 0 and len(frames) >= 2
        assert times == sorted(times) and times[-1] > times[0]
        assert not hub.session.loop.failure and hub.session.loop.changes == []
        ws.send(json.dumps({"type": "u0", "value": [2.0]}))
        frames, other = _states(ws, 0.5)
        assert not other and frames[-1]["u0"] == [2.0]


def test_watchers_and_closing_pages() -> None:
    """One page drives, a second watches (its commands refused); closing the driver stops
    nothing, and the watcher may then drive."""
    hub = fake_hub()
    with running(hub) as port:
        url = f"ws://127.0.0.1:{port}/ws"
        with connect(url) as a, connect(url) as b:
            _drive(a)
            _states(a, 0.2)
            _drive(b)
            b.send(json.dumps({"type": "u0", "value": [1.0]}))
            frames, other = _states(b, 0.3)
            assert [m["type"] for m in other if m["type"] != "hello"] == ["error", "error"]
            assert frames[-1]["role"] == "watcher" and frames[-1]["pages"] == 2
            a.close()
            t1 = hub.session.loop.t
            frames, _ = _states(b, 0.5)
            assert hub.session.loop.t > t1 + 0.3  # the loop ran on
            _drive(b)
            b.send(json.dumps({"type": "u0", "value": [1.0]}))
            frames, other = _states(b, 0.3)
            assert [m["type"] for m in other] == ["role"] and frames[-1]["u0"] == [1.0]


def test_integrator_failure_holds_the_loop_resume_retries_reset_restarts() -> None:
    """When every attempt fails, frames carry the reason (held, with the attempts), the loop
    makes no further attempt until resume, changes are still accepted, resume continues
    from the last good state (not t = 0) and reset starts again from t = 0."""
    from console.engine import MAX_ATTEMPTS

    hub = fake_hub(fail_at=0.3, deadman=None)  # the client holds u0 without keepalives
    loop = hub.session.loop
    with running(hub) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        _drive(ws)
        frames, _ = _states(ws, 0.8)
        f = frames[-1]
        assert "fake failure" in f["failure"] and "held at t = 0.3" in f["failure"]
        assert f["t"] == pytest.approx(0.3) and [e[1] for e in f["events"]][-1] == "held"
        # the call that failed: its first attempt, then MAX_ATTEMPTS - 1 restarts at 0.3 s
        restarts = [(round(t, 9), k) for t, k in loop.attempts if k > 0]
        assert restarts == [(0.3, k) for k in range(1, MAX_ATTEMPTS)]
        n = len(loop.attempts)
        _states(ws, 0.3)
        assert len(loop.attempts) == n  # held: no dead loop of retries
        ws.send(json.dumps({"type": "u0", "value": [1.0]}))
        _, other = _states(ws, 0.2)
        assert other == []  # a change is accepted while held (it lands when the loop runs)
        loop.fail_at = None
        ws.send(json.dumps({"type": "resume"}))
        frames, _ = _states(ws, 0.4)
        assert frames[-1]["failure"] == "" and frames[-1]["t"] > 0.4
        assert [c.t for c in loop.changes] == [pytest.approx(frames[0]["t"], abs=0.2)]
        assert loop.changes[0].t > 0.3  # it landed after the resume, not before the hold
        ws.send(json.dumps({"type": "reset"}))
        frames, _ = _states(ws, 0.4)
        assert frames[-1]["failure"] == "" and 0.2 < frames[-1]["t"] < 0.8


def test_a_failed_attempt_restarts_from_the_last_good_state() -> None:
    """An attempt that stops is retried from the last state it reached with attempt 1
    (the smaller first step): the run goes on, the failure and the recovery are events,
    and the states equal those of a run that never failed (the same RK4 steps)."""
    from console_fake import FakeLoop

    good, flaky = FakeLoop(), FakeLoop(fail_at=0.255, fail_attempts=1)
    for loop in (good, flaky):
        loop.set_u0((2.0,))
        for _ in range(10):
            adv = loop.advance(5)
            assert adv.failure == ""
    assert flaky.failure == "" and flaky.t == pytest.approx(0.5)
    assert [e.kind for e in flaky.events] == ["failure", "recovered"]
    assert flaky.events[0].t == pytest.approx(0.25)  # the last good state
    assert (0.25, 1) in [(round(t, 9), a) for t, a in flaky.attempts]
    assert 0.25 in [round(t, 9) for t in flaky.restarts]
    assert np.allclose(flaky.x, good.x, rtol=0, atol=1e-12)


def ramp_position(a: float, tau: float, r: float) -> float:
    """Position of a double integrator at rest under u0 = a S(τ/r), S = 3x² − 2x³ on [0, 1].

    ∫S = x³ − x⁴/2 and ∫∫S = x⁴/4 − x⁵/10 (x = τ/r, times r and r²); after the ramp,
    y = a (τ − r/2)²/2 + a r²/40 (the value and slope at τ = r continue).
    """
    if tau <= 0:
        return 0.0
    if tau >= r:
        return a * (tau - r / 2) ** 2 / 2 + a * r**2 / 40
    x = tau / r
    return a * r**2 * (x**4 / 4 - x**5 / 10)


def test_pause_scale_and_held_command_against_closed_form() -> None:
    """A command u0 = a landing at t_a ramps in as a S((t − t_a)/r) and moves the leader
    as :func:`ramp_position`; pause freezes the clock; the scale command sets the pace's
    scale (the achieved wall-clock ratio is load-dependent and is not asserted)."""
    hub = fake_hub(deadman=None)  # the client holds u0 without keepalives
    with running(hub) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        _drive(ws)
        ws.send(json.dumps({"type": "pause"}))
        _states(ws, 0.2)
        t_pause = hub.session.loop.t
        ws.send(json.dumps({"type": "u0", "value": [2.0]}))
        ws.send(json.dumps({"type": "scale", "value": 4.0}))
        ws.send(json.dumps({"type": "resume"}))
        frames, _ = _states(ws, 1.5)
        f = frames[-1]
        # the command lands at the end of the first call after the pause (one frame later)
        (change,) = hub.session.loop.changes
        assert change.kind == "u0" and t_pause < change.t <= t_pause + 4 * 0.25
        rise = hub.session.loop.rise
        # RK4 (h = 0.0025) across the ramp's curvature jumps at c and c + r: local error ~1e-8
        assert f["y0"][0] == pytest.approx(ramp_position(2.0, f["t"] - change.t, rise), abs=1e-6)
        assert f["scale"] == 4.0 and f["ratio"] > 0
        ws.send(json.dumps({"type": "pause"}))
        frames, _ = _states(ws, 0.5)
        assert frames[-1]["t"] == frames[len(frames) // 2]["t"] and frames[-1]["paused"]


# --------------------------------------------------------------------------- the page
def _browser():
    """Headless Debian chromium through Playwright, or a skip saying what is missing."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    if not CHROMIUM.exists():
        pytest.skip(
            f"{CHROMIUM} is missing and could not be installed (make chromium needs apt-get as root)"
        )
    return sync_api


def test_page_drives_the_leader_and_followers_follow(tmp_path: Path) -> None:
    """In headless chromium: holding → makes the leader move right; the followers follow
    (each ends nearer its slot than the leader's displacement); a fault button acts;
    a screenshot is saved."""
    sync_api = _browser()
    hub = fake_hub()
    with running(hub) as port, sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 720})
            js_errors: list[str] = []
            page.on("pageerror", lambda exc: js_errors.append(str(exc)))
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function(
                "document.getElementById('role').textContent.startsWith('driver')"
            )
            x_start = hub.session.loop.x.copy()
            page.keyboard.down("ArrowRight")
            time.sleep(1.5)
            page.keyboard.up("ArrowRight")
            page.click("button[data-health='2']")
            time.sleep(0.5)
            page.screenshot(path=str(tmp_path / "console.png"))
            loop = hub.session.loop
            moved = loop.x[0] - x_start[0]
            assert loop.changes[0].kind == "u0" and loop.changes[0].values == (2.0,)
            assert loop.changes[1].kind == "u0" and loop.changes[1].values == (0.0,)
            # the key was surely held 1 s and the check comes >= 0.5 s after its release:
            # the ramp 2 S(τ/r) (r = 1) moves the leader 2 r² (1/4 − 1/10) = 0.3 in its
            # first second, reaching velocity 1; u0 >= 0 after, so velocity >= 1 for 0.5 s
            assert moved > 0.8
            # followers follow: each moved the same way by most of the leader's displacement
            dP = (loop.x[2:] - x_start[2:]).reshape(-1, 2)
            assert np.all(dP[:, 0] > 0.5 * moved) and np.all(np.abs(dP[:, 1]) < 0.1 * moved)
            assert loop.settings.health[1] == pytest.approx(0.6)
            assert page.text_content("#t") not in ("", "0")
            assert (tmp_path / "console.png").stat().st_size > 10_000
            assert js_errors == []  # the page's script ran without an exception
        finally:
            browser.close()


@pytest.mark.parametrize(
    ("argv", "text"),
    [
        (["serve", "scenarios/paper.toml", "--host", "0.0.0.0"], "--host 0.0.0.0: not a loopback"),
        (["serve", "scenarios/paper.toml", "--fps", "100"], "--fps: 100 (expected 20 to 60)"),
        (["serve", "missing.toml"], "missing.toml"),
        (["serve", "scenarios/paper.toml", "--bias-max", "-1"], "--bias-max"),
    ],
)
def test_cli_errors_are_one_line(argv: list[str], text: str, capsys) -> None:
    """Bad command lines stop before anything is built: one line on stderr, exit 2."""
    from console.__main__ import main
    from core.errors import run_cli

    assert run_cli(main, argv) == 2
    err = capsys.readouterr().err
    assert text in err and err.count("\n") == 1


def test_record_refuses_a_replay_the_loader_refuses(tmp_path: Path) -> None:
    """A record whose link cut leaves follower 1 without the leader writes the trace and
    the log but no scenario, and says why; without such a cut the written scenario loads
    with the held trace, the health table and the bias fault, their times breakpoints."""
    from helpers import PAPER

    from console.record import write_record
    from console.scenario import console_table
    from core.scenario import load_scenario

    table = console_table(PAPER)
    t = np.arange(201) * 0.01
    X = np.zeros((len(t), 2))
    args = (table, [0.0], [0.95] * 5, t, X, ["a", "b"], 0.01)
    cut = [Change(1.0, "link", 0, -1, (0.0,))]
    rec = write_record(tmp_path / "cut", args[0], cut, *args[1:])
    assert rec.scenario is None and "cannot be reached" in rec.reason
    assert (tmp_path / "cut" / "u0.csv").exists() and (tmp_path / "cut" / "console.csv").exists()
    ok = [
        Change(0.5, "u0", values=(2.0,)),
        Change(0.7, "health", 2, values=(0.6,)),
        Change(1.2, "bias", 3, values=(1.0, -1.0)),
    ]
    rec = write_record(tmp_path / "ok", args[0], ok, *args[1:], rise=0.75)
    sc = load_scenario(rec.scenario)
    assert sc.leader.u0_hold and sc.integration.horizon == 2.0
    r = sc.leader.u0_rise
    assert r > 0 and {0.5, 0.7, 1.2, 0.5 + r} <= set(sc.breakpoints())
    # the change ramps in from its row: 2 S((t − 0.5)/r), S(x) = 3x² − 2x³
    for t in (0.49, 0.5, 0.5 + r / 4, 0.5 + r / 2, 0.5 + r, 1.99):
        x = min(max((t - 0.5) / r, 0.0), 1.0)
        assert sc.leader.u0_numpy(t)[0] == pytest.approx(2.0 * (3 * x**2 - 2 * x**3), abs=1e-15)
    assert sc.followers[2].g.expr.numpy(0.7) == pytest.approx(0.6)


# ------------------------------------------------------------ letting go, saves, dead sockets
def test_a_held_command_without_keepalives_returns_to_zero() -> None:
    """Dead-man's handle on the server: a driver that holds u0 = 2 and re-sends it every
    0.2 s keeps it; once it stops sending, u0 is 0 within the dead-man time (0.5 s, plus a
    frame) and the driver is told why."""
    from console.server import DEADMAN, KEEPALIVE

    hub = fake_hub()
    loop = hub.session.loop
    with running(hub) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        _drive(ws)
        end = time.monotonic() + 1.2
        while time.monotonic() < end:  # keepalives: the command stays
            ws.send(json.dumps({"type": "u0", "value": [2.0]}))
            _states(ws, KEEPALIVE)
        assert tuple(loop.target.u0) == (2.0,)
        t_last = time.monotonic()
        released = None
        while released is None and time.monotonic() < t_last + 2.0:
            m = json.loads(ws.recv(timeout=2))
            if m["type"] == "released":
                released = time.monotonic() - t_last
        assert released is not None and released < DEADMAN + 0.2, released
        assert m["reason"] == f"no command for {DEADMAN:g} s"
        time.sleep(0.1)
        assert tuple(loop.target.u0) == (0.0,)


def test_saves_are_limited_to_one_per_interval() -> None:
    """Twenty saves at once: one is written, the others are refused in one line (one save
    at a time); a save within the interval is refused saying when to try again; after the
    interval it is written."""

    def recorder(snap) -> dict:
        return {"folder": f"rec-{snap.rows}", "rows": snap.rows}

    hub = fake_hub(recorder=recorder, save_interval=1.0)
    with running(hub) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        _drive(ws)
        replies = []
        for _ in range(20):
            ws.send(json.dumps({"type": "save"}))
        while len(replies) < 20:
            m = json.loads(ws.recv(timeout=5))
            if m["type"] in ("saved", "error"):
                replies.append(m)
        kinds = [m["type"] for m in replies]
        assert kinds.count("saved") == 1, kinds
        refused = [m["message"] for m in replies if m["type"] == "error"]
        assert all(r.startswith("save: ") and "\n" not in r for r in refused)
        ws.send(json.dumps({"type": "save"}))  # the first is written: now the interval counts
        while (m := json.loads(ws.recv(timeout=5)))["type"] not in ("saved", "error"):
            pass
        assert "at most one save every 1 s; try again in" in m["message"], m
        time.sleep(1.1)
        ws.send(json.dumps({"type": "save"}))
        while (m := json.loads(ws.recv(timeout=5)))["type"] not in ("saved", "error"):
            pass
        assert m["type"] == "saved", m


def test_a_dead_socket_is_not_written_to(caplog) -> None:
    """A client that floods the server with bad messages and resets its TCP connection
    without reading: the server stops writing to it (no 'socket.send() raised exception'
    lines in the log) and goes on serving."""
    import socket
    import struct

    hub = fake_hub()
    caplog.set_level(logging.WARNING)
    with running(hub) as port:
        for _ in range(3):
            with connect(f"ws://127.0.0.1:{port}/ws") as ws:
                _drive(ws)
                for _ in range(3000):
                    ws.send("{bad")
                sock = ws.socket
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                sock.close()  # RST: every later write of the server fails
            time.sleep(0.5)
        with connect(f"ws://127.0.0.1:{port}/ws") as ws:
            frames, _ = _states(ws, 0.3)
            assert frames
    flood = [r for r in caplog.records if "socket.send() raised exception" in r.getMessage()]
    assert flood == []


def test_an_attempt_past_its_wall_time_budget_is_killed() -> None:
    """A call that would run 30 s in the child is stopped after its 0.5 s budget; the
    child is replaced and the next call is answered."""
    from console.calls import CallTimeout, ChildCalls

    calls = ChildCalls()
    try:
        calls.warm()
        t0 = time.monotonic()
        with pytest.raises(CallTimeout):
            calls.call(time.sleep, (30.0,), timeout=0.5)
        assert time.monotonic() - t0 < 1.5 and calls.kills == 1
        assert calls.call(divmod, (7, 2), timeout=30.0) == (3, 1)
        with pytest.raises(RuntimeError, match="ZeroDivisionError"):
            calls.call(divmod, (1, 0), timeout=30.0)
    finally:
        calls.close()


def test_slow_calls_take_fewer_quanta() -> None:
    """Frame pacing: when each quantum costs 20 ms of wall time (a stiff stretch), calls
    take at most CALL_WALL / 20 ms = 5 quanta (about 0.1 s each, so the state keeps
    changing several times a second) instead of a whole tick's 0.25 s of simulated time
    in one 0.5 s call; the run falls behind the scale and the ratio says so."""
    from console.session import CALL_WALL, Session

    loop = FakeLoop()
    plain = loop.integrate
    per_call: list[int] = []

    def slow(x0, t_out, breaks, attempt=0):
        per_call.append(len(t_out) - 1)
        time.sleep(0.02 * (len(t_out) - 1))
        return plain(x0, t_out, breaks, attempt)

    loop.integrate = slow
    session = Session(loop)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        frame = session.tick()
        time.sleep(1 / 30)
    assert len(per_call) > 10 and max(per_call[2:]) <= round(CALL_WALL / 0.02), per_call
    assert frame["ratio"] < 0.9


def test_closing_the_child_does_not_wait_for_its_call() -> None:
    """Shutdown while an attempt runs: close() kills the child at once (it does not wait
    for the call's budget), and the call in progress fails saying the process died."""
    import threading

    from console.calls import ChildCalls

    calls = ChildCalls()
    calls.warm()
    seen: list[str] = []

    def run() -> None:
        try:
            calls.call(time.sleep, (30.0,), timeout=20.0)
        except RuntimeError as exc:
            seen.append(str(exc))

    th = threading.Thread(target=run)
    th.start()
    time.sleep(0.3)
    t0 = time.monotonic()
    calls.close()
    th.join(timeout=10)
    assert time.monotonic() - t0 < 1.0 and seen and "died (signal 9)" in seen[0], seen
