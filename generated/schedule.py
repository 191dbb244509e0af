"""When a run's integrators stop: output times, restarts at breakpoints, the time resolution.

:func:`schedule` is the one place that reconciles output times with breakpoints (fault
onsets, steps in inputs): the CasADi methods' chunk loop (:mod:`generated.solvers.engine`)
and the native driver (:mod:`generated.native`) both integrate to its targets.
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
        Final time (s).
    output_step : float
        Spacing ``h`` of the output times (s); must divide ``horizon``.

    Raises
    ------
    IntegrationError
        If the step does not divide the horizon (to 1e-9 relative).
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

    CVODE refuses an output time within ``2 eps |t|`` of the current time (``TOO_CLOSE``)
    and takes a stop time within ``100 eps (|t| + |h|)`` as reached; 1000 eps of the
    time scale lies above both and far below any output step (4.4e-12 s at 20 s).

    Parameters
    ----------
    t0, tf : float
        First and last output time.
    """
    return TIME_ULPS * float(np.finfo(float).eps) * max(1.0, abs(t0), abs(tf))


@dataclass(frozen=True)
class Schedule:
    """Where every integrator of a run stops: restarts and the time integrated to per row.

    Made by :func:`schedule`, the one place that reconciles output times with breakpoints
    (the CasADi methods here, and the native driver, which receive ``targets`` and
    ``breaks``). Every two distinct times among ``t0``, ``breaks`` and ``targets`` are
    more than ``tol`` apart, so no integrator is asked for a time within ``tol`` of the
    time it stands at.

    Attributes
    ----------
    t_out : ndarray
        The requested output times; the trajectory's rows keep exactly these.
    targets : ndarray
        The time integrated to for each row: ``t_out[k]``, or the breakpoint within
        ``tol`` of it (the row then holds the state at that breakpoint, reached by the
        segment that ends there; it differs from the state at ``t_out[k]`` by at most
        ``tol · |ẋ|``).
    breaks : ndarray
        Restart times, strictly inside ``(t0 + tol, tf - tol)``, sorted, pairwise more
        than ``tol`` apart.
    tol : float
        :func:`time_tolerance` of the run.
    """

    t_out: np.ndarray
    targets: np.ndarray
    breaks: np.ndarray
    tol: float

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

    A breakpoint within ``tol`` (:func:`time_tolerance`) of ``t0``, of the horizon or of
    an earlier kept breakpoint is dropped (the run starts, stops or restarts there
    already), as is one outside ``(t0, tf)``; an output time within ``tol`` of a kept
    breakpoint is integrated to that breakpoint (:attr:`Schedule.targets`).

    Parameters
    ----------
    t_out : ndarray
        Output times, increasing by more than ``2 tol`` (the first is the start).
    breakpoints : sequence of float
        Known discontinuity times, any order.

    Returns
    -------
    Schedule

    Raises
    ------
    IntegrationError
        If the output times are not finite, or two are within ``2 tol`` of each other.
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
    """``t_out`` with every time after the first moved to its nearest break if within ``tol``.

    The nearest of the two breaks around ``t_out[k]`` (the earlier on a tie), for all
    rows at once.
    """
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
