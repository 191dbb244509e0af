"""When a run's integrators stop: output times, restarts at breakpoints, the time resolution.

:func:`schedule` is the one place that reconciles output times with breakpoints; every
method integrates to its targets (docs/simulation.md gives the rules and why).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from core.errors import IntegrationError


def output_grid(horizon: float, output_step: float) -> np.ndarray:
    """Output times ``0, h, 2h, ..., horizon`` (the last one exactly ``horizon``).

    Parameters
    ----------
    horizon : float
    output_step : float
        Must divide ``horizon`` (to 1e-9 relative).
    """
    n = round(horizon / output_step)
    if n < 1 or abs(n * output_step - horizon) > 1e-9 * max(horizon, 1.0):
        raise IntegrationError(
            f"integration.output_step: {output_step} does not divide the horizon {horizon} "
            "(choose a step that does)"
        )
    return np.linspace(0.0, horizon, n + 1)


#: two times closer than this many machine epsilons of the run's time scale are one instant
TIME_ULPS = 1000


def time_tolerance(t0: float, tf: float) -> float:
    """The time resolution of a run over ``[t0, tf]``: ``TIME_ULPS · eps · max(1, |t0|, |tf|)``.

    Above CVODE's ``TOO_CLOSE`` (2 eps |t|) and stop-time (100 eps (|t| + |h|)) thresholds,
    far below any output step (4.4e-12 s at 20 s).

    Parameters
    ----------
    t0, tf : float
    """
    return TIME_ULPS * float(np.finfo(float).eps) * max(1.0, abs(t0), abs(tf))


@dataclass(frozen=True)
class Schedule:
    """Where every integrator of a run stops (:func:`schedule`).

    Every two distinct times among ``t0``, ``breaks`` and ``targets`` are more than
    ``tol`` apart, so no integrator is asked for a time within ``tol`` of where it stands.
    """

    t_out: np.ndarray  # the requested output times: the trajectory's rows keep exactly these
    targets: np.ndarray  # per row: t_out[k], or the breakpoint within tol of it
    breaks: np.ndarray  # restarts in (t0 + tol, tf - tol), sorted, pairwise > tol apart
    tol: float  # time_tolerance of the run

    def segments(self) -> list[tuple[float, float, list[int]]]:
        """``(start, end, rows)`` per segment between restarts; ``rows``: the output rows
        whose target lies in ``(start, end]`` (``end`` is a breakpoint or the horizon)."""
        ends = [*self.breaks.tolist(), float(self.targets[-1])]
        out, k, start = [], 1, float(self.targets[0])
        for end in ends:
            rows = []
            while k < len(self.targets) and self.targets[k] <= end:
                rows.append(k)
                k += 1
            out.append((start, end, rows))
            start = end
        return out


def schedule(t_out: np.ndarray, breakpoints: Sequence[float] = ()) -> Schedule:
    """Reconcile output times with breakpoints (restart times) to the run's time resolution.

    A breakpoint outside ``(t0 + tol, tf - tol)`` or within ``tol`` of an earlier kept one
    is dropped; an output time within ``tol`` of a kept breakpoint is integrated to it.

    Parameters
    ----------
    t_out : ndarray
        Output times, increasing by more than ``2 tol`` (the first is the start).
    breakpoints : sequence of float
        Known discontinuity times, any order.
    """
    t_out = np.asarray(t_out, dtype=float).ravel()
    if t_out.size < 1 or not np.all(np.isfinite(t_out)):
        raise IntegrationError("output times: need at least one, all finite")
    t0, tf = float(t_out[0]), float(t_out[-1])
    tol = time_tolerance(t0, tf)
    if t_out.size > 1 and np.diff(t_out).min() <= 2.0 * tol:
        raise IntegrationError(
            f"output times must increase by more than {2.0 * tol:.3g} s (the time resolution); "
            "choose a larger integration.output_step"
        )
    kept: list[float] = []
    for b in sorted(float(b) for b in breakpoints if math.isfinite(b)):
        if t0 + tol < b < tf - tol and (not kept or b - kept[-1] > tol):
            kept.append(b)
    breaks = np.array(kept, dtype=float)
    return Schedule(t_out=t_out, targets=_targets(t_out, breaks, tol), breaks=breaks, tol=tol)


def _targets(t_out: np.ndarray, breaks: np.ndarray, tol: float) -> np.ndarray:
    """``t_out`` with every time after the first moved to its nearest break (the earlier
    on a tie) if within ``tol``."""
    targets = t_out.copy()
    if not breaks.size or t_out.size < 2:
        return targets
    tk = t_out[1:]
    i = np.searchsorted(breaks, tk)
    lo = breaks[np.maximum(i - 1, 0)]
    hi = breaks[np.minimum(i, breaks.size - 1)]
    d_lo = np.where(i >= 1, np.abs(lo - tk), np.inf)
    d_hi = np.where(i < breaks.size, np.abs(hi - tk), np.inf)
    near = np.where(d_lo <= d_hi, lo, hi)
    move = np.abs(near - tk) <= tol
    targets[1:][move] = near[move]
    return targets
