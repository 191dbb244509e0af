"""Graph algebra shared by every stage: Assumption 1 (docs/reading.md, 'Network and signed graphs').

Every follower must be reachable from the leader, equivalently L̄ = H(L + B)H is a
nonsingular M-matrix; for signed graphs the graph must be structurally balanced and
the gauge H = diag(±1) is found here.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from core.errors import SynthesisError


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
    A = sp.csr_matrix(adjacency, dtype=float)
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
