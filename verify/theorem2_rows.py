"""Theorem 2 and Definition 1 rows, per follower and per interval between its restart points.

Follower i's derivation is restarted at its own health switches, at the operator's
steps when χ_i depends on u0, and at switches of its neighbourhood
(:mod:`verify.intervals`). On each interval the comparison lemma starts from the
measured V2i at the first output time after the restart, with that interval's
constants (:func:`verify.bounds.theorem2_constants` with the interval's range of g_i
and sup |ġ_i|); the rows are stated from the comparison-lemma time t_c to the interval's
end. An interval whose t_c lies beyond its end gets its rows with ``holds`` empty and
the reason (docs/verification.md, 'Theorem 2 on intervals').
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.scenario import Scenario
from synthesis.gains import Gains
from verify import claims as CL
from verify import signals as S
from verify.bounds import (
    Theorem2Constants,
    VerifyConfig,
    comparison_reaching_time,
    lemma1_bound,
    lemma1_reaching_time,
    theorem2_constants,
)
from verify.intervals import Piece
from verify.lyapunov import InequalityCheck
from verify.rows import Rows, Span
from verify.theorem2_check import theorem2_guaranteed

#: why the printed Theorem 2 rows are the paper's claims, not guarantees
PAPER_NOTE = "Lemma 1 applied with no decay in ghat (docs/fidelity.md, D3)"
#: the note's start on a zero bound (d_i = 0): the claim is asymptotic, not a tail level
ZERO_NOTE = "asymptotic claim (bound 0, d_i = 0): checked as a decay of the tail sup"


@dataclass(frozen=True)
class IntervalWindow:
    """Where one interval's provable rows are stated.

    Attributes
    ----------
    piece : Piece
        The interval.
    index, count : int
        Its 0-based position among the follower's intervals, and their number.
    c : Theorem2Constants
        Its constants.
    ks : int
        The sample the comparison lemma starts from (first output time after the restart).
    tc : float
        The comparison-lemma time (inf when it cannot be computed).
    mask : ndarray or None
        Output times of the window (None when the window is empty).
    why : str
        Why no rows are evaluated on it ('' when they are).
    env : ndarray or None
        Output times of the envelope's window [t_s, end) (None when it cannot be stated).
    W : ndarray or None
        The comparison-lemma envelope of V2 at those times.
    """

    piece: Piece
    index: int
    count: int
    c: Theorem2Constants
    ks: int
    tc: float
    mask: np.ndarray | None
    why: str
    env: np.ndarray | None = None
    W: np.ndarray | None = None

    @property
    def last(self) -> bool:
        """Whether it is the follower's last interval."""
        return self.index == self.count - 1

    def bounds(self, t: np.ndarray) -> tuple[float, float]:
        """The window (s): [first, last output time] when stated, else the interval.

        Parameters
        ----------
        t : ndarray
            The output times (s); the interval's end is clipped to the last one.
        """
        if self.mask is not None:
            ts = t[self.mask]
            return float(ts[0]), float(ts[-1])
        return (self.piece.start, min(self.piece.end, float(t[-1])))

    def label(self) -> str:
        """'' for a run with one interval, else which interval and what opened it."""
        if self.count == 1:
            return ""
        return f"; interval {self.index + 1} of {self.count} (from {self.piece.label()})"


