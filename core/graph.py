"""Graph algebra shared by every stage: Assumption 1 (docs/reading.md, 'Network and signed graphs').

Every follower must be reachable from the leader, equivalently L̄ = H(L + B)H is a
nonsingular M-matrix; for signed graphs the graph must be structurally balanced and
the gauge H = diag(±1) is found here.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np
import scipy.sparse as sp

from core.errors import SynthesisError
from core.memo import MEMO


# --------------------------------------------------------------------------- Assumption 1
@dataclass(frozen=True)
class NetworkCheck:
    """Result of Assumption 1.

    Attributes
    ----------
    h : ndarray
        Gauge h_i = ±1 (all +1 for cooperative graphs).
    L_bar : scipy.sparse.csr_matrix
        L̄ = H(L + B)H, N×N (sparse: only Lemma 3 touches N).
    signed : bool
        Whether the graph has negative edges.
    """

    h: np.ndarray
    L_bar: sp.csr_matrix
    signed: bool


def find_gauge(adjacency: np.ndarray | sp.spmatrix, pinning: np.ndarray) -> np.ndarray:
    """Find the gauge of a structurally balanced signed graph (Remark 2).

    The gauge satisfies h_i h_j = sign(a_ij) on every edge, treating edges as
    undirected (structural balance is a property of the underlying signed graph).
    In each weakly connected component the lowest-indexed pinned follower (or the
    lowest-indexed follower if none is pinned) gets h = +1. Every pinned follower must
    then have h = +1: the leader's camp is the one it pins.

    Parameters
    ----------
    adjacency : ndarray or sparse matrix
        N×N, ``adjacency[i, j] = a_ij`` (follower i hears follower j).
    pinning : ndarray
        N, a_i0 >= 0.

    Returns
    -------
    ndarray
        h, N entries in {+1, -1}.

    Raises
    ------
    SynthesisError
        The graph is not structurally balanced; the message names one cycle with an
        odd number of negative edges (1-based follower numbers). Or two pinned
        followers lie in opposite camps (both are named).
    """
    A = sp.csr_matrix(adjacency, dtype=float)
    N = A.shape[0]
    # Undirected signed view; a pair with a_ij and a_ji of opposite signs is itself a 2-cycle.
    Au = sp.coo_matrix(A + A.T)
    Apos = sp.coo_matrix((A > 0).astype(float) + (A > 0).T.astype(float))
    Aneg = sp.coo_matrix((A < 0).astype(float) + (A < 0).T.astype(float))
    conflict = sp.coo_matrix(Apos.multiply(Aneg))
    if conflict.nnz:
        i, j = int(conflict.row[0]), int(conflict.col[0])
        i, j = min(i, j), max(i, j)
        raise SynthesisError(
            f"graph.adjacency: Assumption 1 fails: not structurally balanced: cycle "
            f"{i + 1} -> {j + 1} -> {i + 1} has one negative edge "
            f"(a_{i + 1}{j + 1} = {A[i, j]:g}, a_{j + 1}{i + 1} = {A[j, i]:g}); "
            "use signs with h_i h_j = sign(a_ij) for some h_i = ±1"
        )
    sign = sp.csr_matrix((np.sign(Au.data), (Au.row, Au.col)), shape=(N, N))
    sign.eliminate_zeros()
    h = np.zeros(N)
    parent = np.full(N, -1)
    depth = np.zeros(N, dtype=int)
    pinned = np.asarray(pinning) > 0
    order = list(np.flatnonzero(pinned)) + list(np.flatnonzero(~pinned))
    for root in order:
        if h[root] != 0:
            continue
        h[root] = 1.0
        queue = deque([root])
        while queue:
            u = queue.popleft()
            lo, hi = sign.indptr[u], sign.indptr[u + 1]
            for v, s in zip(sign.indices[lo:hi], sign.data[lo:hi], strict=True):
                if h[v] == 0:
                    h[v] = h[u] * s
                    parent[v] = u
                    depth[v] = depth[u] + 1
                    queue.append(v)
                elif h[v] != h[u] * s:
                    cyc = _cycle(parent, depth, int(u), int(v))
                    loop = cyc + [cyc[0]]
                    nneg = sum(sign[a, b] < 0 for a, b in zip(loop, loop[1:], strict=False))
                    names = " - ".join(str(k + 1) for k in loop)
                    raise SynthesisError(
                        f"graph.adjacency: Assumption 1 fails: not structurally balanced: "
                        f"cycle {names} (edge directions ignored) has {nneg} negative edge(s), "
                        "an odd number; flip the sign of one of its edges or remove it"
                    )
    _check_pinned_camp(h, pinned, parent)
    return h


def _check_pinned_camp(h: np.ndarray, pinned: np.ndarray, parent: np.ndarray) -> None:
    """Refuse pinned followers in the camp opposite to the leader's (they would track −y0)."""
    bad = np.flatnonzero(pinned & (h < 0))
    if bad.size:
        i = ref = int(bad[0])
        while parent[ref] >= 0:  # the BFS root of i's component: a pinned follower with h = +1
            ref = int(parent[ref])
        raise SynthesisError(
            f"graph.pinning: followers {ref + 1} and {i + 1} are both pinned (a_i0 > 0) but "
            f"lie in opposite camps of the signed graph (h_{ref + 1} = +1, h_{i + 1} = -1), so "
            f"follower {i + 1} would be driven to -y0; pin followers of one camp only "
            f"(set pinning[{i + 1}] = 0) or flip the signs of the edges between the camps"
        )


