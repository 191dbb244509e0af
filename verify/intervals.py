"""Restart points of Theorem 2 per follower, and the intervals between them.

Theorem 2's comparison lemma integrates V̇2i ≤ −Ωv2 V2i + χv2 (eq. (38)) forward in time.
It needs V2i absolutely continuous and the constants fixed. Three things break that
for follower i, and each starts a new interval (docs/verification.md, 'Theorem 2 on
intervals'):

- a jump of its own health g_i (abrupt or intermittent faults, health tables): V2i's
  weight g_i/(2γ_i) and g̃_i = ĝ_i − 1/g_i jump, and so does the ĝ term of χv2;
- a jump of the operator's command u0 when χ_i depends on u0 (structurally: the
  pinned followers, whose reference velocity contains η̇0 = A0 η0 + B0 u0 through
  the oracle ḃ_i): χ_i, hence V2i, jumps with u0;
- a switch of the graph in follower i's row or in the rows of its in-neighbours (ψ_i
  and the neighbours' η̂̇_j enter its reference).

A continuously varying health (a ramp, an expression of t) is no jump: on such a piece
the interval carries sup |ġ_i|, whose term (ġ_i/(2γ_i))(ĝ_i² − 1/g_i²) = ∂V2i/∂t joins χv2
(:func:`verify.bounds.theorem2_constants`); its ends start intervals because the constants
change there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from core.scenario import Health, Scenario

#: points sampled inside a piece of g_i to tell a constant piece from a varying one and to
#: take sup |ġ_i| (the loader takes g_i's minimum on the same kind of grid)
SAMPLES = 257
#: a relative change of g_i below this inside a piece is no change (round-off of the expression)
FLAT_RTOL = 1e-12
#: a change of u0 across a breakpoint larger than this (relative to 1 + |u0|) is a jump
JUMP_RTOL = 1e-6
#: one-sided offset (s) at which u0 is evaluated around a breakpoint
SIDE = 1e-9


class Cause(StrEnum):
    """What starts an interval of follower i's Theorem 2 derivation."""

    START = "start of the run"
    HEALTH_JUMP = "health switch"
    HEALTH_KINK = "health ramp start/end"
    OPERATOR_STEP = "operator step"
    GRAPH_SWITCH = "graph switch"


@dataclass(frozen=True)
class Piece:
    """One interval [start, end) of follower i's derivation, with its health on it.

    Attributes
    ----------
    start, end : float
        Times (s); ``end`` is the next restart or the horizon.
    causes : tuple of Cause
        What starts it (:attr:`Cause.START` for the first).
    g_lo, g_hi : float
        Smallest and largest g_i on it (equal for a constant piece).
    gdot : float
        sup |ġ_i| on it (0 for a constant piece).
    """

    start: float
    end: float
    causes: tuple[Cause, ...]
    g_lo: float
    g_hi: float
    gdot: float

    @property
    def constant(self) -> bool:
        """Whether g_i is constant on the piece."""
        return self.gdot == 0.0

    def label(self) -> str:
        """``'health switch at t = 6 s'`` (or ``'start of the run'``)."""
        if self.causes == (Cause.START,):
            return Cause.START.value
        return " + ".join(c.value for c in self.causes) + f" at t = {self.start:.6g} s"


def _inside(a: float, b: float) -> np.ndarray:
    """SAMPLES points strictly inside (a, b)."""
    return np.linspace(a, b, SAMPLES + 2)[1:-1]


def _gdot(health: Health, ts: np.ndarray) -> np.ndarray:
    """ġ_i at ``ts`` by automatic differentiation of the health expression."""
    import casadi as ca

    t = ca.SX.sym("t")
    g = ca.SX(health.expr.casadi(t))
    f = ca.Function("gdot", [t], [ca.jacobian(g, t)])
    return np.asarray(f.map(len(ts))(ts.reshape(1, -1)).full(), float).ravel()


def health_pieces(
    health: Health, horizon: float
) -> list[tuple[float, float, float, float, float, bool]]:
    """g_i's pieces between its breakpoints: ``(a, b, g_lo, g_hi, gdot, jump_at_a)``.

    Parameters
    ----------
    health : Health
        Follower i's g_i.
    horizon : float
        End of the run.

    Returns
    -------
    list of tuple
        Per piece its ends, the range and sup |ġ| of g_i on it (0 where g_i is constant),
        and whether g_i jumps at its start.
    """
    cuts = [0.0, *sorted(b for b in health.breakpoints if 0.0 < b < horizon), horizon]
    out = []
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        ts = _inside(a, b)
        g = np.broadcast_to(health.expr.numpy(ts), ts.shape)
        lo, hi = float(g.min()), float(g.max())
        jump = False
        if a > 0.0:
            left = float(np.broadcast_to(health.expr.numpy(np.array([a - SIDE])), (1,))[0])
            right = float(np.broadcast_to(health.expr.numpy(np.array([a + SIDE])), (1,))[0])
            jump = abs(right - left) > JUMP_RTOL * (1.0 + abs(left))
        if hi - lo <= FLAT_RTOL * max(abs(hi), 1.0):
            out.append((a, b, lo, hi, 0.0, jump))
            continue
        ends = np.array([a + SIDE, b - SIDE])
        g_end = np.broadcast_to(health.expr.numpy(ends), ends.shape)
        lo, hi = min(lo, float(g_end.min())), max(hi, float(g_end.max()))
        gd = float(np.abs(_gdot(health, np.concatenate([ts, ends]))).max())
        out.append((a, b, lo, hi, gd, jump))
    return out