def interval_windows(
    scenario: Scenario, df: S.FrameOrView, agent: int, pieces: list[Piece], cfg: VerifyConfig
) -> list[IntervalWindow]:
    """Follower ``agent``'s intervals with their constants, comparison-lemma times and windows.

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame
        The trajectory (``t`` and ``V2_<i>``).
    agent : int
        0-based follower.
    pieces : list of Piece
        :func:`verify.intervals.follower_pieces`.
    cfg : VerifyConfig
        Lemma 1's δ.
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    col = S.Signal.V2.column(agent + 1)
    V2 = view.scalar(S.Signal.V2, agent + 1) if view.has(S.Signal.V2, agent + 1) else None
    out = []
    for k, p in enumerate(pieces):
        c = theorem2_constants(scenario, agent, cfg, health=(p.g_lo, p.g_hi, p.gdot))
        last = k == len(pieces) - 1
        # the first piece starts at t[0]; a restart at the first output time after it
        ks = 0 if k == 0 else int(np.searchsorted(t, p.start, side="right"))
        inside = ks < len(t) and (last or t[ks] < p.end)
        tc, mask, why, env, W = math.inf, None, "", None, None
        if not c.provable:
            why = c.why_not
        elif V2 is None:
            why = f"the trajectory has no {col} column"
        elif not inside:
            why = f"no output time inside [{p.start:.6g}, {p.end:.6g}) s"
        else:
            tc = float(t[ks]) + comparison_reaching_time(
                c.Omega_var, c.chi_v_var, float(V2[ks]), cfg.lemma1_delta
            )
            env = (t >= t[ks]) & ((t < p.end) if not last else True)
            W = envelope(c, float(V2[ks]), t[env] - t[ks])
            m = (t >= tc) & env
            if m.any():
                mask = m
            elif not math.isfinite(tc):
                why = "no comparison-lemma time (chi_v = 0)"
            else:
                end = "the horizon" if last else "the interval's end"
                why = f"comparison-lemma time {tc:.4g} s lies beyond {end} ({p.end:.4g} s)"
        out.append(IntervalWindow(p, k, len(pieces), c, ks, tc, mask, why, env, W))
    return out


def envelope(c: Theorem2Constants, V2_start: float, dt: np.ndarray) -> np.ndarray:
    """Comparison lemma: V2(t_s + dt) ≤ V2(t_s) e^{−Ω dt} + (χv/Ω)(1 − e^{−Ω dt}).

    Parameters
    ----------
    c : Theorem2Constants
        The interval's constants (provable variant: Ω, χv).
    V2_start : float
        The logged V2 at t_s.
    dt : ndarray
        Times since t_s (≥ 0).
    """
    decay = np.exp(-c.Omega_var * np.asarray(dt, float))
    return V2_start * decay + c.chi_v_var / c.Omega_var * (1.0 - decay)


def chi_envelope(c: Theorem2Constants, W: np.ndarray) -> np.ndarray:
    """‖χ‖ ≤ sqrt(2W/λ_min(M)): ½λ_min(M)‖χ‖² ≤ ½χᵀMχ ≤ V2 ≤ W (eq. (39)).

    Parameters
    ----------
    c : Theorem2Constants
        The constants (``lam_min_M`` is used).
    W : ndarray
        The comparison-lemma bound on V2 (negative values are taken as 0).
    """
    return np.sqrt(2.0 * np.maximum(W, 0.0) / c.lam_min_M)


def theorem2_rows(
    R: Rows,
    scenario: Scenario,
    df: S.FrameOrView,
    span: Span,
    checks: list[InequalityCheck],
    windows: list[list[IntervalWindow]],
    *,
    config: VerifyConfig | None = None,
) -> None:
    """Theorem 2 (controller): eq. (38) consistency, then per follower the printed and provable bounds.

    Parameters
    ----------
    R : Rows
        Rows to append to.
    scenario : Scenario
    df : DataFrame
        The trajectory.
    span : Span
        Its time grid and windows.
    checks : list of InequalityCheck
        One per follower from :func:`verify.lyapunov.check_theorem2`.
    windows : list of list of IntervalWindow
        Per follower, :func:`interval_windows`.
    config : VerifyConfig, optional
    """
    cfg = config or VerifyConfig()
    _consistency_rows(R, scenario, checks, span.full)
    view = S.TrajectoryView.of(df)
    dm = view.dims
    for i in range(dm.N):
        _theorem2_agent_rows(R, scenario, view, span, i, dm.n, windows[i], cfg)


def _consistency_rows(
    R: Rows, scenario: Scenario, checks: list[InequalityCheck], window: tuple[float, float]
) -> None:
    """Eq. (38) with exact dV2/dt: an implementation-consistency check, not Theorem 2's evidence.

    With the shipped laws, dV2/dt − rhs(38) = χᵀf − dᵀ|χ| − ½k2‖θ̂‖² (+ the projection's
    term ≤ 0), which is ≤ 0 whenever |f_r| ≤ d_r (docs/verification.md): the row fails
    only if the simulated vector field or V2 differ from the derivation. A varying health
    adds its exact term ∂V2/∂t to both sides.
    """
    for chk in checks:
        ok, why = theorem2_guaranteed(scenario, chk.agent)
        note = "reduces to chi'f - d'|chi| - k2|th|^2/2 <= 0: fails only on an implementation bug"
        note = f"{note}; {why}"
        if not chk.ok:
            note += f"; worst {chk.worst:.3g} at t = {chk.t_worst:.3g} s"
        R.add(
            CL.T2_CONSISTENCY,
            CL.Kind.CONSISTENCY if ok else CL.Kind.INFO,
            1.0,
            chk.fraction,
            window,
            note,
            agent=chk.agent,
            holds=chk.ok,
            larger_is_better=True,
        )


def _paper_rows(R: Rows, c: Theorem2Constants, span: Span, chin, et, etd, i: int) -> None:  # noqa: ANN001
    """The paper's Theorem 2 rows (31) and Lemma 2 on the tail; a zero bound as a decay."""
    tail, tw = span.tail, span.tail_window
    _tail_row(R, CL.T2_CHI_PAPER, c.chi_bar, chin, span, i, None)
    for r in range(et.shape[1]):
        _tail_row(R, CL.T2_E_PAPER, c.e_bar[r], np.abs(et[:, r]), span, i, r)
        R.add(
            CL.LEMMA2_PAPER,
            CL.Kind.PAPER,
            c.edot_bar[r],
            np.abs(etd[tail, r]).max(),
            tw,
            PAPER_NOTE if c.edot_bar[r] > 0 else ZERO_NOTE,
            agent=i,
            component=r,
            holds=bool(np.abs(etd[tail, r]).max() <= c.edot_bar[r])
            if c.edot_bar[r] > 0
            else _decays(span, np.abs(etd[:, r])),
        )