def _cycle(parent: np.ndarray, depth: np.ndarray, u: int, v: int) -> list[int]:
    """The cycle closed by the non-tree edge (u, v) in a BFS forest."""
    pu, pv = [u], [v]
    a, b = u, v
    while depth[a] > depth[b]:
        a = int(parent[a])
        pu.append(a)
    while depth[b] > depth[a]:
        b = int(parent[b])
        pv.append(b)
    while a != b:
        a, b = int(parent[a]), int(parent[b])
        pu.append(a)
        pv.append(b)
    # pu ends at the common ancestor; pv too (drop its copy)
    return pu + pv[-2::-1]


def unreachable_followers(adjacency: np.ndarray | sp.spmatrix, pinning: np.ndarray) -> list[int]:
    """0-based followers with no directed path from the leader (edges j -> i when a_ij != 0).

    Parameters
    ----------
    adjacency : ndarray or sparse matrix
        N×N, ``adjacency[i, j] = a_ij`` (follower i hears follower j).
    pinning : ndarray
        N pinning gains a_i0; followers with a_i0 > 0 hear the leader.
    """
    A = sp.csr_matrix(adjacency, dtype=float)
    At = sp.csr_matrix(A.T)  # row j lists the i that hear j
    N = A.shape[0]
    seen = np.asarray(pinning) > 0
    queue = deque(np.flatnonzero(seen).tolist())
    while queue:
        j = queue.popleft()
        lo, hi = At.indptr[j], At.indptr[j + 1]
        for i, a in zip(At.indices[lo:hi], At.data[lo:hi], strict=True):
            if a != 0 and not seen[i]:
                seen[i] = True
                queue.append(int(i))
    return [i for i in range(N) if not seen[i]]


def check_network(adjacency: np.ndarray | sp.spmatrix, pinning: np.ndarray) -> NetworkCheck:
    """Assumption 1: reachability, structural balance and L̄ = H(L + B)H.

    Parameters
    ----------
    adjacency : ndarray or sparse matrix
        N×N signed adjacency, ``adjacency[i, j] = a_ij``.
    pinning : ndarray
        N, a_i0 >= 0.

    Returns
    -------
    NetworkCheck

    Raises
    ------
    SynthesisError
        A follower is unreachable from the leader (named), a pinning is negative,
        or the signed graph is not structurally balanced (a cycle is named).
    """
    A = sp.csr_matrix(adjacency, dtype=float)
    b = np.asarray(pinning, dtype=float)
    N = A.shape[0]
    if A.shape != (N, N) or b.shape != (N,):
        raise SynthesisError(
            f"graph: adjacency {A.shape} and pinning {b.shape} do not match; "
            "give an N x N adjacency and N pinning gains"
        )
    if np.any(b < 0):
        i = int(np.flatnonzero(b < 0)[0])
        raise SynthesisError(f"graph.pinning[{i + 1}] = {b[i]:g} is negative; use a_i0 >= 0")
    if np.any(A.diagonal() != 0):
        raise SynthesisError("graph.adjacency: non-zero diagonal (self-loop); use a_ii = 0")
    bad = unreachable_followers(A, b)
    if bad:
        names = ", ".join(str(i + 1) for i in bad)
        raise SynthesisError(
            f"graph: Assumption 1 fails: follower(s) {names} cannot be reached from the leader; "
            "add a pinning a_i0 > 0 or an edge from a reachable follower"
        )
    signed = bool((A.data < 0).any())
    h = find_gauge(A, b) if signed else np.ones(N)
    Hs = sp.diags(h)
    L_bar = sp.csr_matrix(Hs @ pinned_laplacian(A, b) @ Hs)  # L̄ = H(L + B)H (Lemma 3, Remark 2)
    return NetworkCheck(h=h, L_bar=L_bar, signed=signed)


