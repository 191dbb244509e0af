"""One console run: wall-clock pacing, the operator's commands, the log and the record.

The server calls :meth:`Session.tick` at its frame rate and :meth:`Session.handle`
for every validated message, both from one asyncio thread, so a command always
falls between two integrator calls. Pacing: the simulated time owed grows by
``scale`` × the wall time since the last tick (at most :data:`MAX_LAG` seconds of
wall time per tick, so a stall is not made up in a burst) and is paid in whole
quanta; the states at every quantum are logged from t = 0.

A save takes a :class:`Snapshot` of the log on the loop's thread (:meth:`Session.save_job`)
and the recorder writes it from another thread (the server's record worker): the log
only grows, and a reset starts a new one, so the rows a snapshot names never change.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from console.engine import RAMP_SLOTS, Change, Event, LoopBase
from console.protocol import Command, MessageError

#: most wall-clock seconds one tick pays for (a longer stall slows the run down instead)
MAX_LAG = 0.25
#: most quanta one integrator call may take (keeps a tick short at a large time scale)
MAX_QUANTA = 2000
#: logged rows kept from t = 0 (at the default quantum 0.01 s: 2 h 46 min of simulated time)
MAX_LOG_ROWS = 1_000_000
#: window of the simulated/real ratio shown on the page (s)
RATIO_WINDOW = 1.0
#: the integrator's latest events sent with every frame
EVENTS_SHOWN = 5
#: the console's log: the integrator's failures, restarts and holds
LOG = logging.getLogger("console")
#: wall time (s) one integrator call aims at: fewer quanta per call when calls are slow
#: (a stiff stretch), so states keep coming at several per second instead of one per call
CALL_WALL = 0.1
#: |u_i| counts towards the page's peak from this simulated time on (the start-up
#: transient before it is the loop's own, not the operator's)
PEAK_FROM = 1.0
#: the bound on the peak |u_i| after PEAK_FROM the page and the scripted sessions check
#: (torques of the order of 1e3; an unshaped press gives 1e4 and more)
PEAK_BOUND = 1e3


@dataclass
class Pace:
    """The clock's state, as the page shows it.

    Attributes
    ----------
    scale : float
        Simulated seconds per wall-clock second asked for.
    paused : bool
    ratio : float
        Simulated seconds advanced per wall-clock second over the last
        :data:`RATIO_WINDOW` (equal to ``scale`` when the loop keeps up).
    load : float
        Fraction of wall time spent integrating over the same window.
    """

    scale: float = 1.0
    paused: bool = False
    ratio: float = 0.0
    load: float = 0.0
    window: deque = field(default_factory=deque)  # (wall, simulated advanced, busy)


@dataclass(frozen=True)
class Snapshot:
    """The log and the changes of a run as they were when a save was asked for.

    Attributes
    ----------
    run : int
        Which run of the session (a reset starts the next).
    log_t : list of float
        The run's logged times (the session's own list: only rows below ``rows`` are read).
    log_x : list of ndarray
        The run's logged states, as ``log_t``.
    rows : int
        Rows of the log the record holds (>= 1).
    changes : tuple of Change
        The run's changes so far.
    restarts : tuple of float
        Times the integrator restarted so far.
    events : tuple of Event
        The integrator's failures, restarts and holds so far.
    """

    run: int
    log_t: list[float]
    log_x: list[np.ndarray]
    rows: int
    changes: tuple[Change, ...]
    restarts: tuple[float, ...]
    events: tuple[Event, ...] = ()

    @property
    def t_end(self) -> float:
        """The last logged time of the record."""
        return self.log_t[self.rows - 1]


class Session:
    """A live loop, its pacing and its log.

    Parameters
    ----------
    loop : LoopBase
        The engine (:class:`console.engine.LiveLoop`, or a stand-in with the same base).
    recorder : callable, optional
        ``recorder(snapshot) -> dict`` writes the record of a :class:`Snapshot` and
        returns what the page is told (paths); without one, ``save`` is refused.
    clock : callable
        Wall clock in seconds (``time.perf_counter``; tests may pass their own).
    """

    def __init__(self, loop: LoopBase, recorder: Any = None, clock: Any = time.perf_counter):
        self.loop, self.recorder, self.clock = loop, recorder, clock
        self.pace = Pace()
        self.owed = 0.0
        self.last_wall = clock()
        self.run = 0
        self.wall_per_quantum = 0.0  # of the last integrator call
        self._start_log()

    def _start_log(self) -> None:
        self.run += 1
        self.events_logged = 0
        self.peak_u = [0.0] * self.loop.limits.N  # largest |u_i| in a frame from PEAK_FROM on
        self.peak_t = [float("nan")] * self.loop.limits.N
        self.log_t: list[float] = [self.loop.t]
        self.log_x: list[np.ndarray] = [self.loop.x.copy()]
        self.log_full = False

    # ---------------------------------------------------------------- commands
    def handle(self, cmd: Command) -> dict[str, Any] | None:
        """Apply one validated command; a reply for the page, or None.

        Parameters
        ----------
        cmd : Command
            From :func:`console.protocol.parse_message`.

        Changes are accepted while the loop is held (they land when it runs again).

        Raises
        ------
        MessageError
            For a save without a recorder.
        """
        loop = self.loop
        if cmd.kind == "pause":
            self.pace.paused = True
        elif cmd.kind == "resume":
            self.pace.paused = False
            loop.resume()  # a held loop tries again from its last good state
            self.last_wall = self.clock()
        elif cmd.kind == "scale":
            self.pace.scale = cmd.values[0]
        elif cmd.kind == "reset":
            loop.reset()
            self.owed = 0.0
            self._start_log()
        elif cmd.kind == "save":
            return self.save_job()()
        elif cmd.kind == "u0":
            loop.set_u0(cmd.values)
        elif cmd.kind == "health":
            loop.set_health(cmd.follower, cmd.values[0])
        elif cmd.kind == "bias":
            loop.set_bias(cmd.follower, cmd.values)
        elif cmd.kind == "link":
            loop.set_link(cmd.follower, cmd.neighbour, cmd.cut)
        elif cmd.kind == "clear":
            loop.clear(cmd.follower)
        return None

    # ---------------------------------------------------------------- time
    def tick(self) -> dict[str, Any]:
        """Advance by the simulated time the wall clock owes; the frame for the pages."""
        now = self.clock()
        wall = min(max(now - self.last_wall, 0.0), MAX_LAG)
        self.last_wall = now
        advanced, busy = 0.0, 0.0
        if not self.pace.paused and not self.loop.failure:
            # owed time never exceeds one tick's worth: a loop that cannot keep up runs
            # slower than the scale asked for (the ratio says so), it does not burst later
            self.owed = min(self.owed + wall * self.pace.scale, MAX_LAG * self.pace.scale)
            h = self.loop.quantum
            quanta = min(int(math.floor(self.owed / h + 1e-9)), MAX_QUANTA)
            if self.wall_per_quantum > 0:  # frame pacing: a call of about CALL_WALL
                quanta = min(quanta, max(1, int(CALL_WALL / self.wall_per_quantum)))
            if quanta >= 1:
                t_before = self.loop.t
                w0 = self.clock()
                adv = self.loop.advance(quanta)
                busy = self.clock() - w0
                advanced = self.loop.t - t_before
                self.wall_per_quantum = busy / quanta
                self.owed = 0.0 if adv.failure else max(self.owed - quanta * h, 0.0)
                self._log(adv.t, adv.x)
        self._report_events()
        self._measure(now, wall, advanced, busy)
        frame = self.frame()
        self._peak(frame)
        frame["peak_u"], frame["peak_t"] = list(self.peak_u), list(self.peak_t)
        return frame

    def _peak(self, frame: dict[str, Any]) -> None:
        """The largest |u_i| of the frames from :data:`PEAK_FROM` on (a non-finite one wins)."""
        un = frame.get("unorm")
        if un is None or frame["t"] < PEAK_FROM:
            return
        for i, v in enumerate(un):
            v = float("inf") if v is None or not math.isfinite(v) else float(v)
            if v > self.peak_u[i]:
                self.peak_u[i], self.peak_t[i] = v, float(frame["t"])

    def _report_events(self) -> None:
        """The integrator's new events into the console's log (logger ``console``)."""
        events = self.loop.events
        for e in events[self.events_logged :]:
            LOG.warning("t = %.6g s: integrator %s: %s", e.t, e.kind, e.text)
        self.events_logged = len(events)

    def _log(self, t: np.ndarray, x: np.ndarray) -> None:
        room = MAX_LOG_ROWS - len(self.log_t)
        if room < len(t):
            self.log_full = True
        self.log_t.extend(float(v) for v in t[:room])
        self.log_x.extend(np.array(r) for r in x[:room])

    def _measure(self, now: float, wall: float, advanced: float, busy: float) -> None:
        w = self.pace.window
        w.append((now, wall, advanced, busy))
        while w and now - w[0][0] > RATIO_WINDOW:
            w.popleft()
        total = sum(e[1] for e in w)
        self.pace.ratio = sum(e[2] for e in w) / total if total > 0 else 0.0
        self.pace.load = sum(e[3] for e in w) / total if total > 0 else 0.0

    # ---------------------------------------------------------------- view
    def frame(self) -> dict[str, Any]:
        """The state message every page receives."""
        loop = self.loop
        st = loop.target  # what the operator set (it lands at the end of the next call)
        return {
            "type": "state",
            "t": loop.t,
            **loop.signals(loop.x),
            "u0": st.u0.tolist(),
            "health": st.health.tolist(),
            "bias": st.bias.tolist(),
            "cut": [[i + 1, j + 1] for (i, j), w in sorted(st.weights.items()) if w == 0.0],
            "paused": self.pace.paused,
            "scale": self.pace.scale,
            "ratio": self.pace.ratio,
            "load": self.pace.load,
            "steps": loop.steps,
            "failure": loop.failure,
            "events": [[e.t, e.kind, e.text] for e in loop.events[-EVENTS_SHOWN:]],
            "recoveries": sum(e.kind == "recovered" for e in loop.events),
            "ramps": len(loop.ramps),
            "queued": bool(np.any(loop.settings.u0 != st.u0)),
            "slots_full": len(loop.ramps) >= RAMP_SLOTS,
            "changes": len(loop.changes),
            "log_full": self.log_full,
            "peak_u": list(self.peak_u),
            "peak_t": list(self.peak_t),
        }

    def snapshot(self) -> Snapshot:
        """The log and the changes so far (call it on the loop's thread)."""
        loop = self.loop
        return Snapshot(
            self.run,
            self.log_t,
            self.log_x,
            len(self.log_t),
            tuple(loop.changes),
            tuple(loop.restarts),
            tuple(loop.events),
        )

    def save_job(self) -> Callable[[], dict[str, Any]]:
        """Snapshot now; the returned call writes the record and gives the ``saved`` reply.

        The call may run on another thread (the loop goes on meanwhile).

        Raises
        ------
        MessageError
            Without a recorder.
        """
        if self.recorder is None:
            raise MessageError("save: this console has no record folder (start it with --out)")
        recorder, snap = self.recorder, self.snapshot()
        return lambda: {"type": "saved", **recorder(snap)}

    def log_array(self) -> tuple[np.ndarray, np.ndarray]:
        """The logged times and states from t = 0."""
        return np.array(self.log_t), np.array(self.log_x)