def _decays(span: Span, x: np.ndarray) -> bool:
    """A zero bound's asymptotic reading: the sup over the tail's second half is below that
    over its first half (the signal decays toward 0 on the tail)."""
    ts = span.t[span.tail]
    mid = 0.5 * (ts[0] + ts[-1])
    first, second = x[span.tail & (span.t < mid)], x[span.tail & (span.t >= mid)]
    return bool(first.size and second.size and second.max() < first.max())


def _tail_row(R: Rows, claim, bound: float, x: np.ndarray, span: Span, i: int, r) -> None:  # noqa: ANN001
    """A paper row: tail sup against ``bound``, or, for a zero bound, its decay on the tail."""
    sup = float(x[span.tail].max())
    if bound > 0:
        R.add(claim, CL.Kind.PAPER, bound, sup, span.tail_window, PAPER_NOTE, agent=i, component=r)
        return
    R.add(
        claim,
        CL.Kind.PAPER,
        bound,
        sup,
        span.tail_window,
        ZERO_NOTE,
        agent=i,
        component=r,
        holds=_decays(span, x),
    )


def _theorem2_agent_rows(
    R: Rows,
    scenario: Scenario,
    view: S.TrajectoryView,
    span: Span,
    i: int,
    n: int,
    windows: list[IntervalWindow],
    cfg: VerifyConfig,
) -> None:
    """Theorem 2's rows for follower ``i`` (``n`` outputs): (31), Lemma 2, provable, Lemma 1."""
    c = theorem2_constants(scenario, i, cfg)
    lam = np.asarray(scenario.controller.Lambda[i], float)
    chi = view.block(S.Signal.CHI, i + 1, n)
    et = view.block(S.Signal.ET, i + 1, n)
    etd = chi - et * lam  # ė_t = χ − Λ e_t, eq. (28)
    chin = np.linalg.norm(chi, axis=1)
    _paper_rows(R, c, span, chin, et, etd, i)
    ok, why = theorem2_guaranteed(scenario, i)
    if _has_variant(scenario):
        for w in windows:
            _provable_rows(R, w, span.t, chin, et, i, ok, why)
    if view.has(S.Signal.V2, i + 1):
        _lemma1_row(R, c, span, view.scalar(S.Signal.V2, i + 1), i, cfg)


def _has_variant(scenario: Scenario) -> bool:
    """Whether the ĝ law has a provable variant at all (the paper's law has none)."""
    return scenario.options.ghat_law != "paper"


