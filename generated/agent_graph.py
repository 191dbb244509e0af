"""The graph as the per-agent driver reads it: CSR rows of L + B, an order grouped by depth.

One :class:`Topology` per graph of a scenario (the base graph, then one per switching
time) and the :class:`Segment` of fading links are runtime data of
:mod:`generated.agents`, never compiled in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.graph import pinned_laplacian


def _order(ptr: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, bool, np.ndarray]:
    """An order of the followers grouped by depth, whether it is topological, the depths.

    Kahn's algorithm; a cycle is broken at the waiting follower with the fewest unheard
    followers (ties by index). A follower's depth is 1 + the largest depth of the
    followers it hears that come before it (0 if none): on a cycle the back edges are
    dropped, which is the preconditioner's graph.
    """
    N = len(ptr) - 1
    indeg = np.diff(ptr).astype(int)
    listeners: list[list[int]] = [[] for _ in range(N)]
    for i in range(N):
        for j in idx[ptr[i] : ptr[i + 1]]:
            listeners[int(j)].append(i)
    done = np.zeros(N, bool)
    order: list[int] = []
    acyclic = True
    ready = sorted(int(i) for i in np.flatnonzero(indeg == 0))
    while len(order) < N:
        if not ready:  # a cycle: break it at the follower with the fewest missing inputs
            acyclic = False
            wait = np.flatnonzero(~done)
            ready = [int(wait[np.argmin(indeg[wait])])]
        j = ready.pop(0)
        if done[j]:
            continue
        done[j] = True
        order.append(j)
        for i in listeners[j]:
            indeg[i] -= 1
            if indeg[i] == 0 and not done[i]:
                ready.append(i)
        ready.sort()
    pos = np.empty(N, dtype=int)
    pos[order] = np.arange(N)
    depth = np.zeros(N, dtype=int)
    for i in order:
        js = [j for j in idx[ptr[i] : ptr[i + 1]] if pos[j] < pos[i]]
        depth[i] = 1 + depth[js].max() if js else 0
    grouped = np.asarray(sorted(order, key=lambda i: (depth[i], pos[i])), dtype=np.int32)
    return grouped, acyclic, depth.astype(np.int32)


@dataclass(frozen=True)
class Topology:
    """One topology as the driver reads it.

    Attributes
    ----------
    t_start : float
    ptr, idx, w : ndarray
        CSR of the off-diagonal (L + B)_ij of each row (follower i hears idx).
    cpl : ndarray
        N × 2: (l̄_ii, a_i0 h_i).
    order : ndarray
        Sorted by depth: on an acyclic topology each follower comes after all it hears.
    acyclic : bool
    depth : ndarray
        N: each follower's depth (on a cycle, over the edges from earlier followers).
    """

    t_start: float
    ptr: np.ndarray
    idx: np.ndarray
    w: np.ndarray
    cpl: np.ndarray
    order: np.ndarray
    acyclic: bool
    depth: np.ndarray


def _csr(
    t_start: float, ptr: np.ndarray, idx: np.ndarray, w: np.ndarray, cpl: np.ndarray
) -> Topology:
    """The :class:`Topology` of a CSR pattern, with its order and depths."""
    order, acyclic, depth = _order(ptr, idx)
    return Topology(float(t_start), ptr, idx, w, cpl, order, acyclic, depth)


def topology(t_start: float, adjacency: np.ndarray, pinning: np.ndarray, h: np.ndarray) -> Topology:
    """The driver's data of one graph (eq. (6)'s L + B and a0 ∘ h).

    Parameters
    ----------
    t_start : float
    adjacency : ndarray
        N×N, a_ij (follower i hears j).
    pinning : ndarray
        N, a_i0.
    h : ndarray
        N gauge signs.
    """
    L_B = pinned_laplacian(np.asarray(adjacency, float), np.asarray(pinning, float)).toarray()
    off = L_B != 0
    np.fill_diagonal(off, False)
    ptr = np.concatenate([[0], np.cumsum(off.sum(axis=1))]).astype(np.int32)
    idx = np.nonzero(off)[1].astype(np.int32)
    cpl = np.column_stack([np.diag(L_B), np.asarray(pinning, float) * h]).astype(float)
    return _csr(t_start, ptr, idx, L_B[off].astype(float), cpl)


@dataclass(frozen=True)
class Segment:
    """A stretch of time on which the same topologies are active (the driver's unit).

    With ``graph.link_fade`` = T > 0 the weights are W(t) = Σ_k c_k(t) W_k with
    c_k = σ_k − σ_{k+1} (σ_0 = 1, σ_K = 0, σ_k = σ((t − s_k)/T), :func:`core.graph.fade_jets`).
    A segment's pattern is the union of its active topologies' (two acyclic graphs fading
    into each other may form a cycle); with T = 0 every segment is one topology.

    Attributes
    ----------
    t_start : float
    graph : Topology
        The union pattern, its order and depths (``w``, ``cpl``: the first active one's).
    active : ndarray
        Indices k of the active topologies.
    w : ndarray
        nact × nnz: each active topology's off-diagonal (L + B)_ij on the union pattern.
    cpl : ndarray
        nact × N × 2: each active topology's (l̄_ii, a_i0 h_i).
    """

    t_start: float
    graph: Topology
    active: np.ndarray
    w: np.ndarray
    cpl: np.ndarray


def _union(t_start: float, tops: tuple[Topology, ...], active: list[int]) -> Segment:
    """The segment of ``active`` topologies: union pattern, each one's weights on it."""
    if len(active) == 1:
        tp = tops[active[0]]
        return Segment(
            float(t_start), tp, np.asarray(active, np.int32), tp.w[None, :], tp.cpl[None]
        )
    N = len(tops[0].ptr) - 1
    # edge (i, j) as i N + j: sorted, the union's keys are its CSR order
    keys = [np.repeat(np.arange(N), np.diff(tops[k].ptr)) * N + tops[k].idx for k in active]
    union = np.unique(np.concatenate(keys))
    w = np.zeros((len(active), len(union)))
    for a, (k, key) in enumerate(zip(active, keys, strict=True)):
        w[a, np.searchsorted(union, key)] = tops[k].w
    ptr = np.searchsorted(union, np.arange(N + 1) * N).astype(np.int32)
    cpl = np.stack([tops[k].cpl for k in active])
    g = _csr(t_start, ptr, (union % N).astype(np.int32), w[0], cpl[0])
    return Segment(float(t_start), g, np.asarray(active, np.int32), w, cpl)


def segments(tops: tuple[Topology, ...], fade: float) -> tuple[Segment, ...]:
    """The driver's segments of a switched graph whose links fade over ``fade`` seconds.

    Boundaries at every switching time s_k and, with ``fade`` = T > 0, at every s_k + T;
    topology k is active on [s_k, s_{k+1} + T) (s_0 = 0, s_K = ∞), where its c_k ≠ 0.

    Parameters
    ----------
    tops : tuple of Topology
        The base graph, then one per switching time (``t_start`` increasing).
    fade : float
        ``graph.link_fade`` (0: raw switching, one topology per segment).
    """
    starts = [t.t_start for t in tops]
    if fade <= 0.0 or len(tops) == 1:
        return tuple(_union(s, tops, [k]) for k, s in enumerate(starts))
    out = []
    for b in sorted({*starts, *(s + fade for s in starts[1:])}):
        act = [
            k
            for k in range(len(tops))
            if starts[k] <= b and (k + 1 == len(tops) or b < starts[k + 1] + fade)
        ]
        out.append(_union(b, tops, act))
    return tuple(out)
