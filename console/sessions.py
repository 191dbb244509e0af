"""Scripted console sessions: a random operator at the keys, the loop's health measured.

``python -m console.sessions [SCENARIO] [--sessions 200] [--seconds 6] [--seed 0]
[--workers 2] [--network] [--out out/console-sessions]`` opens the console of ``SCENARIO``
(default the paper's) without a server and, for each session, resets the loop and plays a
random operator through the session layer exactly as the server does (validated
messages between frames of a wall clock the script advances at 30 frames per second):

* **holds**: a key pressed for 0.2-2.5 s, then released;
* **quick taps**: 1-6 presses of 30-150 ms each, 30-200 ms apart;
* **reversals**: the opposite key pressed while one is held;
* **stick moves**: a gamepad axis at a random value, moved or released;

each command of random size up to the protocol's bound (|u0_k| ≤ α/√p) and random sign,
with pauses of 50 ms to 1.5 s between actions. With ``--network`` the operator also
cuts links (a random edge of the graph; a cut the console refuses because it would
leave a follower unreachable from the leader is counted) and restores them 0.3-2 s
later, and injects faults (a health g_i between g_min and 1, a bias up to
``--bias-max`` on each coordinate, ``clear``). Measured per session: integrator
failures (attempts that stopped), holds (every attempt failed), attempts stopped by
their wall-time budget, the largest |u_i| over the logged states from t = 1 s on (the
quanta, every ``integration.output_step``), the commands that waited for a ramp slot,
integrator steps, the longest tick (wall time of one frame's integrator call: in a
served console the state on the page does not change for that long, though frames
go on) and the ticks over 1 s (*freezes*), and wall time.

Writes ``sessions.csv`` (one row per session), ``report.md`` (provenance line, the
command, the totals) and ``provenance.json`` into ``--out``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from console.engine import CONSOLE_RISE
from console.session import PEAK_BOUND, PEAK_FROM
from core.cli_args import count, positive
from core.errors import CliParser, UsageError, run_cli

#: frames per second of the scripted page (the server's default)
FPS = 30.0
DEFAULT_SCENARIO = "scenarios/paper.toml"


@dataclass(frozen=True)
class SessionResult:
    """One scripted session's measurements.

    Attributes
    ----------
    session : int
        Its index (the seed of its script is (seed, session)).
    commands : int
        u0 messages sent.
    changes : int
        u0 changes that landed.
    waited : int
        Frames in which a command waited for a free ramp slot.
    failures : int
        Integrator attempts that stopped (each restarted from the last good state).
    recoveries : int
        Restarts that reached the end of their call.
    held : int
        Times every attempt failed and the loop was held.
    peak_u : float
        Largest |u_i| (any follower) over the logged states with t >= :data:`PEAK_FROM`.
    peak_t : float
        When it occurred.
    t_end : float
        Simulated time reached.
    steps : int
        Integrator steps.
    wall_s : float
        Wall time of the session.
    network : int
        Link cuts, restores and faults sent.
    refused : int
        Messages the console refused (a cut breaking Assumption 1).
    timeouts : int
        Attempts stopped by their wall-time budget.
    longest_tick_s : float
        Longest wall time of one tick.
    freezes : int
        Ticks longer than :data:`FREEZE` s.
    """

    session: int
    commands: int
    changes: int
    waited: int
    failures: int
    recoveries: int
    held: int
    peak_u: float
    peak_t: float
    t_end: float
    steps: int
    wall_s: float
    network: int = 0
    refused: int = 0
    timeouts: int = 0
    longest_tick_s: float = 0.0
    freezes: int = 0


#: a tick (one frame's integrator call) longer than this is a freeze of the page's state (s)
FREEZE = 1.0


def network_script(
    rng: np.random.Generator, seconds: float, edges: Sequence[tuple[int, int]], N: int, lim: Any
) -> list[tuple[float, dict]]:
    """Random link cuts with their restores and faults: (time, message) pairs, sorted.

    Parameters
    ----------
    rng : numpy.random.Generator
    seconds : float
        Length of the session (simulated s).
    edges : sequence of (int, int)
        The graph's edges, 1-based (follower, neighbour; 0 the leader).
    N : int
        Followers.
    lim : console.protocol.Limits
        ``g_min``, ``bias_max`` and ``n``.
    """
    out: list[tuple[float, dict]] = []
    t = float(rng.uniform(1.0, 2.0))
    edges = sorted(edges)
    while t < seconds:
        kind = rng.choice(["cut", "health", "bias", "clear"], p=[0.5, 0.2, 0.2, 0.1])
        i = int(rng.integers(1, N + 1))
        if kind == "cut":
            f, j = edges[int(rng.integers(len(edges)))]
            out.append((t, {"type": "link", "follower": f, "neighbour": j, "cut": True}))
            back = t + float(rng.uniform(0.3, 2.0))
            out.append((back, {"type": "link", "follower": f, "neighbour": j, "cut": False}))
        elif kind == "health":
            g = float(rng.uniform(lim.g_min, 1.0))
            out.append((t, {"type": "health", "follower": i, "value": g}))
        elif kind == "bias":
            b = [float(v) for v in rng.uniform(-lim.bias_max, lim.bias_max, lim.n)]
            out.append((t, {"type": "bias", "follower": i, "value": b}))
        else:
            out.append((t, {"type": "clear", "follower": i}))
        t += float(rng.uniform(0.5, 2.0))
    return sorted(((tk, m) for tk, m in out if tk < seconds), key=lambda e: e[0])


def operator_script(
    rng: np.random.Generator, seconds: float, p: int, u_max: float
) -> list[tuple[float, tuple[float, ...]]]:
    """A random operator's commands: (time, u0) pairs, sorted, the last one a release.

    Parameters
    ----------
    rng : numpy.random.Generator
    seconds : float
        Length of the session (simulated s).
    p : int
        Inputs.
    u_max : float
        Largest |u0_k| the protocol accepts.
    """
    out: list[tuple[float, tuple[float, ...]]] = []
    t = float(rng.uniform(0.0, 1.0))

    def press() -> tuple[float, ...]:
        u = np.zeros(p)
        axes = rng.choice(p, size=int(rng.integers(1, p + 1)), replace=False)
        u[axes] = rng.choice([-1.0, 1.0], size=len(axes)) * rng.uniform(0.05, 1.0, len(axes))
        u[axes] *= u_max
        if rng.random() < 0.3:  # an arrow key: the full size
            u[axes] = np.sign(u[axes]) * u_max
        return tuple(float(v) for v in u)

    zero = (0.0,) * p
    while t < seconds:
        kind = rng.choice(["hold", "taps", "reversal", "stick"], p=[0.3, 0.3, 0.2, 0.2])
        if kind == "hold":
            out.append((t, press()))
            t += float(rng.uniform(0.2, 2.5))
            out.append((t, zero))
        elif kind == "taps":
            u = press()
            for _ in range(int(rng.integers(1, 7))):
                out.append((t, u))
                t += float(rng.uniform(0.03, 0.15))
                out.append((t, zero))
                t += float(rng.uniform(0.03, 0.2))
        elif kind == "reversal":
            u = press()
            out.append((t, u))
            t += float(rng.uniform(0.1, 1.0))
            out.append((t, tuple(-v for v in u)))
            t += float(rng.uniform(0.1, 1.0))
            out.append((t, zero))
        else:
            for _ in range(int(rng.integers(1, 5))):
                out.append((t, press()))
                t += float(rng.uniform(0.05, 0.6))
            out.append((t, zero))
        t += float(rng.uniform(0.05, 1.5))
    return [(tk, u) for tk, u in out if tk < seconds]


def session_script(
    rng: np.random.Generator, seconds: float, lim: Any, network: bool
) -> list[tuple[float, dict]]:
    """A session's messages: (time, message) pairs, sorted.

    Parameters
    ----------
    rng : numpy.random.Generator
    seconds : float
        Length of the session (simulated s).
    lim : console.protocol.Limits
    network : bool
        Add :func:`network_script`'s link cuts, restores and faults.
    """
    ops = operator_script(rng, seconds, lim.p, lim.u_max)
    script = [(t, {"type": "u0", "value": list(u)}) for t, u in ops]
    if network:
        script += network_script(rng, seconds, lim.edges, lim.N, lim)
        script.sort(key=lambda e: e[0])
    return script


def run_session(con, index: int, seed: int, seconds: float, network: bool = False) -> SessionResult:
    """Reset the console's loop and play one random operator; its measurements.

    Parameters
    ----------
    con : console.app.Console
        An opened console (its loop is reset first).
    index : int
        The session's index.
    seed : int
        The run's seed (the script's is (seed, index)).
    seconds : float
        Simulated seconds.
    network : bool
        Also cut and restore links and inject faults (:func:`network_script`).
    """
    from console.protocol import MessageError, parse_message

    loop, s = con.loop, con.session
    lim = loop.limits
    s.handle(parse_message('{"type": "reset"}', lim))
    script = session_script(np.random.default_rng([seed, index]), seconds, lim, network)
    now = [0.0]
    s.clock, s.last_wall = (lambda: now[0]), 0.0
    frames = int(math.ceil(seconds * FPS))
    k, waited, sent, logged, net, refused = 0, 0, 0, 1, 0, 0
    longest, freezes = 0.0, 0
    peak, peak_t = -1.0, float("nan")
    w0 = time.perf_counter()
    for f in range(frames):
        t_page = f / FPS  # wall time of the page = simulated time at scale 1
        while k < len(script) and script[k][0] <= t_page:
            msg = script[k][1]
            try:
                s.handle(parse_message(json.dumps(msg), lim))
            except MessageError:  # a cut that would break Assumption 1
                refused += 1
            sent += msg["type"] == "u0"
            net += msg["type"] != "u0"
            k += 1
        now[0] += 1.0 / FPS
        tick0 = time.perf_counter()
        frame = s.tick()
        tick = time.perf_counter() - tick0
        longest, freezes = max(longest, tick), freezes + (tick > FREEZE)
        waited += bool(frame["queued"] and frame["slots_full"])
        t_new, x_new = s.log_t[logged:], s.log_x[logged:]
        logged = len(s.log_t)
        u, tu = peak_torque(loop, np.array(t_new), np.array(x_new))
        if not u <= peak:  # larger, or not finite
            peak, peak_t = u, tu
        if loop.failure:
            break
    wall = time.perf_counter() - w0
    ev = [e.kind for e in loop.events]
    return SessionResult(
        session=index,
        commands=sent,
        changes=sum(c.kind == "u0" for c in loop.changes),
        waited=waited,
        failures=ev.count("failure"),
        recoveries=ev.count("recovered"),
        held=ev.count("held"),
        peak_u=peak,
        peak_t=peak_t,
        t_end=loop.t,
        steps=loop.steps,
        wall_s=wall,
        network=net,
        refused=refused,
        timeouts=sum(e.kind == "failure" and "wall-time budget" in e.text for e in loop.events),
        longest_tick_s=longest,
        freezes=freezes,
    )


def peak_torque(loop, t: np.ndarray, X: np.ndarray) -> tuple[float, float]:
    """Largest |u_i| over states just logged with t >= :data:`PEAK_FROM`, and when.

    |u_i| is the closed loop's own torque output (``u``) at each state, with the runtime
    parameters of the loop right after the call that reached them: its ramps of u0 are
    those that ran in the call (a ramp that landed at its end is 0 up to it; one that
    ended before it is in the base command), and a scripted session changes nothing else.

    Parameters
    ----------
    loop : console.engine.LiveLoop
    t, X : ndarray
        States logged by the last call.
    """
    sel = np.flatnonzero(t >= PEAK_FROM) if t.size else np.empty(0, dtype=int)
    if sel.size == 0:
        return -1.0, float("nan")
    N = loop.sc.N
    best, when = -1.0, float("nan")
    for j in sel:
        out = loop.outputs_at(float(t[j]), X[j])
        u = np.linalg.norm(np.asarray(out["u"], dtype=float).reshape(N, -1), axis=1).max()
        if not np.isfinite(u):
            return float("inf"), float(t[j])
        if u > best:
            best, when = float(u), float(t[j])
    return best, when


def _worker(args: tuple[str, str, list[int], int, float, float, bool]) -> list[SessionResult]:
    """Open the console once in this process and run its share of the sessions."""
    from console.app import open_console

    scenario, out_root, indices, seed, seconds, rise, network = args
    con = open_console(scenario, out_root=out_root, rise=rise)
    con.loop.calls.warm()  # the integrator's child is up before any session starts
    try:
        return [run_session(con, i, seed, seconds, network) for i in indices]
    finally:
        con.loop.close()


def run_sessions(
    scenario: str,
    sessions: int,
    seconds: float,
    seed: int,
    workers: int,
    out_root: str,
    rise: float = CONSOLE_RISE,
    network: bool = False,
) -> list[SessionResult]:
    """Every session, split over ``workers`` processes (each opens the console once).

    Parameters
    ----------
    scenario : str
        The scenario file.
    sessions, seconds, seed, workers
        As the command line.
    out_root : str
        Where the console's gains are cached.
    rise : float
        Rise time of the shaped changes of u0 (s).
    network : bool
        Link cuts, restores and faults too.
    """
    shares = [list(range(w, sessions, workers)) for w in range(workers)]
    jobs = [(scenario, out_root, idx, seed, seconds, rise, network) for idx in shares if idx]
    if len(jobs) == 1:
        results = _worker(jobs[0])
    else:
        with ProcessPoolExecutor(max_workers=len(jobs)) as ex:
            results = [r for part in ex.map(_worker, jobs) for r in part]
    return sorted(results, key=lambda r: r.session)


def report(
    results: Sequence[SessionResult], command: str, scenario: str, prov: str, rise: float
) -> str:
    """The Markdown report: provenance, the command, totals and the worst sessions.

    Parameters
    ----------
    results : sequence of SessionResult
    command : str
        The command line that produced them.
    scenario : str
        The scenario file.
    prov : str
        The provenance line (:func:`core.provenance.provenance_line`).
    rise : float
        The rise time of the shaped changes of u0 (s).
    """
    peaks = np.array([r.peak_u for r in results])
    fails = sum(r.failures for r in results)
    held = sum(r.held for r in results)
    over = int(np.sum(~(peaks <= PEAK_BOUND)))
    frozen = sum(r.freezes for r in results)
    worst = sorted(results, key=lambda r: -r.peak_u if np.isfinite(r.peak_u) else -np.inf)[:5]
    lines = [
        prov,
        "",
        f"# Scripted console sessions: {scenario}",
        "",
        f"Each change of u0 ramps in over {rise:g} s (smoothstep); "
        f"{PEAK_FROM:g} s start-up excluded from the peak.",
        "",
        f"`{command}`",
        "",
        f"- sessions: {len(results)}, simulated {sum(r.t_end for r in results):.0f} s in "
        f"{sum(r.wall_s for r in results):.0f} s of wall time (summed over workers)",
        f"- u0 commands sent: {sum(r.commands for r in results)}, changes landed: "
        f"{sum(r.changes for r in results)}, frames with a command waiting for a ramp "
        f"slot: {sum(r.waited for r in results)}",
        f"- link cuts, restores and faults sent: {sum(r.network for r in results)} (cuts refused "
        f"as breaking Assumption 1: {sum(r.refused for r in results)})",
        f"- integrator failures: {fails} (restarts that recovered: "
        f"{sum(r.recoveries for r in results)}), loops held: {held} (sessions with a failure: "
        f"{sum(r.failures > 0 for r in results)}; attempts stopped by their wall-time budget: "
        f"{sum(r.timeouts for r in results)})",
        f"- freezes (a tick's integrator call over {FREEZE:g} s of wall time): "
        f"{sum(r.freezes for r in results)}; longest tick "
        f"{max(r.longest_tick_s for r in results):.3g} s",
        f"- peak |u_i| after t = {PEAK_FROM:g} s: largest {np.nanmax(peaks):.4g}, median "
        f"{np.nanmedian(peaks):.4g}; sessions above {PEAK_BOUND:g}: {over}",
        f"- integrator steps per simulated second: "
        f"{sum(r.steps for r in results) / max(sum(r.t_end for r in results), 1e-9):.0f}",
        "",
        f"Verdict: {'PASS' if fails == 0 and held == 0 and over == 0 and not frozen else 'FAIL'} "
        f"(0 failures, 0 freezes and peak |u_i| <= {PEAK_BOUND:g} after {PEAK_FROM:g} s in "
        "every session)",
        "",
        "| session | commands | network | changes | failures | held | peak ‖u_i‖ | at t (s) "
        "| steps | longest tick (s) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in worst:
        lines.append(
            f"| {r.session} | {r.commands} | {r.network} | {r.changes} | {r.failures} | "
            f"{r.held} | {r.peak_u:.4g} | {r.peak_t:.2f} | {r.steps} | {r.longest_tick_s:.3g} |"
        )
    return "\n".join(lines) + "\n"


def write_outputs(folder: Path, results: Sequence[SessionResult], text: str) -> None:
    """``sessions.csv``, ``report.md`` and ``provenance.json`` in ``folder``.

    Parameters
    ----------
    folder : Path
        Created if missing.
    results : sequence of SessionResult
    text : str
        The report (:func:`report`).
    """
    from core.artifacts import atomic_write_text
    from core.provenance import write_provenance

    folder.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    names = list(asdict(results[0])) if results else []
    w = csv.DictWriter(buf, fieldnames=names, lineterminator="\n")
    w.writeheader()
    w.writerows(asdict(r) for r in results)
    atomic_write_text(folder / "sessions.csv", buf.getvalue())
    atomic_write_text(folder / "report.md", text)
    write_provenance(folder)


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring).

    Parameters
    ----------
    argv : list of str
        The arguments after ``python -m console.sessions``.
    """
    from core.provenance import provenance_line

    ap = CliParser(prog="python -m console.sessions", description=__doc__)
    ap.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
    ap.add_argument("--sessions", type=count, default=200)
    ap.add_argument("--seconds", type=positive, default=6.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=count, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--out", default="out/console-sessions")
    ap.add_argument("--rise", type=positive, default=CONSOLE_RISE, help="ramp time of u0 (s)")
    ap.add_argument(
        "--network", action="store_true", help="also cut and restore links and inject faults"
    )
    a = ap.parse_args(argv)
    if not (math.isfinite(a.seconds) and a.seconds > PEAK_FROM):
        raise UsageError(f"--seconds: {a.seconds:g} (expected more than {PEAK_FROM:g})")
    if not Path(a.scenario).is_file():
        raise UsageError(f"{a.scenario}: no such scenario file")
    out = Path(a.out)
    results = run_sessions(
        a.scenario, a.sessions, a.seconds, a.seed, a.workers, str(out), a.rise, a.network
    )
    command = "python -m console.sessions " + " ".join(argv or [])
    text = report(results, command.strip(), a.scenario, provenance_line(), a.rise)
    write_outputs(out, results, text)
    print(text, end="")
    bad = sum(r.failures + r.held + r.freezes for r in results) or any(
        not r.peak_u <= PEAK_BOUND for r in results
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