def _lemma1_row(
    R: Rows, c: Theorem2Constants, span: Span, V2: np.ndarray, i: int, cfg: VerifyConfig
) -> None:
    """Lemma 1's reaching time on V2 with the paper's constants (``paper``)."""
    level = lemma1_bound(c.chi_v, c.Omega, cfg.lemma1_delta)
    tf = lemma1_reaching_time(c.Omega, c.chi_v, float(V2[0]), cfg.lemma1_delta)
    te = S.enter_time(span.t, V2, level)
    R.add(
        CL.LEMMA1_PAPER,
        CL.Kind.PAPER,
        tf,
        te,
        span.full,
        f"V2(0) = {V2[0]:.4g}, level {level:.4g}; " + PAPER_NOTE,
        agent=i,
    )


def _provable_rows(
    R: Rows,
    w: IntervalWindow,
    t: np.ndarray,
    chin: np.ndarray,
    et: np.ndarray,
    i: int,
    guaranteed: bool,
    why: str,
) -> None:
    """Theorem 2's bound for the σ/projection ĝ law on one interval, every term included.

    After the comparison-lemma time t_c, V2 ≤ χv/(Ω(1−δ)), so ‖χ‖ ≤ χ̄ (eqs. (39)–(40)).
    Each e_r obeys ė_r = −λ_r e_r + χ_r, so from any t_s ≥ t_c on
    |e_r| ≤ max(χ̄/λ_r, |e_r(t_s)|) (the interval [−χ̄/λ_r, χ̄/λ_r] attracts and is
    invariant); the printed χ̄/λ_r is only asymptotic.
    """
    c = w.c
    _envelope_row(R, w, t, chin, i, guaranteed, why)
    if w.mask is None:
        R.missing(CL.T2_CHI, w.bounds(t), w.why + w.label(), agent=i, bound=c.chi_bar_var)
        for r in range(et.shape[1]):
            R.missing(CL.T2_E, w.bounds(t), w.why + w.label(), agent=i, component=r)
        return
    win = w.mask
    kind = CL.Kind.GUARANTEED if guaranteed and math.isfinite(w.tc) else CL.Kind.INFO
    vnote = (
        f"ghat law {c.variant!r}; chi_v includes ghat term {c.ghat_term:.3g} and boundary-layer "
        f"term {c.layer_term:.3g}"
        + (f" and health-rate term {c.rate_term:.3g}" if c.rate_term else "")
        + f"; window starts after the comparison-lemma time {w.tc:.3g} s"
        + w.label()
        + ("" if guaranteed else f"; not guaranteed: {why}")
    )
    wv = w.bounds(t)
    R.add(CL.T2_CHI, kind, c.chi_bar_var, chin[win].max(), wv, vnote, agent=i)
    k0 = int(np.argmax(win))
    for r in range(et.shape[1]):
        e0 = abs(float(et[k0, r]))
        bound = max(float(c.e_bar_var[r]), e0)  # first-order filter from |e_r(t_s)|
        note = vnote + (
            f"; bound = |e_r(t_s)| = {e0:.3g} > chi_bar/lambda" if e0 > c.e_bar_var[r] else ""
        )
        R.add(CL.T2_E, kind, bound, np.abs(et[win, r]).max(), wv, note, agent=i, component=r)


def _envelope_row(
    R: Rows, w: IntervalWindow, t: np.ndarray, chin: np.ndarray, i: int, ok: bool, why: str
) -> None:
    """‖χ_i(t)‖ ≤ sqrt(2W(t)/λ_min(M)) at every output time of the interval from t_s on."""
    if w.env is None:
        win = (w.piece.start, min(w.piece.end, float(t[-1])))
        R.missing(CL.T2_CHI_ENV, win, (w.why or "no start sample") + w.label(), agent=i)
        return
    bound = chi_envelope(w.c, w.W)
    obs = chin[w.env]
    ts = t[w.env]
    note = (
        f"pointwise; V2 from {w.W[0]:.4g} at t_s = {ts[0]:g} s toward chi_v/Omega = "
        f"{w.c.chi_v_var / w.c.Omega_var:.4g}; bound {bound[0]:.4g} at t_s, {bound[-1]:.4g} at "
        f"the end" + w.label() + ("" if ok else f"; not guaranteed: {why}")
    )
    R.add(
        CL.T2_CHI_ENV,
        CL.Kind.GUARANTEED if ok else CL.Kind.INFO,
        float(bound.max()),
        float(obs.max()),
        (float(ts[0]), float(ts[-1])),
        note,
        agent=i,
        holds=bool(np.all(obs <= bound)),
    )


