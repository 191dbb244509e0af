"""The numbers of a sample's result row, measured on its verified run.

Each function reads one part of the run (its bounds table, trajectory, scenario or
meta.json) and returns its columns of the row (:data:`sweep.results.BASE_COLUMNS`,
``t2_entry:<i>``); :func:`sweep.worker.run_sample` puts them together.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd


def library_key(meta: dict[str, Any]) -> str:
    """The key of the compiled library the run executed (meta.json ``library``): its
    content key when meta.json gives one, else the SHA-256 of the library file.

    Samples with equal keys ran the same compiled code (docs/studies.md).

    Parameters
    ----------
    meta : dict
        The run's meta.json content.
    """
    lib = meta.get("library")
    if isinstance(lib, str):
        return lib
    if isinstance(lib, dict) and isinstance(lib.get("key"), str):
        return lib["key"]
    libs = meta.get("libraries") or {}
    main = (lib or {}).get("path")
    if main in libs:
        return libs[main]
    return ",".join(sorted(libs.values()))


def tail_max_et(frame: pd.DataFrame, tail_fraction: float) -> float:
    """max_i sup over the tail window of the Euclidean norm |e_ti| (block ``Signal.ET``).

    Parameters
    ----------
    frame : DataFrame
        The trajectory (its e_ti: n columns per follower).
    tail_fraction : float
        The asymptotic window: the last fraction of the horizon.
    """
    from verify import signals as S

    view = S.TrajectoryView.of(frame)  # one conversion, then columns by position
    t = view.t
    tail = S.tail_mask(t, tail_fraction)
    best = -math.inf
    for i in range(1, view.dims.N + 1):
        e = np.linalg.norm(np.asfortranarray(view.block(S.Signal.ET, i)[tail]), axis=1)
        best = max(best, float(e.max()))
    return best


def topology_in_tail(sc: Any, frame: pd.DataFrame, tail_fraction: float) -> dict[str, Any]:
    """Whether the tail window saw one fixed graph: ``tail_max_et`` is an asymptotic
    error only then; a link lost or recovered in the window puts its transient in it.

    Parameters
    ----------
    sc : Scenario
        Its ``graph.switches`` (link losses and recoveries).
    frame : DataFrame
        The trajectory (column ``t``).
    tail_fraction : float
        The tail window: the last fraction of the horizon (:func:`verify.signals.tail_start`).

    Returns
    -------
    dict
        ``tail_switches``: distinct topology switch times inside the tail window;
        ``last_switch_t``: the last switch time (NaN for a fixed graph).
    """
    from core.graph import switch_times
    from verify.signals import tail_start

    t = frame["t"].to_numpy(float)
    start, end = tail_start(t, tail_fraction), float(t[-1])
    times = switch_times(sc.graph.switches)
    return {
        "tail_switches": sum(1 for s in times if start <= s <= end),
        "last_switch_t": float(times[-1]) if times else math.nan,
    }


def effort_over_demand(ids: list[str], agents: list[Any], observed: np.ndarray) -> float:
    """Largest ratio over followers of peak |u_i| after the start-up to the peak the slot
    demands (:mod:`verify.demanded_effort`); NaN without both rows.

    Parameters
    ----------
    ids, agents : list
        The table's claim ids and agents, row by row.
    observed : ndarray
        Its observed values.
    """
    from verify.demanded_effort import DEMANDED_LATE
    from verify.effort import PEAK_U_LATE

    def by_agent(cid: str) -> dict[Any, float]:
        return {a: float(o) for c, a, o in zip(ids, agents, observed, strict=True) if c == cid}

    late, demand = by_agent(PEAK_U_LATE.id), by_agent(DEMANDED_LATE.id)
    ratios = [late[a] / demand[a] for a in late if demand.get(a, 0.0) > 0.0]
    return max(ratios) if ratios else math.nan


def summarize_table(table: pd.DataFrame) -> dict[str, Any]:
    """The row's numbers from a bounds table (:func:`verify.table.bounds_table`).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.

    Returns
    -------
    dict
        Formation and observer tails, peak |u_i|, Theorem 2 entry times and the verdicts.
    """
    from types import SimpleNamespace

    from verify import claims as CL
    from verify.demanded_effort import DEMANDED_LATE
    from verify.effort import PEAK_U, PEAK_U_LATE

    # plain lists: a few comparisons per row cost less than pandas' methods
    claims, kinds = table["claim"].tolist(), table["kind"].tolist()
    ids = table["claim_id"].tolist()
    # an empty holds (a row that cannot be evaluated) is neither held nor failed
    holds = [h is True or h == True for h in table["holds"].fillna(False).tolist()]  # noqa: E712
    agents = table["agent"].tolist()
    observed = table["observed"].to_numpy(float)

    def max_observed(cid: str) -> float:
        hit = [c == cid for c in ids]
        vals = observed[np.asarray(hit, dtype=bool)]
        vals = vals[~np.isnan(vals)]  # NaN skipped, as pandas' max does
        return float(vals.max()) if vals.size else math.nan

    g = [k for k, kind in enumerate(kinds) if kind == "guaranteed"]
    c = [k for k, kind in enumerate(kinds) if kind == "consistency"]
    failed = [k for k in g if not bool(holds[k])]
    out: dict[str, Any] = {
        "formation_tail_max": max_observed(CL.FORMATION.id),
        "observer_tail_max": max_observed(CL.T1_TAIL.id),
        "peak_u_max": max_observed(PEAK_U.id),
        "peak_u_late": max_observed(PEAK_U_LATE.id),
        "demanded_u_late": max_observed(DEMANDED_LATE.id),
        "effort_over_demand": effort_over_demand(ids, agents, observed),
        "guaranteed_held": all(holds[k] for k in g),
        "guaranteed_failed": "; ".join(
            _label(SimpleNamespace(claim=claims[k], agent=agents[k])) for k in failed
        ),
        "consistency_held": all(holds[k] for k in c),
        "n_guaranteed": len(g),
        "n_consistency": len(c),
    }
    return out


def _label(row: Any) -> str:
    """A table row's claim, with its follower when it has one."""
    agent = getattr(row, "agent", None)
    try:
        return f"{row.claim} (follower {int(agent)})"
    except (TypeError, ValueError):
        return str(row.claim)


