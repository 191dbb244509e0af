"""How the formation comes back after an operator's step (docs/verification.md, 'Operator steps').

A step of u0 starts at the earliest kink of its atom, raw or shaped
(:func:`core.shaping.step_onsets`). A pinned follower's slot is where the controller
steers it once the observer has converged (η_i = h_i η0): eq. (28)'s
``C0 η_i + b_i`` at η_i = h_i η0, i.e.

    s_i = h_i y0 + b(h_i η̇0, b_i0),   η̇0 = A0 η0 + B0 u0(t)   (eq. (3)),

with ``b(d, b0)`` the formation rule the controller uses, *including* its blend to b_i0
below ``options.tau_threshold`` (docs/closed-loop.md, 'Formation rule where η̇_i ≈ 0'),
evaluated here with numpy from the logged leader state (:func:`formation_rule`): never
the controller's own b_i output, and defined at every output time.

After each step (a window up to the next step or the horizon), a pinned follower's
recovery time is how long its deviation ‖p_i − s_i‖ stays above a level before it
remains below it to the window's end. Each (step, pinned follower) pair is one of:

- ``recovered``: back within the level by ``limit`` seconds after the step and staying;
- ``late``: back only later, or never in a window of at least ``limit`` seconds;
- ``undefined``: still out when the next step (or the horizon) comes less than
  ``limit`` seconds after this one, or the slot is not finite in the window: the
  promise cannot be checked there, and the pair is counted as such.

An ``info`` measurement: the theory promises no time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from core.scenario import Scenario
from core.shaping import step_onsets
from verify import signals as S

#: the level a pinned follower returns to within its slot
RECOVERY_LEVEL = 0.05
#: seconds after each step by which a pinned follower should be back within the level
RECOVERY_LIMIT = 2.0


def step_starts(scenario: Scenario) -> list[float]:
    """The times at which an operator step starts (:func:`core.shaping.step_onsets`).

    Parameters
    ----------
    scenario : Scenario
        Its leader's u0 expressions (a CSV trace gives none).
    """
    u0 = scenario.leader.u0
    return [] if u0 is None else step_onsets(u0)


def formation_rule(d: np.ndarray, b0: np.ndarray, eps: float) -> np.ndarray:
    """The controller's planar formation rule b(d, b0), written out with numpy.

    With σ = ‖d‖², u = σ/ε², w = max(1 − u, 0) (docs/closed-loop.md, 'Formation rule'):
    b = [[d1 q, −d2 q], [d2 q, d1 q]] b0 + κ b0, q = 1/√σ for σ ≥ ε² (the rotation
    R(atan2(d2, d1)) b0), q = (1 + w/2 + 3w²/8 + 5w³/16)/ε below, κ = w⁴(5 − 4w).

    Parameters
    ----------
    d : ndarray
        (K, 2): the first two entries of η̇ at each time.
    b0 : ndarray
        (2,): the formation vector b_i0.
    eps : float
        ε, ``options.tau_threshold``.

    Returns
    -------
    ndarray
        (K, 2).
    """
    d = np.asarray(d, float)
    d1, d2 = d[:, 0], d[:, 1]
    sig = d1**2 + d2**2
    w = np.maximum(1.0 - sig / eps**2, 0.0)
    inner = sig < eps**2
    with np.errstate(divide="ignore"):
        q = np.where(inner, (1 + w / 2 + 3 * w**2 / 8 + 5 * w**3 / 16) / eps, 1 / np.sqrt(sig))
    kappa = w**4 * (5 - 4 * w)
    bx, by = float(b0[0]), float(b0[1])
    return np.stack([q * (d1 * bx - d2 * by) + kappa * bx, q * (d2 * bx + d1 * by) + kappa * by], 1)


def slots(scenario: Scenario, df: S.FrameOrView, h: np.ndarray) -> np.ndarray:
    """Every follower's slot s_i = h_i y0 + b(h_i η̇0, b_i0) per output time, (K, N, n).

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory (``t`` and the leader's ``eta0_k``).
    h : ndarray
        The gauge.
    """
    L, N = scenario.leader, scenario.N
    view = S.TrajectoryView.of(df)
    t = view.t
    eta0 = view.leader(L.m)
    y0 = eta0 @ np.asarray(L.C0, float).T  # (K, n)
    b0 = np.array([fo.b0 for fo in scenario.followers], float)  # (N, n)
    out = h[None, :, None] * y0[:, None, :] + b0[None, :, :]
    if scenario.n != 2 or L.m < 2:
        return out  # no planar rotation: b_i = b_i0, as in the closed loop
    etadot0 = eta0 @ np.asarray(L.A0, float).T + (np.asarray(L.B0, float) @ L.u0_numpy(t)).T
    for i in range(N):  # eq. (3)
        d = h[i] * etadot0[:, :2]
        out[:, i, :] = h[i] * y0 + formation_rule(d, b0[i], scenario.options.tau_threshold)
    return out


def deviation(scenario: Scenario, df: S.FrameOrView, h: np.ndarray) -> np.ndarray:
    """‖p_i − s_i‖ per output time and follower, (K, N) (:func:`slots`).

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory.
    h : ndarray
        The gauge.
    """
    N, n = scenario.N, scenario.n
    view = S.TrajectoryView.of(df)
    p = np.stack([view.block(S.Signal.P, i, n) for i in range(1, N + 1)], 1)
    return np.linalg.norm(p - slots(scenario, view, h), axis=2)


def recovery_time(t: np.ndarray, dev: np.ndarray, start: float, end: float, level: float) -> float:
    """Time from ``start`` until ``dev`` stays at or below ``level`` up to ``end`` (inf if never).

    Parameters
    ----------
    t, dev : ndarray
        Output times and one follower's deviation (NaN anywhere in the window gives NaN).
    start, end : float
        The step and the next step (or the horizon).
    level : float
    """
    w = (t >= start) & (t < end)
    tw, dw = t[w], dev[w]
    if not len(tw) or not np.isfinite(dw).all():
        return math.nan
    above = dw > level
    if not above.any():
        return 0.0
    last = int(np.flatnonzero(above)[-1])
    return math.inf if last == len(tw) - 1 else float(tw[last + 1] - start)


@dataclass(frozen=True)
class StepRecovery:
    """One (operator step, pinned follower) pair.

    Attributes
    ----------
    start : float
        The step's onset [s].
    end : float
        The next step's onset, or the horizon [s].
    follower : int
        0-based.
    time : float
        Recovery time [s] (inf: still out at ``end``; NaN: the slot is not finite).
    outcome : str
        ``recovered``, ``late`` or ``undefined`` (module docstring).
    peak : float
        The largest deviation ‖p_i − s_i‖ in the window (NaN: not finite).
    """

    start: float
    end: float
    follower: int
    time: float
    outcome: str
    peak: float


def classify(time: float, window: float, limit: float) -> str:
    """``recovered``, ``late`` or ``undefined`` for a recovery time in a window of that length.

    Parameters
    ----------
    time : float
        From :func:`recovery_time`.
    window : float
        Seconds from the step to the next step or the horizon.
    limit : float
        The promised recovery time.
    """
    if math.isnan(time):
        return "undefined"
    if math.isinf(time):
        return "late" if window >= limit else "undefined"
    return "recovered" if time <= limit else "late"


def windows(t: np.ndarray, starts: list[float]) -> list[tuple[float, float]]:
    """Each event's window inside the output times: (start, next start or the horizon).

    Parameters
    ----------
    t : ndarray
        Output times; events after the last one are left out.
    starts : list of float
        The events' times, ascending.
    """
    horizon = float(t[-1]) + 1e-12  # the last output time is inside the last window
    inside = [s for s in starts if s < horizon]
    return list(zip(inside, [*inside[1:], horizon][: len(inside)], strict=True))


def pair_recovery(
    t: np.ndarray, dev: np.ndarray, start: float, end: float, level: float, limit: float
) -> tuple[float, str, float]:
    """One (event, follower) pair: its recovery time, outcome and peak deviation in the window.

    Parameters
    ----------
    t, dev : ndarray
        Output times and the follower's deviation.
    start, end : float
        The window.
    level, limit : float
        As in :func:`recovery_time` and :func:`classify`.

    Returns
    -------
    (time, outcome, peak)
        :func:`recovery_time`, :func:`classify`, and the largest deviation in the window
        (NaN: none or not finite).
    """
    r = recovery_time(t, dev, start, end, level)
    w = dev[(t >= start) & (t < end)]
    peak = float(w.max()) if len(w) and np.isfinite(w).all() else math.nan
    return r, classify(r, end - start, limit), peak


class _Pair(Protocol):
    time: float
    outcome: str
    peak: float


def pooled(items: Sequence[_Pair], prefix: str) -> dict[str, float | int]:
    """A study's columns from (event, follower) pairs, named ``<prefix>_...``.

    Parameters
    ----------
    items : sequence of StepRecovery or verify.link_recovery.SwitchRecovery
    prefix : str
        ``step`` or ``switch``.

    Returns
    -------
    dict
        ``<prefix>_recovery_s``: the longest recovery time of the pairs that are not
        ``undefined`` (inf: one never came back; NaN: none); ``<prefix>_deviation_max``:
        the largest finite peak deviation (NaN: none); ``<prefix>_pairs``,
        ``<prefix>_pairs_late``, ``<prefix>_pairs_undefined``: how many pairs in all and of
        each kind.
    """
    defined = [r.time for r in items if r.outcome != "undefined"]
    peaks = [r.peak for r in items if math.isfinite(r.peak)]
    return {
        f"{prefix}_recovery_s": max(defined) if defined else math.nan,
        f"{prefix}_deviation_max": max(peaks) if peaks else math.nan,
        f"{prefix}_pairs": len(items),
        f"{prefix}_pairs_late": sum(r.outcome == "late" for r in items),
        f"{prefix}_pairs_undefined": sum(r.outcome == "undefined" for r in items),
    }


def recoveries(
    scenario: Scenario,
    df: S.FrameOrView,
    h: np.ndarray,
    level: float = RECOVERY_LEVEL,
    limit: float = RECOVERY_LIMIT,
) -> list[StepRecovery]:
    """Every (operator step, pinned follower) pair of a trajectory (empty: no step or no pin).

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory.
    h : ndarray
        The gauge.
    level, limit : float
        Defaults :data:`RECOVERY_LEVEL`, :data:`RECOVERY_LIMIT`.
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    spans = windows(t, step_starts(scenario))
    pinned = [i for i, b in enumerate(scenario.graph.pinning) if b > 0]
    if not spans or not pinned:
        return []
    dev = deviation(scenario, view, h)
    return [
        StepRecovery(a, b, i, *pair_recovery(t, dev[:, i], a, b, level, limit))
        for a, b in spans
        for i in pinned
    ]


def recovery_summary(items: list[StepRecovery]) -> dict[str, float | int]:
    """The study's columns from :func:`recoveries`.

    Parameters
    ----------
    items : list of StepRecovery

    Returns
    -------
    dict
        ``step_recovery_s``: the longest recovery time of the pairs that are not
        ``undefined`` (inf: one never came back; NaN: none); ``step_pairs``,
        ``step_pairs_late``, ``step_pairs_undefined``: how many pairs in all and of each
        kind; ``step_deviation_max``: the largest deviation from the slot after a step (NaN
        if none is finite).
    """
    return pooled(items, "step")


def step_peak_u(scenario: Scenario, df: S.FrameOrView, window: float = RECOVERY_LIMIT) -> float:
    """The largest ‖u_i‖ of any follower within ``window`` seconds after a step's onset.

    Separates what a step costs from the torque the leader's speed asks for anyway (the
    peak after t = 1 s of the whole run, ``peak |u_i| after t = 1 s``, includes both).

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory (columns ``u<i>_<r>``).
    window : float
        Seconds after each onset; default :data:`RECOVERY_LIMIT`.

    Returns
    -------
    float
        NaN without a step inside the output times.
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    near = np.zeros(len(t), bool)
    for a in step_starts(scenario):
        near |= (t >= a) & (t <= a + window)
    if not near.any():
        return math.nan
    N, n = scenario.N, scenario.n
    # the Euclidean norm per follower, as the table's row `peak |u_i| after t = 1 s`
    norms = [
        np.linalg.norm(view.block(S.Signal.U, i, n)[near], axis=1).max() for i in range(1, N + 1)
    ]
    return float(max(norms))


def worst_recovery(
    scenario: Scenario, df: S.FrameOrView, h: np.ndarray, level: float = RECOVERY_LEVEL
) -> float:
    """The longest recovery time of a pinned follower over the steps where it is defined.

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory.
    h : ndarray
        The gauge.
    level : float
        Default :data:`RECOVERY_LEVEL`.
    """
    return float(recovery_summary(recoveries(scenario, df, h, level))["step_recovery_s"])
