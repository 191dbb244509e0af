"""Assumptions 1 and 2 of the paper, checked on numbers (docs/reading.md, 'Network and signed graphs' and 'Leader').

Assumption 1 (network): every follower is reachable from the leader, equivalently
L̄ = H(L + B)H is a nonsingular M-matrix; for signed graphs the graph must be
structurally balanced and the gauge H = diag(±1) is found here.

Assumption 2 (leader): rank(C0B0) = rank(B0) = p and no invariant zero of
(A0, B0, C0) in the closed right half-plane (the unknown-input-observer condition).
"""

from __future__ import annotations

import itertools
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from symbolic.errors import SynthesisError

# Relative tolerance of the SVD rank tests (rank of C0B0, B0 and of the system pencil).
RANK_RTOL = 1e-9
# A candidate s is an invariant zero when σ_min(P(s)) <= ZERO_RTOL · ‖[[A0, B0], [C0, 0]]‖, and (tall
# systems) both random projections have it within MATCH_RTOL_ZERO·(1 + |s|).
ZERO_RTOL = 1e-4
MATCH_RTOL_ZERO = 1e-3
# Generalised eigenvalues beyond INF_ZERO·‖[[A0, B0], [C0, 0]]‖ count as infinite.
INF_ZERO = 1e7


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


# --------------------------------------------------------------------------- Assumption 2
@dataclass(frozen=True)
class LeaderCheck:
    """Result of Assumption 2.

    Attributes
    ----------
    rank_C0B0, rank_B0 : int
    zeros : ndarray
        Invariant zeros of (A0, B0, C0), complex, sorted by real part.
    control_zeros : ndarray or None
        The zeros python-control finds (square systems, or the common zeros of
        its square sub-systems), or None when it cannot answer.
    cross_check : str
        What the cross-check found.
    """

    rank_C0B0: int
    rank_B0: int
    zeros: np.ndarray
    control_zeros: np.ndarray | None
    cross_check: str
    notes: list[str] = field(default_factory=list)


def _rank(M: np.ndarray) -> int:
    s = np.linalg.svd(M, compute_uv=False)
    return int((s > RANK_RTOL * max(1.0, s[0] if s.size else 0.0)).sum()) if s.size else 0


def system_pencil(A0: np.ndarray, B0: np.ndarray, C0: np.ndarray, s: complex) -> np.ndarray:
    """Rosenbrock system matrix [[sI − A0, B0], [C0, 0]] at s (Assumption 2).

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    C0 : ndarray
        n×m leader output matrix.
    s : complex
        Point at which the pencil is evaluated.
    """
    m, p, n = A0.shape[0], B0.shape[1], C0.shape[0]
    top = np.hstack([s * np.eye(m) - A0, B0])
    bot = np.hstack([C0, np.zeros((n, p))])
    return np.vstack([top, bot]).astype(complex)


def _is_zero(A0: np.ndarray, B0: np.ndarray, C0: np.ndarray, s: complex) -> bool:
    """SVD rank test of the pencil at s, relative to the data (not to |s|: near-infinite
    eigenvalues of a squared-down pencil would otherwise pass as zeros)."""
    sv = np.linalg.svd(system_pencil(A0, B0, C0, s), compute_uv=False)
    data = np.block([[A0, B0], [C0, np.zeros((C0.shape[0], B0.shape[1]))]])
    return bool(sv[-1] <= ZERO_RTOL * max(1.0, float(np.linalg.norm(data, 2))))


