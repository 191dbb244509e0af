"""Failures inside an integrator call: restarts from the last good state, then a hold.

When the integrator stops inside a call, the loop restarts it from the last state
reached with a smaller first step (the ``attempt`` of
:meth:`console.engine.LoopBase.integrate`), up to :data:`MAX_ATTEMPTS` times; each
failure is an :class:`Event` (the session's log, the record's ``events.csv``, the
page). If every attempt fails, or one runs past its wall-time budget
(:data:`ATTEMPT_WALL`, enforced where the attempt runs in a child process:
:mod:`console.calls`), the loop is *held* at the last good state (its ``failure`` says
why); ``resume`` tries again from there and ``reset`` goes back to t = 0. Nothing is
ever retried in a loop without the clock advancing or the loop being held.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the loop calls in here; only its type is needed
    from console.engine import LoopBase
    from generated.values import IntegratorSettings

#: integrator attempts per call before the loop is held (the first one and the restarts)
MAX_ATTEMPTS = 4
#: first step (s) of the first restart after a failure; each further restart takes 1/100 of it
FIRST_STEP = 1e-6
#: wall-time budget (s) of one integrator attempt: past it the attempt is stopped and the
#: loop is held (a retry with more steps would only take longer)
ATTEMPT_WALL = 2.0


@dataclass(frozen=True)
class Event:
    """Something the integrator did that the operator is told about.

    Attributes
    ----------
    t : float
        Simulated time it happened at (the last good state's).
    kind : str
        ``failure`` (an attempt stopped; the loop restarts), ``recovered`` (a restart
        reached the end of the call), ``held`` (every attempt failed) or ``resumed``.
    text : str
        One line: the integrator's reason, or what was done.
    """

    t: float
    kind: str
    text: str


def run_attempts(loop: LoopBase, ks: np.ndarray) -> tuple[list[float], list[np.ndarray], int, str]:
    """Integrate ``loop`` to ``ks[-1]`` quanta, restarting after a failure.

    Each attempt starts from the last state reached (the loop's clock and state move
    with every time reached), and its failure, or a restart's recovery, is logged in
    ``loop.events``.

    Parameters
    ----------
    loop : LoopBase
        The loop; its ``integrate`` makes one attempt.
    ks : ndarray of int
        The quanta of the call, the first one now.

    Returns
    -------
    tuple
        The times and states reached (after the start), the steps taken and, when
        every attempt failed, why (else ``""``).
    """
    ts: list[float] = []
    xs: list[np.ndarray] = []
    steps = 0
    for attempt in range(MAX_ATTEMPTS):
        rest = ks[ks >= loop.k]
        t_out = rest * loop.quantum
        breaks = [rp.end for rp in loop.ramps if t_out[0] < rp.end < t_out[-1]]
        res = loop.integrate(loop.x, t_out, sorted(breaks), attempt)
        reached = len(res.t)  # includes t_out[0]
        if reached > 1:
            loop.k = int(rest[reached - 1])
            loop.x = np.asarray(res.x[-1], dtype=float).copy()
            ts.extend(float(v) for v in res.t[1:])
            xs.extend(np.asarray(r, dtype=float) for r in res.x[1:])
        steps += res.steps
        loop.steps += res.steps
        if not res.failure:
            if attempt:
                loop.events.append(
                    Event(loop.t, "recovered", f"attempt {attempt + 1} reached t = {loop.t:g}")
                )
            return ts, xs, steps, ""
        loop.events.append(Event(loop.t, "failure", res.failure))
        if loop.k > int(rest[0]):  # progress was made: restarts begin there
            loop.restarts.append(loop.t)
        if res.timed_out:
            break
    tried = f"{attempt + 1} integrator attempt{'s' if attempt else ''} failed"
    why = (
        f"held at t = {loop.t:g} s: {tried} ({loop.events[-1].text}); "
        "resume retries from here, reset starts again at t = 0"
    )
    loop.events.append(Event(loop.t, "held", why))
    return ts, xs, steps, why


def restart_settings(
    s: IntegratorSettings,
    t_out: np.ndarray,
    breaks: list[float],
    attempt: int,
    takes_first_step: bool,
) -> tuple[IntegratorSettings, list[float]]:
    """The settings and breakpoints of the k-th restart after a failure (k = ``attempt``).

    10^k × ``max_steps`` and a smaller first step: a method that takes CasADi's options
    gets a first step of :data:`FIRST_STEP` / 100^(k−1) s; the native driver lets CVODE
    choose its first step, so there the first output interval is cut by 10^k − 1
    restarts (each a fresh CVODE start, whose first step CVODE chooses from the
    tolerances and the right-hand side at that point).

    Parameters
    ----------
    s : IntegratorSettings
        The scenario's settings (those of the first attempt, ``attempt`` = 0).
    t_out : ndarray
        Output times of the attempt, the first one now.
    breaks : list of float
        Restart times strictly inside.
    attempt : int
        0 (the settings unchanged), or the restart after a failure.
    takes_first_step : bool
        Whether the method takes a first step through ``extra_options`` (``step0``).
    """
    if not attempt:
        return s, breaks
    s = dataclasses.replace(s, max_steps=int(s.max_steps * 10**attempt))
    if takes_first_step:
        h0 = FIRST_STEP / 100.0 ** (attempt - 1)
        s = dataclasses.replace(s, extra_options=(*s.extra_options, ("step0", h0)))
    else:
        cuts = t_out[0] + (t_out[1] - t_out[0]) * np.arange(1, 10**attempt) / 10**attempt
        breaks = sorted(set(breaks) | {float(c) for c in cuts})
    return s, breaks