def gauge(scenario: Scenario, gains: Gains | None = None) -> np.ndarray:
    """The gauge h_i = ±1 of the graph: the gains' H, else found from the signed adjacency.

    Parameters
    ----------
    scenario : Scenario
        Its graph.
    gains : Gains, optional
        Synthesised gains (their H is the closed loop's convention).
    """
    if gains is not None:
        return np.asarray(gains.h, float)
    from core.graph import find_gauge

    A = np.asarray(scenario.graph.adjacency, float)
    return np.asarray(find_gauge(A, np.asarray(scenario.graph.pinning, float)), float)


def leader_formation(scenario: Scenario, df: S.FrameOrView, h: np.ndarray) -> np.ndarray:
    """R(τ_i⁰) b_i0 with τ_i⁰ the angle of h_i η̇0, η̇0 = A0 η0 + B0 u0(t) (eq. (3)): (K, N, n).

    The formation the paper defines (section 7), referenced to the leader's own state
    rather than to the follower's estimate η̇_i. Where ‖(η̇0⁽¹⁾, η̇0⁽²⁾)‖ is below
    ``options.tau_threshold`` the angle is undefined and the entries are NaN. Without a
    planar rotation (n ≠ 2 or m < 2) b_i = b_i0, as in the closed loop.

    Parameters
    ----------
    scenario : Scenario
        Leader model, u0(t) and the b_i0.
    df : DataFrame
        Trajectory with the leader's state columns ``eta0_k``.
    h : ndarray
        The gauge.
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    L = scenario.leader
    b0 = np.array([fo.b0 for fo in scenario.followers], float)  # (N, n)
    if scenario.n != 2 or L.m < 2:
        return np.broadcast_to(b0, (len(t), *b0.shape)).copy()
    eta0 = view.leader(L.m)
    d = eta0 @ np.asarray(L.A0, float).T + (np.asarray(L.B0, float) @ L.u0_numpy(t)).T  # eq. (3)
    d = d[:, :2]
    c, s = d[:, 0], d[:, 1]
    nd = np.hypot(c, s)
    with np.errstate(invalid="ignore", divide="ignore"):
        c, s = c / nd, s / nd  # cos τ⁰, sin τ⁰
    out = np.empty((len(t), scenario.N, 2))
    for i in range(scenario.N):
        sg = 1.0 if h[i] > 0 else -1.0  # angle of h_i η̇0: R(τ⁰ + π) = −R(τ⁰)
        bx, by = b0[i]
        out[:, i, 0] = sg * (c * bx - s * by)
        out[:, i, 1] = sg * (s * bx + c * by)
    out[nd < scenario.options.tau_threshold] = np.nan
    return out


def definition1_rows(
    R: Rows,
    scenario: Scenario,
    df: S.FrameOrView,
    *,
    gains: Gains | None = None,
    config: VerifyConfig | None = None,
    windows: list[list[IntervalWindow]] | None = None,
) -> None:
    """Definition 1 with the gauge, its derived bound per interval, and the leader-referenced formation.

    Rows per follower: the paper's limsup ‖p_i − h_i y0 − b_i‖ ≤ χ̄_si (``paper``); the
    derived pointwise bound ‖e_ti‖ ≤ B_e plus ‖C0 ē_ηi‖ ≤ B_η(t) on each interval of
    Theorem 2 (``guaranteed`` when Theorem 2's provable variant applies and the gains are
    certified; docs/verification.md, "Definition 1"); ‖p_i − h_i y0 − R(τ_i⁰) b_i0‖ on
    the tail (``info``).

    Parameters
    ----------
    R : Rows
        Rows to append to.
    scenario : Scenario
    df : DataFrame
        The trajectory.
    gains : Gains, optional
        Needed for the derived bound (T, Z, Ω, k1, the gauge).
    config : VerifyConfig, optional
    windows : list of list of IntervalWindow, optional
        Per follower, :func:`interval_windows` (default: one interval, no restarts).
    """
    from verify.bounds import theorem1_floor
    from verify.intervals import follower_pieces

    cfg = config or VerifyConfig()
    view = S.TrajectoryView.of(df)
    dm = view.dims
    t = view.t
    tail = S.tail_mask(t, cfg.tail_fraction)
    k0 = int(np.argmax(tail))
    tw = (float(t[k0]), float(t[-1]))
    h = gauge(scenario, gains)
    y0 = view.leader_output(scenario.leader.C0)
    certified = gains is not None and bool(gains.certificate.get("passed", True))
    phis = all(view.has(S.Signal.PHI, i + 1) for i in range(dm.N))
    derivable = gains is not None and view.has_V1() and phis
    fl = theorem1_floor(scenario, gains) if derivable else None
    lead_b = leader_formation(scenario, view, h)
    for i in range(dm.N):
        c = theorem2_constants(scenario, i, cfg)
        p, b = view.block(S.Signal.P, i + 1), view.block(S.Signal.B, i + 1)
        dev = np.linalg.norm(p - h[i] * y0 - b, axis=1)  # Definition 1 with the gauge h_i
        _definition1_paper(R, c, dev, t, tail, tw, f"h_i = {h[i]:+g}; bound as printed (31)", i)
        if _has_variant(scenario):
            ws = (
                windows[i]
                if windows is not None
                else interval_windows(scenario, view, i, follower_pieces(scenario, i), cfg)
            )
            ok, why = theorem2_guaranteed(scenario, i)
            lam = np.asarray(scenario.controller.Lambda[i], float)
            f = _Follower(R, view, fl, t, k0, dev, i, ok and certified, why, lam)
            _definition1_intervals(f, ws)
        fd = np.linalg.norm(p - h[i] * y0 - lead_b[:, i, :], axis=1)[tail]
        fd = fd[np.isfinite(fd)]
        if fd.size:
            R.add(
                CL.FORMATION,
                CL.Kind.INFO,
                c.chi_bar,
                float(fd.max()),
                tw,
                "tau_i^0 = angle of h_i (A0 eta0 + B0 u0); bound = the paper's chi_bar "
                "(no derived bound)",
                agent=i,
            )


def _definition1_paper(
    R: Rows,
    c: Theorem2Constants,
    dev: np.ndarray,
    t: np.ndarray,
    tail: np.ndarray,
    tw: tuple[float, float],
    note: str,
    i: int,
) -> None:
    """Follower ``i``'s row for the paper's limsup ‖p_i − h_i y0 − b_i‖ ≤ χ̄_si."""
    if c.chi_bar > 0:
        R.add(CL.DEF1_PAPER, CL.Kind.PAPER, c.chi_bar, dev[tail].max(), tw, note, agent=i)
    else:
        sp = Span(t, tail)
        R.add(
            CL.DEF1_PAPER,
            CL.Kind.PAPER,
            c.chi_bar,
            dev[tail].max(),
            tw,
            f"{note}; {ZERO_NOTE}",
            agent=i,
            holds=_decays(sp, dev),
        )


@dataclass(frozen=True)
class _Follower:
    """What follower ``i``'s Definition 1 interval rows read: the trajectory, Theorem 1's
    floor, the deviation and whether Theorem 2 guarantees the rows."""

    R: Rows
    view: S.TrajectoryView
    fl: object  # verify.bounds.Theorem1Floor
    t: np.ndarray
    k0: int
    dev: np.ndarray
    i: int
    ok: bool
    why: str
    lam: np.ndarray

    def c0_bound(self, mask: np.ndarray, ks: int) -> tuple[np.ndarray, int]:
        """‖C0 ē_ηi‖ ≤ B_η(t) on ``mask`` (Theorem 1 with the φ floor), and the sample V1's
        comparison lemma starts from: the tail start or the window's start, whichever is
        earlier (V1 is continuous through health switches and steps of u0)."""
        fl, t = self.fl, self.t
        kv = min(self.k0, ks)
        V1b = fl.v1_bound(float(self.view.V1()[kv]), t[mask] - t[kv])
        phi = np.asfortranarray(self.view.scalars(S.Signal.PHI, fl.h.size)[mask])
        return fl.c0_error_bound(V1b, phi)[:, self.i], kv


def _definition1_intervals(f: _Follower, ws: list[IntervalWindow]) -> None:
    """Follower ``i``'s envelope and derived-bound rows, one pair per interval."""
    for w in ws:
        if f.fl is None:
            why_fl = "needs the synthesised gains and the V1, phi columns" + w.label()
            f.R.missing(CL.DEF1_ENV, w.bounds(f.t), why_fl, agent=f.i)
            f.R.missing(CL.DEF1_DERIVED, w.bounds(f.t), why_fl, agent=f.i)
            continue
        _definition1_envelope(f, w)
        if w.mask is None:
            f.R.missing(CL.DEF1_DERIVED, w.bounds(f.t), w.why + w.label(), agent=f.i)
        else:
            _definition1_derived(f, w)