def theorem2_entry(
    table: pd.DataFrame, scenario: Any, frame: pd.DataFrame, config: Any
) -> dict[str, Any]:
    """Each follower's Theorem 2 entry time: the comparison-lemma time t_c after which the
    provable variant's bound holds (:func:`verify.bounds.provable_entry_time`, the time
    the report's provable rows start from), else Lemma 1's observed reaching time.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table (for Lemma 1's observed reaching time).
    scenario : Scenario
    frame : DataFrame
        The trajectory.
    config : VerifyConfig
        The verification's settings.

    Returns
    -------
    dict
        ``t2_entry:<i>`` per follower (1-based) and ``t2_entry_source`` (``comparison lemma``,
        ``Lemma 1 observed`` or both, comma-separated).
    """
    from verify.bounds import provable_entry_time, theorem2_constants
    from verify.signals import TrajectoryView

    out: dict[str, Any] = {}
    sources: set[str] = set()
    lem = view = None
    for i in range(scenario.N):
        c = theorem2_constants(scenario, i, config)
        if c.provable:
            if view is None:  # one conversion for every follower
                view = TrajectoryView.of(frame)
            out[f"t2_entry:{i + 1}"] = provable_entry_time(c, view, i, config.lemma1_delta)
            sources.add("comparison lemma")
        else:
            if lem is None:  # the table is searched only when some follower needs it
                from verify import claims as CL

                lem = table[table["claim_id"] == CL.LEMMA1_PAPER.id]
            obs = lem.loc[lem["agent"].astype(str) == str(i + 1), "observed"].astype(float)
            out[f"t2_entry:{i + 1}"] = float(obs.iloc[0]) if len(obs) else math.nan
            sources.add("Lemma 1 observed")
    out["t2_entry_source"] = ",".join(sorted(sources))
    return out