def invariant_zeros(A0: np.ndarray, B0: np.ndarray, C0: np.ndarray) -> np.ndarray:
    """Invariant zeros of (A0, B0, C0) from the Rosenbrock pencil.

    The tall (n >= p) pencil s·E − F with E = [[I, 0], [0, 0]], F = [[A0, −B0], [−C0, 0]]
    is squared down from the left by two fixed random projections W (m+p)×(m+n);
    each square pencil's finite generalised eigenvalues contain every invariant zero
    plus zeros that depend on W. A candidate of the first projection is kept when the
    second one has it too (within :data:`MATCH_RTOL_ZERO`) and the full pencil loses
    rank there (SVD test, :data:`ZERO_RTOL`). Square systems use W = I. The tolerances
    are loose on purpose: a zero of multiplicity k is computed only to ~eps^(1/k).

    Parameters
    ----------
    A0, B0, C0 : ndarray
        m×m, m×p, n×m with rank(C0B0) = p (so n >= p and the pencil has full normal rank).

    Returns
    -------
    ndarray
        Complex zeros, sorted by real part.
    """
    m, p, n = A0.shape[0], B0.shape[1], C0.shape[0]
    E = np.zeros((m + n, m + p))
    E[:m, :m] = np.eye(m)
    F = np.block([[A0, -B0], [-C0, np.zeros((n, p))]])
    rng = np.random.default_rng(20260218)
    if n == p:
        Ws = [np.eye(m + n)]
    else:
        Ws = [rng.standard_normal((m + p, m + n)) for _ in range(2)]
    # QZ returns the infinite eigenvalues (relative degree) as huge finite numbers:
    # treat |s| > INF_ZERO · ‖data‖ as infinite
    big = INF_ZERO * max(1.0, float(np.linalg.norm(F, 2)))
    evs = []
    for W in Ws:
        with np.errstate(all="ignore"):
            ev = sla.eigvals(W @ F, W @ E)
        evs.append(ev[np.isfinite(ev) & (np.abs(ev) < big)])
    found: list[complex] = []
    for s in evs[0]:
        s = complex(s)
        if len(evs) > 1 and (
            not evs[1].size or np.min(np.abs(evs[1] - s)) > MATCH_RTOL_ZERO * (1 + abs(s))
        ):
            continue
        if _is_zero(A0, B0, C0, s):
            found.append(s)
    z = np.array(found, dtype=complex)
    return z[np.argsort(z.real, kind="stable")]


def uio_zeros(A0: np.ndarray, B0: np.ndarray, C0: np.ndarray) -> np.ndarray:
    """Invariant zeros as the unobservable modes of (ΦA0, C0) (second implementation).

    With rank(C0B0) = p, rank [[sI − A0, B0], [C0, 0]] = p + rank [[sI − ΦA0], [C0]], so
    the invariant zeros are exactly the eigenvalues of ΦA0 on its unobservable subspace
    (the modes no Θ can move in ΦA0 − ΘC0): the largest ΦA0-invariant subspace in
    ker C0, found by orthogonal (SVD) steps rather than powers of ΦA0.

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    C0 : ndarray
        n×m leader output matrix.
    """
    _, Phi = uio_matrices(B0, C0)
    M = Phi @ A0
    m = A0.shape[0]
    scale = max(1.0, float(np.linalg.norm(M, 2)), float(np.linalg.norm(C0, 2)))
    tol = 1e-9 * scale

    def null_basis(X: np.ndarray) -> np.ndarray:
        if X.shape[1] == 0:
            return np.zeros((X.shape[1], 0))
        _, sv, Vt = np.linalg.svd(X)
        r = int((sv > tol).sum())
        return Vt[r:].T

    # largest M-invariant subspace in ker C0: V_{k+1} = {x ∈ V_k : Mx ∈ V_k} (orthogonal steps)
    V = null_basis(C0)
    for _ in range(m):
        if V.shape[1] == 0:
            break
        Y = null_basis((np.eye(m) - V @ V.T) @ M @ V)
        if Y.shape[1] == V.shape[1]:
            break
        V = V @ Y
    if V.shape[1] == 0:
        return np.zeros(0, dtype=complex)
    z = np.linalg.eigvals(V.T @ M @ V).astype(complex)
    return z[np.argsort(z.real, kind="stable")]


def control_zeros(A0: np.ndarray, B0: np.ndarray, C0: np.ndarray) -> np.ndarray | None:
    """Invariant zeros as python-control sees them, or None when it cannot answer.

    Without slycot python-control handles square systems only. For tall systems every
    invariant zero is a zero of each square sub-system (C0 restricted to p rows), so
    the common zeros of those sub-systems (at most 20 of them) bound the answer.

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    C0 : ndarray
        n×m leader output matrix.
    """
    try:
        import control
    except ImportError:  # pragma: no cover - control is a dependency
        return None
    p, n = B0.shape[1], C0.shape[0]

    def zeros_of(C: np.ndarray) -> np.ndarray | None:
        try:
            sys = control.ss(A0, B0, C, np.zeros((C.shape[0], p)))
            with np.errstate(all="ignore"):
                z = np.asarray(sys.zeros(), dtype=complex)
        except (NotImplementedError, ValueError, np.linalg.LinAlgError):
            return None
        # without slycot, infinite eigenvalues of the pencil come back as ~1e16: drop them
        return z[np.isfinite(z) & (np.abs(z) < 1e12)]

    if n == p:
        return zeros_of(C0)
    common: np.ndarray | None = None
    for rows in itertools.islice(itertools.combinations(range(n), p), 20):
        C = C0[list(rows)]
        if _rank(C @ B0) < p:
            continue  # degenerate square sub-system: its pencil may lose normal rank
        z = zeros_of(C)
        if z is None:
            continue
        if common is None:
            common = z
        else:
            keep = [
                s
                for s in common
                if z.size and np.min(np.abs(z - s)) <= MATCH_RTOL_ZERO * (1 + abs(s))
            ]
            common = np.array(keep, dtype=complex)
    return common


