"""How the formation comes back after a link is lost or restored (docs/verification.md, 'Link losses').

Every distinct time of ``[[graph.switches]]`` is a switch; its window runs to the next
switch or the horizon. For each (switch, follower) pair the recovery time is how long the
follower's deviation ‖p_i − s_i‖ from its slot s_i = h_i y0 + b(h_i η̇0, b_i0)
(:func:`verify.operator_steps.slots`, the slot the controller tracks once the observer has
converged, computed from the leader's logged state) stays above the level before it
remains below it to the window's end, classified as for operator steps
(:func:`verify.operator_steps.classify`: ``recovered`` within the limit, ``late``,
``undefined`` when the window is shorter than the limit and the follower still out).
Every follower is measured, not only those downstream of the link: a switch must not
throw anyone off. ``out_before`` counts the pairs whose follower was already above the
level at the last output time before the switch (its own transient, not the switch's).

An ``info`` measurement: the theory promises no time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.graph import switch_times
from core.scenario import Scenario
from verify import signals as S
from verify.operator_steps import (
    RECOVERY_LEVEL,
    RECOVERY_LIMIT,
    deviation,
    pair_recovery,
    pooled,
    windows,
)


@dataclass(frozen=True)
class SwitchRecovery:
    """One (switch, follower) pair.

    Attributes
    ----------
    start, end : float
        The switch and the next one (or the horizon) [s].
    follower : int
        0-based.
    time : float
        Recovery time [s] (inf: still out at ``end``; NaN: the slot is not finite).
    outcome : str
        ``recovered``, ``late`` or ``undefined``.
    peak : float
        The largest deviation in the window.
    before : float
        The deviation at the last output time before the switch.
    """

    start: float
    end: float
    follower: int
    time: float
    outcome: str
    peak: float
    before: float


def switch_recoveries(
    scenario: Scenario,
    df: S.FrameOrView,
    h: np.ndarray,
    level: float = RECOVERY_LEVEL,
    limit: float = RECOVERY_LIMIT,
) -> list[SwitchRecovery]:
    """Every (graph switch, follower) pair of a trajectory (empty without switches).

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame or TrajectoryView
        The trajectory.
    h : ndarray
        The gauge.
    level, limit : float
        Defaults :data:`verify.operator_steps.RECOVERY_LEVEL` (0.05) and
        :data:`verify.operator_steps.RECOVERY_LIMIT` (2 s).
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    spans = windows(t, switch_times(scenario.graph.switches))
    if not spans:
        return []
    dev = deviation(scenario, view, h)
    out = []
    for a, b in spans:
        k0 = int(np.searchsorted(t, a, side="left")) - 1
        for i in range(scenario.N):
            measured = pair_recovery(t, dev[:, i], a, b, level, limit)
            before = float(dev[k0, i]) if k0 >= 0 else math.nan
            out.append(SwitchRecovery(a, b, i, *measured, before))
    return out


def switch_summary(items: list[SwitchRecovery], level: float = RECOVERY_LEVEL) -> dict:
    """The study's columns from :func:`switch_recoveries`.

    Parameters
    ----------
    items : list of SwitchRecovery
    level : float
        The level of ``out_before``.

    Returns
    -------
    dict
        ``switch_recovery_s`` (the slowest defined return; NaN: none), ``switch_pairs``,
        ``switch_pairs_late``, ``switch_pairs_undefined``, ``switch_pairs_out_before``
        and ``switch_deviation_max``.
    """
    return {
        **pooled(items, "switch"),
        "switch_pairs_out_before": sum(bool(r.before > level) for r in items),
    }


def peak_u_late(df: S.FrameOrView, N: int, n: int, start: float = 1.0) -> float:
    """max over followers of ‖u_i‖ at output times t ≥ ``start`` (the table's row
    ``peak |u_i| after t = 1 s``, computed from the trajectory alone).

    Parameters
    ----------
    df : DataFrame or TrajectoryView
    N, n : int
        Followers and coordinates.
    start : float
        Start-up time excluded.
    """
    view = S.TrajectoryView.of(df)
    late = view.t >= start
    return float(
        max(
            np.linalg.norm(view.block(S.Signal.U, i, n)[late], axis=1).max()
            for i in range(1, N + 1)
        )
    )