def step_recovery(sc: Any, run: Any) -> dict[str, Any]:
    """How the pinned followers came back to their slots after each operator step.

    Parameters
    ----------
    sc : Scenario
        The sample's scenario (its u0 gives the step times).
    run : verify.pipeline.Run
        The sample's run (its gains give the gauge).

    Returns
    -------
    dict
        ``step_recovery_s`` (seconds; NaN without operator steps), the counts of
        (step, pinned follower) pairs (:func:`verify.operator_steps.recovery_summary`) and
        ``step_peak_u``, the largest torque within 2 s of a step
        (:func:`verify.operator_steps.step_peak_u`).
    """
    from verify.operator_steps import recoveries, recovery_summary, step_peak_u
    from verify.signals import TrajectoryView
    from verify.table import gauge

    view = TrajectoryView.of(run.frame)  # one conversion for both
    items = recoveries(sc, view, gauge(sc, run.gains))
    return {**recovery_summary(items), "step_peak_u": step_peak_u(sc, view)}


def link_recovery(sc: Any, run: Any) -> dict[str, Any]:
    """How every follower came back to its slot after each graph switch.

    Parameters
    ----------
    sc : Scenario
        The sample's scenario (its ``graph.switches``).
    run : verify.pipeline.Run
        The sample's run (its gains give the gauge).

    Returns
    -------
    dict
        :func:`verify.link_recovery.switch_summary`'s columns (``switch_pairs`` 0 and NaN
        times without switches).
    """
    from verify.link_recovery import switch_recoveries, switch_summary
    from verify.table import gauge

    return switch_summary(switch_recoveries(sc, run.frame, gauge(sc, run.gains)))


#: the columns of :func:`stop_columns`, NaN (``stop_state`` empty) for a complete run
STOP_COLUMNS = ("t_reached", "t_stop", "stop_state", "stop_abs", "rows_abs", "switch_before_stop")


def stop_columns(sc: Any, traj: Any, layout: Any) -> dict[str, Any]:
    """Where an integration that stopped early stood: a state that ran away, or an
    integrator stalled on a tame one.

    Parameters
    ----------
    sc : Scenario
        Its graph's switching times.
    traj : Trajectory
        The run (:class:`generated.values.Trajectory`); the native engines give where
        CVODE stood when it returned (``t_stop``, ``x_stop``).
    layout : StateLayout or None
        Names the states (the trajectory.csv columns); not read for a complete run.

    Returns
    -------
    dict
        ``t_reached`` (the last output time), ``t_stop`` (CVODE's last internal step),
        ``stop_state`` and ``stop_abs`` (the largest ``|x|`` there), ``rows_abs`` (the
        largest ``|x|`` of the output rows before), ``switch_before_stop`` (the last
        topology switch at or before ``t_stop``); NaN where the run is complete or the
        method does not say.
    """
    from core.graph import switch_times

    out: dict[str, Any] = dict.fromkeys(STOP_COLUMNS, math.nan)
    out["stop_state"] = ""
    out["t_reached"] = float(traj.t_reached)
    k = traj.largest_at_stop()
    if traj.complete or k is None:
        return out
    before = [t for t in switch_times(sc.graph.switches) if t <= traj.t_stop]
    x = np.asarray(traj.x, dtype=float)
    out.update(
        t_stop=float(traj.t_stop),
        stop_state=layout.name_of(k),
        stop_abs=float(abs(traj.x_stop[k])),
        rows_abs=float(np.nanmax(np.abs(x))) if x.size else math.nan,
        switch_before_stop=float(before[-1]) if before else math.nan,
    )
    return out