def pinned_laplacian(adjacency: np.ndarray | sp.spmatrix, pinning: np.ndarray) -> sp.csr_matrix:
    """``L + B`` of a signed graph: ``L = D − A`` with ``D = diag(Σ_j |a_ij|)``, ``B = diag(a_i0)``.

    Parameters
    ----------
    adjacency : ndarray or sparse matrix
        N×N signed adjacency, ``adjacency[i, j] = a_ij``.
    pinning : ndarray
        N pinning gains a_i0.

    Returns
    -------
    scipy.sparse.csr_matrix
        N×N, ``L + B`` (not gauge-transformed; L̄ = H(L + B)H).
    """
    # every stage asks for the same few graphs many times per run: their L + B are kept by value
    if sp.issparse(adjacency):
        A = sp.csr_matrix(adjacency, dtype=float)
        akey = (
            "csr",
            A.shape,
            *((x.dtype.str, x.tobytes()) for x in (A.data, A.indices, A.indptr)),
        )
    else:
        A = np.asarray(adjacency, dtype=float)
        akey = ("dense", A.shape, A.dtype.str, A.tobytes())
    b = np.asarray(pinning, dtype=float)
    return _pinned_laplacian(akey, (b.shape, b.dtype.str, b.tobytes())).copy()


@MEMO.memoize("pinned-laplacians", 32)
def _pinned_laplacian(akey: tuple, bkey: tuple) -> sp.csr_matrix:
    """``L + B`` from the byte keys of :func:`pinned_laplacian` (callers receive copies)."""
    if akey[0] == "csr":
        shape, *arrays = akey[1:]
        data, indices, indptr = (np.frombuffer(raw, dtype=dt) for dt, raw in arrays)
        A = sp.csr_matrix((data, indices, indptr), shape=shape)
    else:
        A = sp.csr_matrix(np.frombuffer(akey[3], dtype=akey[2]).reshape(akey[1]), dtype=float)
    pinning = np.frombuffer(bkey[2], dtype=bkey[1]).reshape(bkey[0])
    D = sp.diags(np.asarray(abs(A).sum(axis=1)).ravel())
    return sp.csr_matrix(D - A + sp.diags(np.asarray(pinning, dtype=float)))


def m_matrix_violation(L_bar: np.ndarray | sp.spmatrix) -> str | None:
    """Why L̄ is not a nonsingular M-matrix, or None when it is.

    Checks the sign pattern (off-diagonal <= 0) and semipositivity: a Z-matrix is a
    nonsingular M-matrix iff (L̄ᵀ)⁻¹1 exists and is positive (solved sparse).

    Parameters
    ----------
    L_bar : ndarray or sparse matrix
        N×N matrix to test, L̄ = H(L + B)H.
    """
    Ls = sp.csc_matrix(L_bar, dtype=float)
    off = Ls - sp.diags(Ls.diagonal())
    if off.nnz and off.data.max() > 0:
        return f"an off-diagonal entry is {off.data.max():g} > 0 (not a Z-matrix)"
    try:
        z = sp.linalg.spsolve(sp.csc_matrix(Ls.T), np.ones(Ls.shape[0]))
    except RuntimeError:
        return "it is singular"
    z = np.atleast_1d(z)
    if not np.all(np.isfinite(z)):
        return "it is singular"
    if z.min() <= 0:
        return f"(L̄ᵀ)⁻¹1 has a non-positive entry {z.min():g}"
    return None