def check_leader(A0: np.ndarray, B0: np.ndarray, C0: np.ndarray) -> LeaderCheck:
    """Assumption 2: rank conditions and invariant zeros (docs/reading.md, 'Leader').

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    C0 : ndarray
        n×m leader output matrix.

    Raises
    ------
    SynthesisError
        rank(C0B0) != p or rank(B0) != p, or an invariant zero has Re(s) >= 0
        (the message gives the numbers).
    """
    p = B0.shape[1]
    r_b, r_cb = _rank(B0), _rank(C0 @ B0)
    if r_b != p or r_cb != p:
        raise SynthesisError(
            f"leader: Assumption 2 fails: rank(C0 B0) = {r_cb}, rank(B0) = {r_b}, p = {p}; "
            "both ranks must equal p (choose C0 with C0 B0 of full column rank)"
        )
    zs = invariant_zeros(A0, B0, C0)
    zu = uio_zeros(A0, B0, C0)
    # conservative: a zero with Re >= 0 found by either implementation fails Assumption 2
    bad = np.concatenate([zs[zs.real >= 0], zu[zu.real >= 0]])
    if bad.size:
        bad = zs[zs.real >= 0] if (zs.real >= 0).sum() >= (zu.real >= 0).sum() else zu[zu.real >= 0]
    if bad.size:
        txt = ", ".join(_fmt(s) for s in bad)
        raise SynthesisError(
            f"leader: Assumption 2 fails: invariant zero(s) {txt} of (A0, B0, C0) with Re(s) >= 0; "
            "no stable unknown-input observer exists (check the signs of C0)"
        )
    cz = control_zeros(A0, B0, C0)
    if cz is None:
        cross = "python-control could not answer"
    else:
        missing = [
            s for s in zs if not cz.size or np.min(np.abs(cz - s)) > MATCH_RTOL_ZERO * (1 + abs(s))
        ]
        extra = [
            s for s in cz if not zs.size or np.min(np.abs(zs - s)) > MATCH_RTOL_ZERO * (1 + abs(s))
        ]
        if missing:
            raise SynthesisError(
                "leader: invariant zeros disagree with python-control: "
                f"pencil {', '.join(_fmt(s) for s in zs)}, "
                f"python-control {', '.join(_fmt(s) for s in cz) or 'none'}"
            )
        cross = "python-control agrees" + (
            f" (its square sub-systems also share {', '.join(_fmt(s) for s in extra)})"
            if extra
            else ""
        )
    same = zs.size == zu.size and all(
        np.min(np.abs(zu - s)) <= MATCH_RTOL_ZERO * (1 + abs(s)) for s in zs
    )
    cross += "; unobservable modes of (ΦA0, C0) " + (
        "agree" if same else f"differ: {', '.join(_fmt(s) for s in zu) or 'none'}"
    )
    return LeaderCheck(
        rank_C0B0=r_cb, rank_B0=r_b, zeros=zs, control_zeros=cz, cross_check=cross, notes=[]
    )


def _fmt(s: complex) -> str:
    s = complex(s)
    if abs(s.imag) <= 1e-12 * (1 + abs(s.real)):
        return f"{s.real:.6g}"
    return f"{s.real:.6g}{s.imag:+.6g}j"


def uio_matrices(B0: np.ndarray, C0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Γ and Φ of the unknown-input observer (docs/reading.md, 'Unknown-input observer').

    Γ = B0[(C0B0)ᵀ(C0B0)]⁻¹(C0B0)ᵀ and Φ = I − ΓC0, so that ΦB0 = 0 (eq. (7), signs
    reconstructed: the paper prints Γ with the opposite sign and Φ = I + ΓC0).

    Parameters
    ----------
    B0 : ndarray
        m×p leader input matrix.
    C0 : ndarray
        n×m leader output matrix; C0B0 must have full column rank p.
    """
    CB = C0 @ B0
    Gamma = B0 @ np.linalg.solve(CB.T @ CB, CB.T)  # eq. (7)
    Phi = np.eye(B0.shape[0]) - Gamma @ C0  # eq. (7)
    return Gamma, Phi
