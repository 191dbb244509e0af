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

What keeps a pair out: the deviation splits as p_i − s_i = e_ti + (a_i − s_i), with
e_ti = p_i − C0η_i − b_i the controller's tracking error (eq. (28)) and a_i = C0η_i + b_i
the slot the follower aims at, built from its observer's estimate η_i (with b_i from its
η̇_i, eq. (3)): a_i − s_i is the observer's part. Each pair records both parts at its
largest deviation after the limit (in the whole window when it is shorter), the largest
deviation within the limit, and whether the switch changed the follower's own links.

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
    slots,
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
    within : float
        The largest deviation in the first ``limit`` seconds of the window.
    worst : float
        The largest deviation after the limit (in the whole window when it is shorter).
    observer, controller : float
        At that time: ‖a_i − s_i‖, the observer's part, and ‖e_ti‖, the controller's.
    own : bool
        The switch changed one of the follower's own links (weights it receives with).
    """

    start: float
    end: float
    follower: int
    time: float
    outcome: str
    peak: float
    before: float
    within: float = math.nan
    worst: float = math.nan
    observer: float = math.nan
    controller: float = math.nan
    own: bool = False

    @property
    def out(self) -> bool:
        """Not back within the level in time (``late`` or ``undefined``)."""
        return self.outcome in ("late", "undefined")


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
    target = slots(scenario, view, h)
    out = []
    for a, b in spans:
        k0 = int(np.searchsorted(t, a, side="left")) - 1
        own = {s.follower for s in scenario.graph.switches if s.time == a}
        for i in range(scenario.N):
            measured = pair_recovery(t, dev[:, i], a, b, level, limit)
            before = float(dev[k0, i]) if k0 >= 0 else math.nan
            parts = _parts(scenario, view, target, dev[:, i], i, (a, b), limit)
            out.append(SwitchRecovery(a, b, i, *measured, before, *parts, own=i in own))
    return out


def _parts(
    scenario: Scenario,
    view: S.TrajectoryView,
    target: np.ndarray,
    dev: np.ndarray,
    i: int,
    window: tuple[float, float],
    limit: float,
) -> tuple[float, float, float, float]:
    """(within, worst, observer, controller) of follower ``i`` in ``window`` (NaN where
    the window holds no output time or a deviation that is not finite)."""
    t, (a, b) = view.t, window
    w = (t >= a) & (t < b)
    if not w.any() or not np.isfinite(dev[w]).all():
        return (math.nan,) * 4
    first = w & (t < a + limit)
    late = w & (t >= a + limit) if (w & (t >= a + limit)).any() else w
    k = int(np.flatnonzero(late)[np.argmax(dev[late])])
    C0 = np.asarray(scenario.leader.C0, float)
    eta = view.block(S.Signal.ETA, i + 1, scenario.leader.m)[k]
    aim = C0 @ eta + view.block(S.Signal.B, i + 1, scenario.n)[k]
    et = view.block(S.Signal.ET, i + 1, scenario.n)[k]
    return (
        float(dev[first].max()) if first.any() else math.nan,
        float(dev[k]),
        float(np.linalg.norm(aim - target[k, i])),
        float(np.linalg.norm(et)),
    )


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
        and ``switch_deviation_max``; of the pairs not back in time (``late`` or
        ``undefined``): ``switch_out_within`` (within the level for the whole limit, above it
        only later), ``switch_out_own`` (the switch changed the follower's own links),
        ``switch_out_observer`` (the observer's part larger than the controller's at the
        largest deviation after the limit), ``switch_out_worst_max``,
        ``switch_out_observer_max`` and ``switch_out_controller_max`` (the largest of each
        over those pairs; NaN: none).
    """
    out = [r for r in items if r.out]

    def largest(xs: list[float]) -> float:
        xs = [x for x in xs if math.isfinite(x)]
        return max(xs) if xs else math.nan

    return {
        **pooled(items, "switch"),
        "switch_pairs_out_before": sum(bool(r.before > level) for r in items),
        "switch_out_within": sum(bool(r.within <= level) for r in out),
        "switch_out_own": sum(r.own for r in out),
        "switch_out_observer": sum(bool(r.observer > r.controller) for r in out),
        "switch_out_worst_max": largest([r.worst for r in out]),
        "switch_out_observer_max": largest([r.observer for r in out]),
        "switch_out_controller_max": largest([r.controller for r in out]),
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