# --------------------------------------------------------------------------- switching topology
# Outside the paper's theorems (docs/fidelity.md, 'Switching topology'): the graph is piecewise
# constant in time; every topology a run reaches must satisfy Assumption 1 with the base gauge.

#: seconds over which a lost or restored link's weight fades (``graph.link_fade``; 0 = raw
#: switching). A deviation from the paper (docs/fidelity.md, E3; docs/verification.md,
#: 'Link losses', where the duration is chosen by measurement).
DEFAULT_LINK_FADE = 1.0


def fade_jets(x: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fade σ(x) = 10x³ − 15x⁴ + 6x⁵ on [0, 1] (0 before, 1 after) and σ', σ''.

    C² (σ' and σ'' vanish at both ends), so the weights' first and second derivatives,
    which the oracle derivatives of ψ take (eq. (6)), are continuous. Numpy reference of
    :func:`symbolic.closed_loop.graph_coupling`'s fade.

    Parameters
    ----------
    x : ndarray or float
        (t − s_k)/T.
    """
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
    s = x**3 * (10.0 - 15.0 * x + 6.0 * x**2)
    ds = 30.0 * x**2 * (1.0 - x) ** 2
    dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    return s, ds, dds


@dataclass(frozen=True)
class Switch:
    """One ``[[graph.switches]]`` event: from ``time`` on, a_{follower, neighbour} = ``weight``.

    Attributes
    ----------
    time : float
        Switching time, 0 < time < horizon.
    follower : int
        0-based follower whose incoming link changes.
    neighbour : int or None
        0-based follower it hears, or None for the leader (its pinning gain a_i0).
    weight : float
        The link's new weight: 0 removes it, any other value sets (adds) it.
    """

    time: float
    follower: int
    neighbour: int | None
    weight: float

    @property
    def link(self) -> str:
        """The weight it sets, 1-based as in files: ``a_31`` or ``a_30`` (the leader)."""
        j = 0 if self.neighbour is None else self.neighbour + 1
        return f"a_{self.follower + 1},{j}"


class Topology(NamedTuple):
    """The graph that holds on ``[t_start, next t_start)``."""

    t_start: float
    adjacency: np.ndarray  # N×N, a_ij
    pinning: np.ndarray  # N, a_i0


class SwitchedGraph(Protocol):
    """What :func:`weights_at` needs of a graph (``core.scenario.Graph`` has it)."""

    adjacency: np.ndarray
    pinning: np.ndarray
    link_fade: float

    def topologies(self) -> tuple[Topology, ...]:
        """The piecewise-constant graph, base graph first (``t_start`` = 0)."""
        ...


def switch_times(switches: tuple[Switch, ...]) -> tuple[float, ...]:
    """The distinct switching times, increasing.

    Parameters
    ----------
    switches : tuple of Switch
    """
    return tuple(sorted({s.time for s in switches}))


def iter_topologies(
    adjacency: np.ndarray, pinning: np.ndarray, switches: tuple[Switch, ...]
) -> Iterator[Topology]:
    """The piecewise-constant graph, one topology at a time (base graph first, t_start = 0).

    Events at the same time are applied together; each topology is a fresh copy.

    Parameters
    ----------
    adjacency : ndarray
        N×N base adjacency.
    pinning : ndarray
        N base pinning gains.
    switches : tuple of Switch
        In any order.
    """
    A = np.array(adjacency, dtype=float)
    b = np.array(pinning, dtype=float)
    yield Topology(0.0, _frozen(A), _frozen(b))
    for t in switch_times(switches):
        for s in switches:
            if s.time != t:
                continue
            if s.neighbour is None:
                b[s.follower] = s.weight
            else:
                A[s.follower, s.neighbour] = s.weight
        yield Topology(t, _frozen(A), _frozen(b))


def topologies(
    adjacency: np.ndarray, pinning: np.ndarray, switches: tuple[Switch, ...]
) -> tuple[Topology, ...]:
    """All topologies of :func:`iter_topologies` as a tuple.

    Parameters
    ----------
    adjacency, pinning : ndarray
        The base graph.
    switches : tuple of Switch
    """
    return tuple(iter_topologies(adjacency, pinning, switches))


def _frozen(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a.setflags(write=False)
    return a


def topology_index(tops: tuple[Topology, ...], t: float) -> int:
    """Index of the topology that holds at time ``t`` (right-continuous: a switch acts at its time).

    Parameters
    ----------
    tops : tuple of Topology
        From :func:`topologies`.
    t : float
    """
    starts = np.array([tp.t_start for tp in tops])
    return max(int(np.searchsorted(starts, t, side="right")) - 1, 0)


def base_gauge(adjacency: np.ndarray | sp.spmatrix, pinning: np.ndarray) -> np.ndarray:
    """The gauge h of the base graph: all +1 when cooperative, else :func:`find_gauge`.

    Parameters
    ----------
    adjacency, pinning : ndarray
        The base graph.
    """
    A = sp.csr_matrix(adjacency, dtype=float)
    if not (A.data < 0).any():
        return np.ones(A.shape[0])
    return find_gauge(A, pinning)


def weights_at(
    graph: SwitchedGraph, t: float, derivative: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """``(L + B, a0 ∘ h)`` at ``t``, dense (a numpy reference), or its time derivative.

    ψ = C0 E (L + B)ᵀ − y0 (a0 ∘ h)ᵀ with E = [η_1 … η_N] (eq. (6) summed over
    neighbours); h is the base graph's gauge, which every topology keeps (checked on load).
    With ``graph.link_fade`` = T > 0 each switch at s_k fades in over [s_k, s_k + T]:
    W(t) = W_0 + Σ_k σ((t − s_k)/T)(W_k − W_{k−1}) (:func:`fade_jets`), a convex
    combination of the topologies (the σ_k decrease with k); with T = 0 the topology
    that holds at t (right-continuous).

    Parameters
    ----------
    graph : SwitchedGraph
        A scenario's graph.
    t : float
        Time.
    derivative : {0, 1, 2}
        0: the weights; 1, 2: their first and second time derivatives.

    Returns
    -------
    L_B, a0h : ndarray
        N×N ``L + B`` (``L = D − A``, ``D = diag(Σ_j |a_ij|)``) and N ``a_i0 h_i``.
    """
    tops = graph.topologies()
    h = base_gauge(graph.adjacency, graph.pinning)
    T = float(graph.link_fade)
    W = [(pinned_laplacian(tp.adjacency, tp.pinning).toarray(), tp.pinning * h) for tp in tops]
    if T <= 0.0:
        if derivative:
            return np.zeros_like(W[0][0]), np.zeros_like(W[0][1])
        return W[topology_index(tops, t)]
    L, a = (W[0][0].copy(), W[0][1].copy()) if derivative == 0 else (0.0 * W[0][0], 0.0 * W[0][1])
    for k in range(1, len(tops)):
        c = fade_jets((t - tops[k].t_start) / T)[derivative] / T**derivative
        L += c * (W[k][0] - W[k - 1][0])
        a += c * (W[k][1] - W[k - 1][1])
    return L, a


def topology_violation(
    adjacency: np.ndarray | sp.spmatrix, pinning: np.ndarray, h: np.ndarray | None
) -> str | None:
    """What a switched topology breaks, or None: Assumption 1, or the gauge ``h``.

    Parameters
    ----------
    adjacency, pinning : ndarray
        The topology.
    h : ndarray or None
        The base graph's gauge, which the certified gains assume (None: not checked).

    Returns
    -------
    str or None
        One clause (``"follower(s) 3 cannot be reached from the leader (Assumption 1)"``).
    """
    if np.any(np.asarray(pinning) < 0):
        i = int(np.flatnonzero(np.asarray(pinning) < 0)[0])
        return f"pinning a_{i + 1},0 = {pinning[i]:g} is negative"
    bad = unreachable_followers(adjacency, pinning)
    if bad:
        names = ", ".join(str(i + 1) for i in bad)
        return f"follower(s) {names} cannot be reached from the leader (Assumption 1)"
    if h is None:
        return None
    try:
        hk = base_gauge(adjacency, pinning)
    except SynthesisError as exc:
        return str(exc).split(": ", 1)[-1]
    flipped = np.flatnonzero(hk != np.asarray(h))
    if flipped.size:
        i = int(flipped[0])
        return (
            f"the signed graph's gauge changes (h_{i + 1} = {h[i]:+g} becomes {hk[i]:+g}), "
            "which the certified gains assume (Remark 2)"
        )
    return None
