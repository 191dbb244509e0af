"""How the formation comes back after an operator's step (docs/verification.md, 'Operator steps').

A step of u0 starts at a breakpoint of the leader's command; a shaped step
(``leader.u0_rise``) has two breakpoints ``u0_rise`` apart, and counts from the
first. After each step, the recovery time of a pinned follower is how long its
formation deviation ‖p_i − h_i y0 − R(τ_i⁰) b_i0‖ (the formation of Definition 1,
referenced to the leader's own state) stays above a level before it remains below
it until the next step. Where the leader is too slow for τ_i⁰ to be defined
(below ``options.tau_threshold``) the slot is undefined and those output times are
skipped, so a step taken while the formation has no orientation counts as recovered.
An ``info`` measurement: the theory promises no time.
"""

from __future__ import annotations

import math

import numpy as np

from core.scenario import Scenario
from verify import signals as S
from verify.table import leader_formation

#: the level a pinned follower returns to within its slot
RECOVERY_LEVEL = 0.05


def step_starts(scenario: Scenario) -> list[float]:
    """The times at which an operator step starts (breakpoints of u0, shaped pairs merged).

    Parameters
    ----------
    scenario : Scenario
        Its leader's u0 expressions (a CSV trace gives none).
    """
    L = scenario.leader
    if L.u0 is None:
        return []
    times = sorted({b for e in L.u0 for b in e.breakpoints()})
    # a breakpoint within u0_rise of the one before ends the same shaped step
    return [b for k, b in enumerate(times) if k == 0 or b - times[k - 1] > L.u0_rise + 1e-9]


def deviation(scenario: Scenario, df: S.Frame, h: np.ndarray) -> np.ndarray:
    """‖p_i − h_i y0 − R(τ_i⁰) b_i0‖ per output time and follower, (K, N); NaN where τ⁰ is undefined.

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory.
    h : ndarray
        The gauge.
    """
    L, N, n = scenario.leader, scenario.N, scenario.n
    eta0 = S.take(df, [f"eta0_{k}" for k in range(1, L.m + 1)])
    y0 = eta0 @ np.asarray(L.C0, float).T  # (K, n)
    slots = h[None, :, None] * y0[:, None, :] + leader_formation(scenario, df, h)
    p = np.stack([S.take(df, [f"p{i}_{r}" for r in range(1, n + 1)]) for i in range(1, N + 1)], 1)
    return np.linalg.norm(p - slots, axis=2)


def recovery_time(t: np.ndarray, dev: np.ndarray, start: float, end: float, level: float) -> float:
    """Time from ``start`` until ``dev`` stays at or below ``level`` up to ``end`` (inf if never).

    Parameters
    ----------
    t, dev : ndarray
        Output times and one follower's deviation (NaN samples are skipped).
    start, end : float
        The step and the next step (or the horizon).
    level : float
    """
    w = (t >= start) & (t < end) & np.isfinite(dev)
    tw, above = t[w], dev[w] > level
    if not above.any():
        return 0.0
    last = int(np.flatnonzero(above)[-1])
    return math.inf if last == len(tw) - 1 else float(tw[last + 1] - start)


def worst_recovery(
    scenario: Scenario, df: S.Frame, h: np.ndarray, level: float = RECOVERY_LEVEL
) -> float:
    """The longest recovery time of a pinned follower over every operator step (NaN: no step).

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
    starts = step_starts(scenario)
    pinned = [i for i, b in enumerate(scenario.graph.pinning) if b > 0]
    if not starts or not pinned:
        return math.nan
    t = S.column(df, "t")
    dev = deviation(scenario, df, h)
    ends = [*starts[1:], math.inf]
    return max(
        recovery_time(t, dev[:, i], a, b, level)
        for a, b in zip(starts, ends, strict=True)
        for i in pinned
    )
