"""The bound-vs-actual table: one row per agent × component × claim.

Columns (:data:`verify.rows.COLUMNS`): ``claim, agent, component, kind, bound, observed,
ratio, holds, window, note, claim_id, t_start, t_end, depends``. Every row names a claim
of the registry (:mod:`verify.claims`); ``kind`` says what a failure means:

- ``guaranteed``: follows from the theory for this reconstruction (a failure is a
  bug; ``make verify`` exits 1);
- ``consistency``: cannot fail for a correct implementation of the shipped laws, so
  it is no evidence for a theorem; a failure means the simulated closed loop
  differs from its derivation (a bug; ``make verify`` exits 1);
- ``paper``: the paper's own claim where it does not follow as printed
  (docs/fidelity.md, deviations); ``--strict`` makes these fail too;
- ``info``: a measurement with no pass/fail (``holds`` is still shown), or a row the
  derivation gives that this run cannot evaluate (``holds`` empty, the note says why).

With an actuator limit (``controller.u_max``) that a run reaches, the rows whose claim
depends on the unsaturated control law (29) become ``info`` with the note
``invalidated: saturation active on [t_a, t_b] s`` (:func:`mark_saturation`).
On a switching graph (``[[graph.switches]]``) the rows built on V1 of the base graph
become ``info`` with the note ``invalidated by switching topology``
(:func:`mark_switching`). Theorem 2 is restarted per follower at its health switches, at
the operator's steps that reach it and at switches of its neighbourhood
(:mod:`verify.intervals`, :mod:`verify.theorem2_rows`; docs/verification.md,
'Theorem 2 on intervals').
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from core.graph import switch_times
from core.scenario import Scenario
from synthesis.gains import Gains
from verify import claims as CL
from verify import signals as S
from verify.bounds import VerifyConfig
from verify.checks import CheckInput, registered_rows
from verify.claims import BUG_KINDS
from verify.effort import STARTUP  # noqa: F401 - report, pipeline and tests read it here
from verify.intervals import follower_pieces
from verify.lyapunov import InequalityCheck
from verify.rows import COLUMNS, KINDS, Rows, Span, failed_mask, held_mask, win
from verify.theorem2_rows import (
    PAPER_NOTE,
    definition1_rows,
    gauge,
    interval_windows,
    leader_formation,
    theorem2_rows,
)

__all__ = [
    "BUG_KINDS",
    "COLUMNS",
    "FIG13_LEVEL_FACTOR",
    "KINDS",
    "PAPER_NOTE",
    "SATURATION_NOTE",
    "STARTUP",
    "SWITCHING_CLAIMS",
    "SWITCHING_NOTE",
    "Rows",
    "Span",
    "bounds_table",
    "definition1_rows",
    "failures",
    "gauge",
    "held_mask",
    "leader_formation",
    "mark_saturation",
    "mark_switching",
    "to_markdown",
]

#: Fig. 13: the entering level is this factor times the larger of both runs' tail suprema
FIG13_LEVEL_FACTOR = 3.0
#: a logged |u_ir| within this relative distance of u_max_i is at the limit
SATURATION_RTOL = 1e-9
#: the note's start on rows the saturation invalidates
SATURATION_NOTE = "invalidated: saturation active on"
#: the claims built on V1 (17) of the base graph or on V2 integrated from t = 0 (the registry's
#: :attr:`verify.claims.Dep.BASE_GRAPH`), by text
SWITCHING_CLAIMS = tuple(
    c.render(level=0).split("{")[0] for c in CL.REGISTRY.values() if CL.Dep.BASE_GRAPH in c.depends
)
#: the note's start on rows a switching graph invalidates
SWITCHING_NOTE = "invalidated by switching topology"


def bounds_table(
    scenario: Scenario,
    df: pd.DataFrame,
    *,
    gains: Gains | None = None,
    theorem1: list[InequalityCheck] | None = None,
    theorem2: list[InequalityCheck] | None = None,
    ablation: pd.DataFrame | None = None,
    config: VerifyConfig | None = None,
    u0_dep: np.ndarray | None = None,
) -> pd.DataFrame:
    """Build the bound-vs-actual table from a trajectory and (optionally) the AD checks.

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory (``trajectory.csv`` columns).
    gains : Gains, optional
        Needed for Theorem 1's rates.
    theorem1 : list of InequalityCheck, optional
        [supported-rate check, printed-rate check] from :func:`verify.lyapunov.check_theorem1`.
    theorem2 : list of InequalityCheck, optional
        One per follower from :func:`verify.lyapunov.check_theorem2`.
    ablation : DataFrame, optional
        The eq. (42) run for the convergence comparison.
    config : VerifyConfig, optional
    u0_dep : ndarray of bool, optional
        Which followers' χ_i depend on u0 (:func:`verify.intervals.u0_dependence`);
        default every follower (an operator step restarts them all).

    Returns
    -------
    DataFrame
        Columns :data:`COLUMNS`.
    """
    cfg = config or VerifyConfig()
    view = S.TrajectoryView.of(df)  # converted once: every row below reads this array
    dm = view.dims
    _check_dims(scenario, dm)
    span = Span.of(view, cfg)
    dep = np.ones(dm.N, bool) if u0_dep is None else np.asarray(u0_dep, bool)
    windows = [
        interval_windows(scenario, view, i, follower_pieces(scenario, i, bool(dep[i])), cfg)
        for i in range(dm.N)
    ]
    R = Rows()
    theorem1_rows(R, scenario, view, span, gains=gains, config=cfg)
    theorem1_lyapunov_rows(R, theorem1 or [], scenario, span, gains=gains)
    theorem2_rows(R, scenario, view, span, theorem2 or [], windows, config=cfg)
    definition1_rows(R, scenario, view, gains=gains, config=cfg, windows=windows)
    inp = CheckInput(scenario, view.columns, gains, cfg, span, windows)
    registered_rows(R, inp)  # verify/checks.py
    if ablation is not None:
        other = S.TrajectoryView.of(ablation)
        for i in range(dm.N):
            ablation_rows(R, view, other, i, dm.n, cfg)
    table = mark_saturation(R.frame(), saturation_window(scenario, view))
    return mark_switching(table, scenario)


def mark_switching(table: pd.DataFrame, scenario: Scenario) -> pd.DataFrame:
    """The rows whose claim depends on the base graph as ``info``, noted, when the graph switches.

    V1 (17) is built on the base graph's Lemma 3 Z and l̄_ii; after the first switch
    Theorem 1's inequality for it no longer follows from the proof (it may still hold), so
    its rows, the decay rate taken from the base graph's w, the Definition 1 bound that
    integrates V1, and Lemma 1's reaching time from V2(0) (V2 may jump at a switch) are
    neither passes nor failures. So are the paper's rows (asymptotic claims measured on a
    window) whose window holds a switch: there they measure the switch's transient.
    Theorem 2's provable rows restart at the switches instead (:mod:`verify.intervals`).
    Without switches the table is returned unchanged.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    scenario : Scenario
        Its ``graph.switches``.
    """
    times = switch_times(scenario.graph.switches)
    if not times:
        return table
    out = table.copy()
    notes = {}
    for k, (cid, kind, a, b) in enumerate(
        zip(out["claim_id"], out["kind"], out["t_start"], out["t_end"], strict=True)
    ):
        inside = [ts for ts in times if a <= ts <= b]
        if CL.depends(cid, CL.Dep.BASE_GRAPH):
            notes[k] = f"{SWITCHING_NOTE} (first switch at t = {times[0]:g} s)"
        elif kind == CL.Kind.PAPER.value and inside:
            notes[k] = f"{SWITCHING_NOTE} (a switch at t = {inside[0]:g} s lies in the window)"
    if not notes:
        return out
    kinds, olds = out["kind"].tolist(), out["note"].tolist()
    for k, note in notes.items():  # the two columns written whole: one assignment each
        kinds[k] = CL.Kind.INFO.value
        olds[k] = f"{note}; {olds[k]}" if olds[k] else note
    out["kind"] = pd.Series(kinds, index=out.index, dtype=out["kind"].dtype)
    out["note"] = pd.Series(olds, index=out.index, dtype=out["note"].dtype)
    return out


def saturation_window(scenario: Scenario, df: S.FrameOrView) -> tuple[float, float] | None:
    """First and last output time at which some logged |u_ir| is at its limit u_max_i.

    The logged ``u`` columns hold the applied, clipped torque, so the limit is met
    exactly while a component saturates.

    Parameters
    ----------
    scenario : Scenario
        Its ``controller.u_max`` (None: no limit, no window).
    df : DataFrame
        The trajectory.

    Returns
    -------
    tuple of float or None
        ``(t_a, t_b)``, or None when no component reaches its limit at an output time.
    """
    u_max = scenario.controller.u_max
    if u_max is None:
        return None
    view = S.TrajectoryView.of(df)
    hit = np.zeros(len(view), dtype=bool)
    for i in range(view.dims.N):
        u = np.abs(view.block(S.Signal.U, i + 1))
        hit |= np.any(u >= u_max[i] * (1.0 - SATURATION_RTOL), axis=1)
    if not hit.any():
        return None
    t = view.t[hit]
    return float(t[0]), float(t[-1])


def mark_saturation(table: pd.DataFrame, window: tuple[float, float] | None) -> pd.DataFrame:
    """The rows of :data:`SATURATION_CLAIMS` as ``info``, noted, when saturation was active.

    Theorem 2, eq. (38), Lemmas 1–2 and Definition 1 assume the follower receives
    g_i ĝ_i Ψ_i; once the torque is clipped that no longer holds, so these rows are
    neither passes nor failures. Without a window the table is returned unchanged.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    window : tuple of float or None
        :func:`saturation_window` of the run.
    """
    if window is None:
        return table
    out = table.copy()
    sel = out["claim_id"].map(lambda c: CL.depends(c, CL.Dep.SATURATION)).astype(bool)
    note = f"{SATURATION_NOTE} {win(*window)}"
    out.loc[sel, "kind"] = "info"
    out.loc[sel, "note"] = [f"{note}; {n}" if n else note for n in out.loc[sel, "note"]]
    return out


def _check_dims(scenario: Scenario, dm: S.Dims) -> None:
    """Raise :class:`VerifyError` when the trajectory's sizes are not the scenario's."""
    if dm.N != scenario.N or dm.n != scenario.n or dm.m != scenario.m:
        raise S.VerifyError(
            f"trajectory has N={dm.N}, n={dm.n}, m={dm.m} but scenario {scenario.name!r} has "
            f"N={scenario.N}, n={scenario.n}, m={scenario.m}: re-run the simulation"
        )


def theorem1_rows(
    R: Rows,
    scenario: Scenario,
    df: S.FrameOrView,
    span: Span,
    *,
    gains: Gains | None = None,
    config: VerifyConfig | None = None,
) -> None:
    """Theorem 1 (observer) from the trajectory: decay rate, entering time, tail sup (info).

    Parameters
    ----------
    R : Rows
        Rows to append to.
    scenario : Scenario
    df : DataFrame
        The trajectory; followers without ``eeta`` columns end the rows.
    span : Span
        Its time grid and windows.
    gains : Gains, optional
        Needed for the decay-rate row (Theorem 1's supported rate).
    config : VerifyConfig, optional
    """
    cfg = config or VerifyConfig()
    view = S.TrajectoryView.of(df)
    t, tail = span.t, span.tail
    floor = scenario.observer.phi_min > 0
    for i in range(view.dims.N):
        if not view.has(S.Signal.EETA, i + 1):
            break
        e = view.norm(S.Signal.EETA, i + 1)
        if gains is not None:
            from verify.bounds import theorem1_rates

            R.add(
                CL.T1_RATE,
                CL.Kind.INFO,
                theorem1_rates(scenario, gains).supported / 2.0,
                S.decay_rate(t[tail], e[tail], floor=1e-12),
                span.tail_window,
                "phi floor: only ultimately bounded" if floor else "V1 >= c|ebar|^2",
                agent=i,
                larger_is_better=True,
            )
        te = S.enter_time(t, e, cfg.enter_level)
        R.add(
            CL.T1_ENTER,
            CL.Kind.INFO,
            span.t1,
            te,
            span.full,
            "inf = never stays inside" if not math.isfinite(te) else "",
            agent=i,
            text={"level": cfg.enter_level},
        )
        R.add(
            CL.T1_TAIL,
            CL.Kind.INFO,
            cfg.enter_level,
            float(e[tail].max()),
            span.tail_window,
            f"phi_min = {scenario.observer.phi_min:g}" if floor else "",
            agent=i,
        )


def _theorem1_kind(label: str, certified: bool, floor: bool) -> str:
    """What a failure of Theorem 1's ``label`` check means (see the module docstring)."""
    if not certified:  # the proof needs gains that pass the LMIs
        return "info"
    if label == "floor":  # V̇1 ≤ −δ̃V1 + c_φ: the proof's inequality with φ_min > 0
        return "guaranteed"
    if floor:  # the floor leaves c_φ > 0 on the right: V̇1 ≤ −δ̃V1 does not follow
        return "info"
    return "guaranteed" if label == "supported" else "paper"


def _theorem1_note(chk: InequalityCheck, label: str, certified: bool, floor: bool) -> str:
    """The note of Theorem 1's ``label`` check row."""
    note = (
        f"worst violation {chk.worst:.3g} at t = {chk.t_worst:.3g} s"
        if not chk.ok
        else "holds at every output time"
    )
    if label == "floor":
        note += "; supported rate, c_phi from the floor (docs/verification.md)"
    elif floor:
        note += "; phi floor > 0 breaks the proof's last step (ultimately bounded)"
    if not certified:
        note += "; the gains' certificate does not pass"
    return note


def theorem1_lyapunov_rows(
    R: Rows,
    checks: list[InequalityCheck],
    scenario: Scenario,
    span: Span,
    *,
    gains: Gains | None = None,
) -> None:
    """Theorem 1's exact dV1/dt inequalities: the fraction of output times where each holds.

    Parameters
    ----------
    R : Rows
        Rows to append to.
    checks : list of InequalityCheck
        [supported rate, printed rate, floor] (a prefix) from
        :func:`verify.lyapunov.check_theorem1`.
    scenario : Scenario
    span : Span
        The trajectory's time grid.
    gains : Gains, optional
        Their certificate decides whether the rows are guaranteed.
    """
    floor = scenario.observer.phi_min > 0
    certified = gains is None or bool(getattr(gains, "certificate", {}).get("passed", True))
    for chk, label in zip(checks, ("supported", "printed", "floor"), strict=False):
        R.add(
            {"floor": CL.T1_FLOOR, "supported": CL.T1_SUPPORTED, "printed": CL.T1_PRINTED}[label],
            _theorem1_kind(label, certified, floor),
            1.0,
            chk.fraction,
            span.full,
            _theorem1_note(chk, label, certified, floor),
            holds=chk.ok,
            larger_is_better=True,
        )


def ablation_rows(
    R: Rows, df: S.FrameOrView, ablation: S.FrameOrView, i: int, n: int, cfg: VerifyConfig
) -> None:
    """Fig. 13 (the ablation (42) converges more slowly) for follower ``i``.

    The verdict row enters a level set by both runs' own tails: FIG13_LEVEL_FACTOR ×
    max(tail sup FTC, tail sup ablation), so it measures the approach, not the noise
    floor; the fixed 1e-2 reading and least-squares decay rates of ‖e_ti‖ on the
    common window [t0, min of both entering times] stand beside it.

    Parameters
    ----------
    R : Rows
        Rows to append to.
    df, ablation : DataFrame
        The FTC (29) run and the eq. (42) ablation run.
    i : int
        0-based follower.
    n : int
        Number of outputs.
    cfg : VerifyConfig
        Its tail fraction sets the tail suprema.
    """
    fv, av = S.TrajectoryView.of(df), S.TrajectoryView.of(ablation)
    t, ta = fv.t, av.t
    ft, ab = fv.norm(S.Signal.ET, i + 1, n), av.norm(S.Signal.ET, i + 1, n)
    tail, abt = S.tail_mask(t, cfg.tail_fraction), S.tail_mask(ta, cfg.tail_fraction)
    sup_ft, sup_ab = float(ft[tail].max()), float(ab[abt].max())
    full = (float(t[0]), float(t[-1]))
    lvl = FIG13_LEVEL_FACTOR * max(sup_ft, sup_ab)
    t_ft, t_ab = S.enter_time(t, ft, lvl), S.enter_time(ta, ab, lvl)
    R.add(  # the paper's claim (Fig. 13): the ablation needs more time to converge
        CL.FIG13_VERDICT,
        CL.Kind.PAPER,
        t_ft,
        t_ab,
        full,
        f"level {lvl:.3g}; bound = FTC time, observed = ablation time; ratio > 1: ablation slower",
        agent=i,
        larger_is_better=True,
        text={"factor": FIG13_LEVEL_FACTOR},
    )
    fixed = 1e-2
    R.add(
        CL.FIG13_FIXED,
        CL.Kind.INFO,
        S.enter_time(t, ft, fixed),
        S.enter_time(ta, ab, fixed),
        full,
        f"level within {fixed / max(sup_ft, sup_ab):.2g}x of the tails: may time the noise floor",
        agent=i,
        larger_is_better=True,
        text={"level": fixed},
    )
    end = min(t_ft, t_ab)
    w, wa = t <= end, ta <= end
    rate_ft, rate_ab = S.decay_rate(t[w], ft[w]), S.decay_rate(ta[wa], ab[wa])
    R.add(
        CL.FIG13_RATE,
        CL.Kind.INFO,
        rate_ft,
        rate_ab,
        (float(t[0]), end),
        "least squares on log|e_ti| up to the earlier entering time; bound = FTC rate, "
        "observed = ablation rate; ratio < 1: ablation slower",
        agent=i,
        holds=bool(rate_ab <= rate_ft),
    )
    R.add(
        CL.FIG13_TAIL,
        CL.Kind.INFO,
        sup_ft,
        sup_ab,
        (float(t[tail][0]), float(t[-1])),
        "bound = FTC, observed = ablation; ratio > 1: ablation worse",
        agent=i,
        larger_is_better=True,
    )


def failures(table: pd.DataFrame, strict: bool = False) -> pd.DataFrame:
    """Rows that make ``check`` fail: guaranteed and consistency ones, plus the paper's when strict.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    strict : bool
        Also count the paper's own claims (kind ``paper``).
    """
    kinds = [*BUG_KINDS, CL.Kind.PAPER.value] if strict else list(BUG_KINDS)
    return table[table["kind"].isin(kinds) & failed_mask(table)]


def to_markdown(table: pd.DataFrame) -> str:
    """GitHub Markdown table (no extra dependency), numbers to 4 significant digits.

    Parameters
    ----------
    table : DataFrame
        Any table; booleans are shown as yes/**no**, NaN as –.
    """

    def fmt(v: object) -> str:
        if v is pd.NA or v is None:
            return ""
        if isinstance(v, bool | np.bool_):
            return "yes" if v else "**no**"
        if isinstance(v, float):
            if math.isnan(v):
                return "–"
            return f"{v:.4g}"
        return str(v).replace("|", "\\|")

    head = "| " + " | ".join(table.columns) + " |"
    sep = "|" + "|".join("---" for _ in table.columns) + "|"
    body = ["| " + " | ".join(fmt(v) for v in row) + " |" for row in table.itertuples(index=False)]
    return "\n".join([head, sep, *body])