def _definition1_envelope(f: _Follower, w: IntervalWindow) -> None:
    """‖p_i − h_i y0 − b_i‖ ≤ ‖B_e(t)‖ + ‖C0 ē_ηi‖ bound from t_s, with the χ envelope.

    ė_r = −λ_r e_r + χ_r with |χ_r| ≤ c(t) = max over [t_s, t] of the χ envelope gives
    |e_r(t)| ≤ max(|e_r(t_s)|, c(t)/λ_r) (the interval [−c/λ_r, c/λ_r] attracts).
    """
    t, i, lam = f.t, f.i, f.lam
    if w.env is None:
        win = (w.piece.start, min(w.piece.end, float(t[-1])))
        f.R.missing(CL.DEF1_ENV, win, (w.why or "no start sample") + w.label(), agent=i)
        return
    et = f.view.block(S.Signal.ET, i + 1, lam.size)
    ks = int(np.argmax(w.env))
    cmax = np.maximum.accumulate(chi_envelope(w.c, w.W))  # running max of the χ envelope
    Be = np.linalg.norm(np.maximum(np.abs(et[ks])[None, :], cmax[:, None] / lam[None, :]), axis=1)
    Bn, kv = f.c0_bound(w.env, ks)
    bound = Be + Bn
    obs = f.dev[w.env]
    ts = t[w.env]
    note = (
        f"pointwise; |e_ti| from the chi envelope (T2, V2 from t_s = {ts[0]:g} s) + "
        f"|C0 ebar_eta_i| (T1 with the phi floor, V1 from t = {t[kv]:g} s)"
        + w.label()
        + ("" if f.ok else f"; not guaranteed: {f.why}")
    )
    f.R.add(
        CL.DEF1_ENV,
        CL.Kind.GUARANTEED if f.ok else CL.Kind.INFO,
        float(bound.max()),
        float(obs.max()),
        (float(ts[0]), float(ts[-1])),
        note,
        agent=i,
        holds=bool(np.all(obs <= bound)),
    )


