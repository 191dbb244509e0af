"""Rigorous definiteness proofs of the certificate's matrix inequalities (docs/synthesis.md,
'Verified certificates').

A matrix inequality is proven on the *exact* matrix the stored gains define: its entries are
formed in rational arithmetic (:func:`rational`, every float is a dyadic rational, so no
rounding happens), then proven positive definite by up to three tests, each a :class:`Proof`:

* ``"rump-cholesky"`` (:func:`rump_pd`): the exact matrix M is rounded to a float matrix F
  (entrywise, correctly rounded), the rounding E = M − F is bounded exactly by
  r = max_i Σ_j |E_ij| ≥ ‖E‖₂, and a floating-point Cholesky factorisation of
  F − (m + r + c)I (diagonal rounded down) running to completion proves M − mI ≻ 0 by Rump's
  theorem (S. M. Rump, "Verification of positive definiteness", BIT 46 (2006) 433–452,
  Theorem 2.3 / Corollary 2.4), with the shift c of :func:`rump_shift`. Every load re-runs it.
* ``"exact-rational"`` (:func:`exact_pd`): LDLᵀ elimination of M − mI in fractions; M − mI ≻ 0
  iff every pivot is > 0 (Sylvester). Only for n ≤ :data:`EXACT_MAX_N`.
* ``"numpy-eigvalsh"``: λ_min of F by LAPACK, not rigorous, recorded for comparison.

``margin`` of a rigorous proof is the m it proved: λ_min(M) > m ≥ 0. Negative definiteness
of M is positive definiteness of −M (exact).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from core.errors import SynthesisError
from synthesis.certificate_record import ProofRecord
from synthesis.gains import Gains
from synthesis.lemma3 import DENSE_EIG_MAX_N
from synthesis.lmi_matrices import lmi15_matrix, lmi16_matrix

U = Fraction(1, 2**53)  # unit roundoff of IEEE binary64, rounding to nearest
ETA = Fraction(1, 2**1074)  # smallest positive subnormal
EXACT_MAX_N = 12  # exact rational LDLᵀ only up to this size (agent-size LMIs)
RUMP = "rump-cholesky"
EXACT = "exact-rational"
NUMPY = "numpy-eigvalsh"


@dataclass(frozen=True)
class Proof:
    """One test's verdict on ``M − margin·I ≻ 0``.

    Attributes
    ----------
    test : str
        ``"rump-cholesky"``, ``"exact-rational"`` or ``"numpy-eigvalsh"``.
    passed : bool
        True when the test proved M ≻ 0 (numpy: when its λ_min estimate is > 0).
    margin : float or None
        Rigorous tests: the m with λ_min(M) > m ≥ 0 proven (None when nothing was proven);
        numpy: its λ_min estimate.
    detail : str
        What was run (shift, rounding bound, pivots).
    """

    test: str
    passed: bool
    margin: float | None
    detail: str = ""

    @property
    def rigorous(self) -> bool:
        """True for the tests that prove (Rump's and the exact one)."""
        return self.test in (RUMP, EXACT)

    def to_json(self) -> ProofRecord:
        """``{"test", "passed", "margin", "detail"}``."""
        m = self.margin
        return {
            "test": self.test,
            "passed": bool(self.passed),
            "margin": None if m is None or not math.isfinite(m) else float(m),
            "detail": self.detail,
        }


# ----------------------------------------------------------------------------- exact data
def rational(x: np.ndarray | float) -> np.ndarray:
    """The exact value of floats as an object array of :class:`fractions.Fraction`.

    Parameters
    ----------
    x : ndarray or float
        Finite floats (a non-finite entry raises ``ValueError``).
    """
    a = np.asarray(x, dtype=float)
    out = np.empty(a.shape, dtype=object)
    for idx, v in np.ndenumerate(a):
        out[idx] = Fraction(float(v))
    return out


def sym_part(M: np.ndarray) -> np.ndarray:
    """(M + Mᵀ)/2, exact for a rational (object) array.

    Parameters
    ----------
    M : ndarray
        Square, of Fractions (object) or floats.
    """
    return (M + M.T) / Fraction(2) if M.dtype == object else 0.5 * (M + M.T)


def _down(q: Fraction) -> float:
    """The largest float ≤ q (q finite, within range)."""
    f = float(q)  # int/int division: correctly rounded
    return f if Fraction(f) <= q else float(np.nextafter(f, -math.inf))


def ieee_ok() -> bool:
    """numpy arithmetic rounds to nearest with gradual underflow (the theorem's model)."""
    one, tiny = np.float64(1.0), np.float64(1e-30)
    nearest = one + tiny == one and one - tiny == one and one + np.float64(2.0**-52) != one
    sub = np.float64(2.0**-1022) / np.float64(2.0) > 0 and np.float64(5e-324) > 0
    return bool(nearest and sub)


# ----------------------------------------------------------------------------- Rump's test
def rump_shift(diag: Iterable[float]) -> Fraction:
    """Rump's shift c for a symmetric float matrix with this (positive) diagonal.

    c = (n+1)u / (1 − 2(n+1)u) · tr(A) + 4nη(2(n+1) + max_i a_ii), u = 2⁻⁵³, η = 2⁻¹⁰⁷⁴,
    i.e. γ_{n+1}/(1 − γ_{n+1})·tr(A) + …, γ_k = ku/(1 − ku): Rump (2006), Corollary 2.4 with
    the trace bound of ‖Δ‖ (formalised in Coq as ``c_upper_bound`` by P. Roux, "Formal proofs
    of rounding error bounds", J. Autom. Reasoning 57 (2016)). Exact.

    Parameters
    ----------
    diag : iterable of float
        a_11 … a_nn, all > 0.
    """
    d = [Fraction(float(v)) for v in diag]
    n = len(d)
    k = n + 1
    return k * U / (1 - 2 * k * U) * sum(d, Fraction(0)) + 4 * n * ETA * (2 * k + max(d))


def float_cholesky_succeeds(A: np.ndarray) -> bool:
    """Floating-point Cholesky A ≈ RᵀR runs to completion (every pivot > 0 and finite).

    IEEE operations in the order of the theorem's formalisation: r_jj = √(a_jj − r_1j² − … −
    r_(j−1)j²) and r_jl = (a_jl − r_1j r_1l − … − r_(j−1)j r_(j−1)l)/r_jj, each product and
    difference rounded separately, left to right. The right-looking form below subtracts
    the outer product of row j of R from the trailing block at step j, which is that order
    for every entry (numpy's elementwise operations do not fuse them).

    Parameters
    ----------
    A : ndarray
        n×n float, symmetric.
    """
    S = np.array(A, dtype=float)
    n = S.shape[0]
    with np.errstate(all="ignore"):
        for j in range(n):
            piv = S[j, j]
            if not (np.isfinite(piv) and piv > 0):
                return False
            row = S[j, j + 1 :] / np.sqrt(piv)
            if not np.all(np.isfinite(row)):
                return False
            S[j + 1 :, j + 1 :] = S[j + 1 :, j + 1 :] - np.outer(row, row)
    return True


def float_enclosure(M: np.ndarray) -> tuple[np.ndarray, Fraction]:
    """F = fl(M) entrywise (correctly rounded) and r = max_i Σ_j |M_ij − F_ij| (exact).

    For symmetric M, ‖M − F‖₂ = ρ(M − F) ≤ ‖M − F‖_∞ = r.

    Parameters
    ----------
    M : ndarray of Fraction
        n×n rational matrix.
    """
    n = M.shape[0]
    F = np.empty((n, n))
    r = Fraction(0)
    for i in range(n):
        row = Fraction(0)
        for j in range(n):
            q = M[i, j]
            f = float(q)
            F[i, j] = f
            if q != f:  # not a float already (zeros of a sparse matrix are the common case)
                row += abs(q - Fraction(f))
        r = max(r, row)
    return F, r


def rump_pd_at(F: np.ndarray, r: Fraction, m: float) -> tuple[bool, str]:
    """Rump's test that every symmetric M with ‖M − F‖₂ ≤ r has M − mI ≻ 0.

    A' = F with diagonal rounded down from F_ii − m − r (so M − mI − A' ⪰ 0); if A' has a
    positive diagonal and the float Cholesky of A' − cI (diagonal rounded down, c from
    :func:`rump_shift` of A') completes, A' ≻ 0 (Rump 2006, Cor. 2.4), hence M − mI ≻ 0.

    Parameters
    ----------
    F : ndarray
        n×n symmetric float matrix.
    r : Fraction
        Bound on ‖M − F‖₂.
    m : float
        The margin to prove (≥ 0).

    Returns
    -------
    proven, detail : bool, str
    """
    n = F.shape[0]
    if 4 * (n + 1) * U >= 1:
        return False, f"n = {n} too large for the theorem"
    shift = Fraction(m) + r
    d = [_down(Fraction(float(F[i, i])) - shift) for i in range(n)]
    if min(d) <= 0:
        return False, "a diagonal entry of the shifted matrix is not positive"
    c = rump_shift(d)
    At = F.copy()
    for i in range(n):
        At[i, i] = _down(Fraction(d[i]) - c)
    ok = float_cholesky_succeeds(At)
    return ok, f"Cholesky of F − (m + r + c)I, r = {float(r):.3g}, c = {float(c):.3g}"


def _candidates(lam: float, slack: float) -> list[float]:
    """Margins to try, largest first; 0 last (strict definiteness alone)."""
    if not (math.isfinite(lam) and lam > 0):
        return [0.0]
    out = [lam - slack * 4.0**k for k in range(6)] + [lam / 2, lam / 16]
    return sorted({m for m in out if m > 0}, reverse=True) + [0.0]


def rump_pd(M: np.ndarray) -> tuple[Proof, Proof]:
    """Prove the exact symmetric matrix ``M`` positive definite, with the largest margin found.

    Parameters
    ----------
    M : ndarray of Fraction
        n×n exactly symmetric rational matrix (e.g. built from :func:`rational` data).

    Returns
    -------
    rump, numpy : Proof, Proof
        Rump's test (margin: the largest m with M − mI ≻ 0 proven, or None) and numpy's
        λ_min of fl(M) for comparison.
    """
    if not ieee_ok():
        raise SynthesisError(
            "floating-point arithmetic does not round to nearest with gradual underflow "
            "(a library set flush-to-zero?): the verified certificate cannot run; "
            "run without that library loaded"
        )
    try:
        F, r = float_enclosure(M)
    except OverflowError:
        nan = Proof(NUMPY, False, None, "entries overflow binary64")
        return Proof(RUMP, False, None, "entries overflow binary64"), nan
    lam = float(np.linalg.eigvalsh(F)[0]) if np.all(np.isfinite(F)) else -math.inf
    n = F.shape[0]
    c_est = float(rump_shift(np.abs(np.diag(F)) + 1e-300))
    slack = 2.0 * (c_est + float(r)) + 4.0 * (n + 1) * 2.0**-53 * float(np.abs(F).sum())
    numpy_proof = Proof(NUMPY, lam > 0, lam, "λ_min of fl(M) by LAPACK (not rigorous)")
    for m in _candidates(lam, slack):
        ok, detail = rump_pd_at(F, r, m)
        if ok:
            return Proof(RUMP, True, m, f"λ_min(M) > {m:.6g}: {detail}"), numpy_proof
    return Proof(RUMP, False, None, f"not proven ({detail})"), numpy_proof


# ----------------------------------------------------------------------------- exact test
def exact_pd(M: np.ndarray, m: Fraction | float = 0) -> bool:
    """Whether M − mI ≻ 0 exactly: symmetric Gaussian elimination (LDLᵀ) in fractions, every
    pivot > 0 (the pivots' products are the leading principal minors: Sylvester's criterion).

    Parameters
    ----------
    M : ndarray of Fraction
        n×n exactly symmetric rational matrix.
    m : Fraction or float
        Shift (exact).
    """
    n = M.shape[0]
    mq = Fraction(m)
    A = [[Fraction(M[i, j]) - (mq if i == j else 0) for j in range(n)] for i in range(n)]
    for k in range(n):
        p = A[k][k]
        if p <= 0:
            return False
        for i in range(k + 1, n):
            f = A[i][k] / p
            if f:
                Ai, Ak = A[i], A[k]
                for j in range(k + 1, n):
                    Ai[j] -= f * Ak[j]
    return True


def exact_proof(M: np.ndarray, tries: Iterable[float]) -> Proof:
    """The exact test at the first margin of ``tries`` it proves (then at 0).

    Parameters
    ----------
    M : ndarray of Fraction
        n×n exactly symmetric rational matrix, n ≤ :data:`EXACT_MAX_N`.
    tries : iterable of float
        Margins to try first (largest first); 0 is tried last.
    """
    for m in [*(t for t in tries if t is not None and t > 0), 0.0]:
        if exact_pd(M, Fraction(m)):
            return Proof(EXACT, True, m, f"LDLᵀ of M − {m:.6g}·I in fractions: all pivots > 0")
    return Proof(EXACT, False, None, "LDLᵀ in fractions: a pivot ≤ 0, M is not positive definite")


def prove_pd(M: np.ndarray, *, exact: bool | None = None) -> tuple[Proof, ...]:
    """Every applicable test of M ≻ 0: Rump's, the exact one (n ≤ :data:`EXACT_MAX_N` unless
    ``exact`` says otherwise), and numpy's estimate.

    Parameters
    ----------
    M : ndarray of Fraction
        n×n exactly symmetric rational matrix (use ``-M`` to prove negative definiteness).
    exact : bool, optional
        Run the exact test (default: when n ≤ :data:`EXACT_MAX_N`).

    Returns
    -------
    tuple of Proof
        (rump, exact, numpy) or (rump, numpy).
    """
    if any(M[i, j] != M[j, i] for i in range(M.shape[0]) for j in range(i)):
        raise ValueError("prove_pd needs an exactly symmetric matrix; pass sym_part(M)")
    rump, est = rump_pd(M)
    if exact if exact is not None else M.shape[0] <= EXACT_MAX_N:
        lam = est.margin if est.margin is not None else 0.0
        tries = [lam * (1 - r) for r in (1e-12, 1e-9, 1e-6)] + [rump.margin or 0.0]
        return rump, exact_proof(M, sorted(tries, reverse=True)), est
    return rump, est


def proven(proofs: Iterable[Proof]) -> bool:
    """True when at least one rigorous test ran and every rigorous test proved.

    Parameters
    ----------
    proofs : iterable of Proof
        The tests run on one inequality.
    """
    rig = [p for p in proofs if p.rigorous]
    return bool(rig) and all(p.passed for p in rig)


# ----------------------------------------------------------------------------- the certificate's
@dataclass(frozen=True)
class Inequality:
    """One matrix inequality of the certificate, as the exact matrix proven ≻ 0.

    Attributes
    ----------
    proved : str
        The matrix, in words (``"−(A0T + TA0ᵀ − λ̄1B0B0ᵀ + δ1T) ≻ 0"``).
    matrix : ndarray of Fraction
        Its exact value from the stored numbers.
    """

    proved: str
    matrix: np.ndarray


def inequalities(g: Gains) -> dict[str, Inequality]:
    """The exact matrices behind the certificate's checks ``T_pd``, ``lmi15``, ``Omega_pd``,
    ``lmi16``, ``lemma3_w`` and ``k1`` (docs/synthesis.md, 'Verified certificates').

    T and Ω enter through their exact symmetric parts, as in the numpy checks. Lemma 3 is
    proven at w' = (1 − 10⁻⁶)·(stored w), the relative room ``lemma3_w`` already allows a
    stored w over the recomputed one; it is left out for N >
    :data:`synthesis.lemma3.DENSE_EIG_MAX_N` or a non-positive z.

    Parameters
    ----------
    g : Gains
        Finite numbers of consistent shapes (``check_shapes_finite`` passed).
    """
    A0, B0, C0 = rational(g.A0), rational(g.B0), rational(g.C0)
    T, Om = sym_part(rational(g.T)), sym_part(rational(g.Omega))
    Phi, Theta = rational(g.Phi), rational(g.Theta)
    q = Fraction
    F15 = lmi15_matrix(A0, B0, T, q(g.lambda_bar1), q(g.delta1))  # eq. (15)
    F16 = lmi16_matrix(Phi, A0, C0, Theta, Om, q(g.delta2))  # eq. (16)
    out = {
        "T_pd": Inequality("T ≻ 0", T),
        "lmi15": Inequality("−(A0T + TA0ᵀ − λ̄1B0B0ᵀ + δ1T) ≻ 0 (eq. (15))", -F15),
        "Omega_pd": Inequality("Ω ≻ 0", Om),
        "lmi16": Inequality("−((ΦA0−ΘC0)ᵀΩ + Ω(ΦA0−ΘC0) + δ2Ω) ≻ 0 (eq. (16))", -F16),
    }
    z = np.diag(g.Z)
    N = z.size
    if float(z.min()) > 0 and N <= DENSE_EIG_MAX_N:
        Lb = np.asarray(g.L_bar, dtype=float)
        w = Fraction(float(g.w)) * (1 - Fraction(1, 10**6))
        zq = [Fraction(float(v)) for v in z]
        S = np.zeros((N, N), dtype=object)
        rows, cols = np.nonzero(Lb)
        for i, j in zip(rows.tolist(), cols.tolist(), strict=True):
            lij = Fraction(float(Lb[i, j]))
            S[i, j] += zq[i] * lij  # (ZL̄)_ij
            S[j, i] += lij * zq[i]  # (L̄ᵀZ)_ji
        for i in range(N):
            S[i, i] -= w * zq[i]
        text = f"L̄ᵀZ + ZL̄ − w'Z ≻ 0, w' = {float(w):.9g} (Lemma 3)"
        out["lemma3_w"] = Inequality(text, S)
    if float(z.min()) > 0:
        zmax = Fraction(float(z.max()))
        X = Phi @ A0 - Theta @ C0 - A0
        c = zmax * q(g.k1) * q(g.delta1_hat) * q(g.delta2_hat)
        K = np.block([[T, zmax * X], [zmax * X.T, c * Om]])
        text = (
            "[[T, z_max X], [z_max Xᵀ, z_max k1 δ̂1 δ̂2 Ω]] ≻ 0, X = ΦA0 − ΘC0 − A0 "
            "(Schur: ⇔ T ≻ 0 and k1 δ̂1 δ̂2 Ω ≻ z_max XᵀT⁻¹X, eq. (17))"
        )
        out["k1"] = Inequality(text, K)
    return out


def prove_inequalities(g: Gains) -> dict[str, tuple[str, tuple[Proof, ...]]]:
    """Every inequality of :func:`inequalities` through :func:`prove_pd`.

    Parameters
    ----------
    g : Gains
        Finite numbers of consistent shapes.

    Returns
    -------
    dict
        Check name → (the matrix proven ≻ 0 in words, its proofs).
    """
    out = {k: (v.proved, prove_pd(v.matrix)) for k, v in inequalities(g).items()}
    out["lambda1"] = lambda1_proof(g)
    return out


def lambda1_proof(g: Gains) -> tuple[str, tuple[Proof, ...]]:
    """Theorem 1's λ1·w′ > λ̄1 in exact arithmetic, at the w′ Lemma 3 is proven for.

    With ``lemma3_w``'s proof (L̄ᵀZ + ZL̄ ⪰ w′Z) this closes Theorem 1's condition on the
    stored numbers without rounding.

    Parameters
    ----------
    g : Gains
        Finite numbers.
    """
    w = Fraction(float(g.w)) * (1 - Fraction(1, 10**6))
    room = Fraction(float(g.lambda1)) * w - Fraction(float(g.lambda_bar1))
    text = f"λ1·w′ > λ̄1, w′ = (1 − 10⁻⁶)·w = {float(w):.9g} (Theorem 1)"
    proof = Proof(EXACT, room > 0, _down(room) if room > 0 else None, "λ1·w′ − λ̄1 in fractions")
    return text, (proof,)
