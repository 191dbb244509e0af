"""Assumption 2 of the paper (and Assumption 1 from core.graph), checked on numbers (docs/reading.md, 'Network and signed graphs' and 'Leader').

Assumption 1 (network): every follower is reachable from the leader, equivalently
L̄ = H(L + B)H is a nonsingular M-matrix; for signed graphs the graph must be
structurally balanced and the gauge H = diag(±1) is found here.

Assumption 2 (leader): rank(C0B0) = rank(B0) = p and no invariant zero of
(A0, B0, C0) in the closed right half-plane (the unknown-input-observer condition).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from core.errors import SynthesisError

# Relative tolerance of the SVD rank tests (rank of C0B0, B0 and of the system pencil).
RANK_RTOL = 1e-9
# A candidate s is an invariant zero when σ_min(P(s)) <= ZERO_RTOL · ‖[[A0, B0], [C0, 0]]‖, and (tall
# systems) both random projections have it within MATCH_RTOL_ZERO·(1 + |s|).
ZERO_RTOL = 1e-4
MATCH_RTOL_ZERO = 1e-3
# Generalised eigenvalues beyond INF_ZERO·‖[[A0, B0], [C0, 0]]‖ count as infinite.
INF_ZERO = 1e7


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