def _definition1_derived(f: _Follower, w: IntervalWindow) -> None:
    """‖p_i − h_i y0 − b_i‖ ≤ ‖e_ti‖ + ‖C0 ē_ηi‖ on one interval, each bounded by its theorem."""
    win, c, t = w.mask, w.c, f.t
    et = f.view.block(S.Signal.ET, f.i + 1, c.e_bar_var.size)
    ks = int(np.argmax(win))
    # Theorem 2 provable variant from t_s: |e_r| ≤ max(χ̄/λ_r, |e_r(t_s)|) (as _provable_rows)
    Be = float(np.linalg.norm(np.maximum(c.e_bar_var, np.abs(et[ks]))))
    Bn, kv = f.c0_bound(win, ks)
    bound = Be + Bn
    ok = f.ok and math.isfinite(w.tc)
    note = (
        f"pointwise; |e_ti| <= {Be:.3g} (T2 provable) + |C0 ebar_eta_i| <= {float(Bn.max()):.3g}"
        f" (T1 with the phi floor, V1 from t = {t[kv]:g} s)" + w.label()
    )
    if not ok:
        why = f.why if math.isfinite(w.tc) else "no comparison-lemma time"
        note += f"; not guaranteed: {why}"
    f.R.add(
        CL.DEF1_DERIVED,
        CL.Kind.GUARANTEED if ok else CL.Kind.INFO,
        float(bound.max()),
        float(f.dev[win].max()),
        w.bounds(t),
        note,
        agent=f.i,
        holds=bool(np.all(f.dev[win] <= bound)),
    )