def operator_jumps(sc: Scenario) -> tuple[float, ...]:
    """Times in (0, horizon) at which the operator's command u0 jumps.

    A step atom of a ``leader.u0`` expression jumps unless ``leader.u0_rise > 0`` shaped
    it; a kink (``abs``, ``min``) does not. A held CSV trace jumps at each row.

    Parameters
    ----------
    sc : Scenario
    """
    H = sc.integration.horizon
    L = sc.leader
    if L.u0 is None:
        if not L.u0_hold:
            return ()
        cand = sorted({float(t) for t in L.u0_trace[:, 0] if 0.0 < t < H})
    else:
        cand = sorted({b for e in L.u0 for b in e.breakpoints() if 0.0 < b < H})
    if not cand:
        return ()
    ts = np.asarray(cand, float)
    left, right = L.u0_numpy(ts - SIDE), L.u0_numpy(ts + SIDE)  # (p, K)
    size = 1.0 + np.abs(left).max(axis=0)
    jump = np.abs(right - left).max(axis=0) > JUMP_RTOL * size
    return tuple(float(t) for t, j in zip(ts, jump, strict=True) if j)


def u0_dependence(cl: Any, sc: Scenario) -> np.ndarray:
    """Which followers' χ_i depend on u0 structurally: (N,) bool.

    The sparsity of ∂χ/∂p of the parametric closed loop at the literals of the u0
    expressions (or, without literals, ∂χ/∂t). Without a parametric loop every follower
    is taken to depend on u0 (a restart at a point where V2i does not jump is still sound).

    Parameters
    ----------
    cl : ClosedLoop or None
        The symbolic closed loop.
    sc : Scenario
    """
    import casadi as ca

    par = getattr(cl, "parametric", None)
    if par is None:
        return np.ones(sc.N, dtype=bool)
    f = par.outputs
    j = f.name_out().index("chi")
    rows, cols = f.size_out(j)
    cols_u0 = [sl for k, sl in par.layout.slices.items() if k.startswith("expr:leader.u0")]
    cols_u0 = [c for sl in cols_u0 for c in range(sl.start, sl.stop)]
    if cols_u0:
        D = np.asarray(ca.DM(f.sparsity_jac(f.name_in().index("p"), j), 1).full()) != 0
        hit = D[:, cols_u0].any(axis=1)
    else:
        hit = np.asarray(ca.DM(f.sparsity_jac(0, j), 1).full()).ravel() != 0
    # the output's entries in column-major order: entry (i, r) at i + rows·r
    return hit.reshape(cols, rows).T.any(axis=1)


def graph_restarts(sc: Scenario, agent: int) -> tuple[float, ...]:
    """Graph switch times at which follower ``agent``'s row or an in-neighbour's row changes.

    Parameters
    ----------
    sc : Scenario
    agent : int
        0-based follower.
    """
    tops = sc.graph.topologies()
    out = []
    for prev, nxt in zip(tops[:-1], tops[1:], strict=True):
        near = {agent}
        for A in (prev.adjacency, nxt.adjacency):
            near |= {int(j) for j in np.flatnonzero(np.asarray(A)[agent] != 0)}
        rows = sorted(near)
        changed = not np.array_equal(
            np.asarray(prev.adjacency)[rows], np.asarray(nxt.adjacency)[rows]
        ) or not np.array_equal(np.asarray(prev.pinning)[rows], np.asarray(nxt.pinning)[rows])
        if changed:
            out.append(float(nxt.t_start))
    return tuple(out)


def follower_pieces(sc: Scenario, agent: int, u0_dep: bool = True) -> list[Piece]:
    """Follower ``agent``'s intervals between restart points (module docstring).

    Parameters
    ----------
    sc : Scenario
    agent : int
        0-based follower.
    u0_dep : bool
        Whether χ_agent depends on u0 (:func:`u0_dependence`).

    Returns
    -------
    list of Piece
        Consecutive, covering [0, horizon].
    """
    H = float(sc.integration.horizon)
    hp = health_pieces(sc.followers[agent].g, H)
    cuts: dict[float, set[Cause]] = {}
    for k, (a, _b, _lo, _hi, gd, jump) in enumerate(hp):
        if a <= 0.0:
            continue
        prev_gd = hp[k - 1][4]
        if jump:
            cuts.setdefault(a, set()).add(Cause.HEALTH_JUMP)
        elif gd != prev_gd:
            cuts.setdefault(a, set()).add(Cause.HEALTH_KINK)
    if u0_dep:
        for ts in operator_jumps(sc):
            cuts.setdefault(ts, set()).add(Cause.OPERATOR_STEP)
    for ts in graph_restarts(sc, agent):
        if 0.0 < ts < H:
            cuts.setdefault(ts, set()).add(Cause.GRAPH_SWITCH)
    starts = [0.0, *sorted(cuts)]
    ends = [*starts[1:], H]
    pieces = []
    for a, b in zip(starts, ends, strict=True):
        inside = [p for p in hp if p[0] < b and p[1] > a]  # health pieces overlapping [a, b)
        lo = min(p[2] for p in inside)
        hi = max(p[3] for p in inside)
        gd = max(p[4] for p in inside)
        causes = (Cause.START,) if a == 0.0 else tuple(sorted(cuts[a], key=list(Cause).index))
        pieces.append(Piece(a, b, causes, lo, hi, gd))
    return pieces


def covered_fraction(windows: list[tuple[float, float]], horizon: float) -> float:
    """Share of [0, horizon] inside the union of ``windows``.

    Parameters
    ----------
    windows : list of (float, float)
        Closed intervals (s).
    horizon : float
        The run's length (s), > 0.
    """
    if horizon <= 0 or not windows:
        return 0.0
    total, end = 0.0, -math.inf
    for a, b in sorted((max(a, 0.0), min(b, horizon)) for a, b in windows):
        if b <= a:
            continue
        if a > end:
            total += b - a
            end = b
        elif b > end:
            total += b - end
            end = b
    return total / horizon
