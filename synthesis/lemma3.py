"""Lemma 3: a diagonal Z ≻ 0 with L̄ᵀZ + ZL̄ ⪰ wZ, w > 0 (docs/reading.md, 'Lemmas 1–3').

Two variants are computed and both are reported:

* ``"lemma3"`` — the paper's z = (L̄ᵀ)⁻¹1_N (sparse LU, any N);
* ``"best"`` — the diagonal Z that maximises w, a generalised-eigenvalue problem
  solved by bisection on cvxpy feasibility problems, with the condition number of
  Z bounded by :data:`BEST_Z_COND` (without a bound the supremum is usually
  approached only as Z becomes singular, e.g. on acyclic graphs). Dense, so only
  for N <= :data:`BEST_Z_MAX_N`.

The variant with the larger w is used.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from core.errors import SynthesisError

BEST_Z_COND = 100.0  # Z ⪰ I, Z ⪯ BEST_Z_COND·I in the maximisation of w
BEST_Z_MAX_N = 60  # dense SDP size limit for the best diagonal Z
DENSE_EIG_MAX_N = 400  # above this, w is computed with sparse shift-invert eigensolvers
BISECT_RTOL = 1e-4  # relative width of the final bisection bracket


@dataclass(frozen=True)
class ZVariant:
    """One diagonal Z of Lemma 3 with its constant w = λ_min(Z^{-1/2}(L̄ᵀZ + ZL̄)Z^{-1/2})."""

    name: str
    z: np.ndarray
    w: float
    detail: str


@dataclass(frozen=True)
class Lemma3Result:
    """Both variants and the one used (larger w)."""

    used: ZVariant
    variants: tuple[ZVariant, ...]
    skipped: str  # why the best-Z variant was not computed ("" when it was)


def w_of(L_bar: np.ndarray | sp.spmatrix, z: np.ndarray) -> float:
    """w = λ_min(Z^{-1/2} S Z^{-1/2}) with S = L̄ᵀZ + ZL̄ (Lemma 3), sparse for large N.

    Parameters
    ----------
    L_bar : ndarray or sparse matrix
        N×N.
    z : ndarray
        Diagonal of Z, all entries > 0.

    Returns
    -------
    float
        The generalised minimum eigenvalue λ_min(S, Z); may be <= 0 if Z is not admissible.
    """
    z = np.asarray(z, dtype=float)
    if np.any(z <= 0):
        raise SynthesisError("Lemma 3: Z has a non-positive diagonal entry; use z_i > 0")
    N = z.size
    r = 1.0 / np.sqrt(z)
    if N <= DENSE_EIG_MAX_N:
        Ld = L_bar.toarray() if sp.issparse(L_bar) else np.asarray(L_bar, dtype=float)
        S = Ld.T * z + (z[:, None] * Ld)  # L̄ᵀZ + ZL̄
        K = (r[:, None] * S) * r[None, :]
        return float(np.linalg.eigvalsh(0.5 * (K + K.T))[0])
    Ls = sp.csr_matrix(L_bar, dtype=float)
    Zs = sp.diags(z)
    S = sp.csc_matrix(Ls.T @ Zs + Zs @ Ls)
    Rs = sp.diags(r)
    K = sp.csc_matrix(Rs @ S @ Rs)
    K = 0.5 * (K + K.T)
    # shift-invert about a Gershgorin lower bound of the spectrum: the eigenvalue nearest
    # the shift is then the smallest one, whatever the sign of K.
    absK = abs(K)
    g = float((2 * K.diagonal() - np.asarray(absK.sum(axis=1)).ravel()).min())
    shift = g - 1e-3 * max(1.0, abs(g))
    vals = spla.eigsh(K, k=1, sigma=shift, which="LM", return_eigenvectors=False)
    return float(vals[0])


def lemma3_z(L_bar: np.ndarray | sp.spmatrix) -> np.ndarray:
    """z = (L̄ᵀ)⁻¹1_N (Lemma 3), by a sparse LU solve.

    Parameters
    ----------
    L_bar : ndarray or sparse matrix
        N×N, L̄ = H(L + B)H, a nonsingular M-matrix.
    """
    Ls = sp.csc_matrix(L_bar, dtype=float)
    z = np.atleast_1d(spla.spsolve(sp.csc_matrix(Ls.T), np.ones(Ls.shape[0])))
    if not np.all(np.isfinite(z)) or z.min() <= 0:
        raise SynthesisError(
            "Lemma 3: (L̄ᵀ)⁻¹1 is not positive, so L̄ is not a nonsingular M-matrix "
            "(Assumption 1); check the graph"
        )
    return z


def best_diagonal_z(
    L_bar: np.ndarray, w_lo: float, *, cond: float = BEST_Z_COND, solver_order=("CLARABEL", "SCS")
) -> tuple[np.ndarray, float, int]:
    """Maximise w over diagonal Z with I ⪯ Z ⪯ cond·I and L̄ᵀZ + ZL̄ ⪰ wZ, by bisection.

    Each step is a cvxpy feasibility problem (an LMI in z for fixed w). The bracket
    starts at [w_lo, 2·min Re λ(L̄)] (an upper bound for any Z ≻ 0: the inequality
    makes −L̄ + (w/2)I Lyapunov stable). The returned w is recomputed from the
    returned z with numpy, never taken from the solver.

    Parameters
    ----------
    L_bar : ndarray
        N×N, L̄ = H(L + B)H.
    w_lo : float
        Lower end of the bisection bracket (a w known to be feasible, or 0).
    cond : float
        Bound on Z: I ⪯ Z ⪯ cond·I.
    solver_order : tuple of str
        cvxpy solvers tried in turn at each step.

    Returns
    -------
    z, w, steps : ndarray, float, int
    """
    import cvxpy as cp

    Ld = np.asarray(L_bar, dtype=float)
    N = Ld.shape[0]
    w_hi = 2.0 * float(np.linalg.eigvals(Ld).real.min())
    zv = cp.Variable(N)
    wp = cp.Parameter(nonneg=True)
    Zm = cp.diag(zv)
    S = Ld.T @ Zm + Zm @ Ld
    M = S - wp * Zm
    cons = [0.5 * (M + M.T) >> 0, zv >= 1.0, zv <= cond]
    prob = cp.Problem(cp.Minimize(0), cons)
    best_z: np.ndarray | None = None
    best_w = -np.inf
    lo, hi = w_lo, w_hi
    steps = 0
    while hi - lo > BISECT_RTOL * max(hi, 1e-12) and steps < 60:
        mid = 0.5 * (lo + hi)
        wp.value = mid
        steps += 1
        ok = False
        for s in solver_order:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    prob.solve(solver=s)
            except cp.error.SolverError:
                continue
            if prob.status in ("optimal", "optimal_inaccurate") and zv.value is not None:
                z = np.clip(np.asarray(zv.value, dtype=float), 1e-12, None)
                w = w_of(Ld, z)
                if w > best_w:
                    best_z, best_w = z, w
                ok = w >= mid * (1 - 1e-6)  # trust only what numpy confirms
                break
            if prob.status in ("infeasible", "infeasible_inaccurate"):
                break
        if ok:
            lo = mid
        else:
            hi = mid
    if best_z is None:
        return np.ones(N), w_of(Ld, np.ones(N)), steps
    return best_z, best_w, steps


def lemma3(L_bar: np.ndarray | sp.spmatrix) -> Lemma3Result:
    """Both Z variants of Lemma 3 and the better one (docs/reading.md, 'Lemmas 1–3').

    Parameters
    ----------
    L_bar : ndarray or sparse matrix
        N×N, L̄ = H(L + B)H, a nonsingular M-matrix (Assumption 1).

    Raises
    ------
    SynthesisError
        If the paper's Z does not give L̄ᵀZ + ZL̄ ≻ 0 (cannot happen for a nonsingular
        M-matrix: S is a symmetric Z-matrix with row sums Zb + 1 > 0).
    """
    N = L_bar.shape[0]
    z0 = lemma3_z(L_bar)
    w0 = w_of(L_bar, z0)
    if w0 <= 0:
        raise SynthesisError(
            f"Lemma 3: L̄ᵀZ + ZL̄ is not positive definite for z = (L̄ᵀ)⁻¹1 (w = {w0:.3g}); "
            "check Assumption 1"
        )
    paper = ZVariant("lemma3", z0, w0, "z = (L̄ᵀ)⁻¹1_N")
    if N > BEST_Z_MAX_N:
        skipped = f"best diagonal Z not computed for N = {N} > {BEST_Z_MAX_N} (dense SDP)"
        return Lemma3Result(used=paper, variants=(paper,), skipped=skipped)
    Ld = L_bar.toarray() if sp.issparse(L_bar) else np.asarray(L_bar, dtype=float)
    # start the bracket at the w of the paper's Z (scaled into I ⪯ Z ⪯ cond·I if it fits)
    zc = z0 / z0.min()
    w_lo = w0 if zc.max() <= BEST_Z_COND else 0.0
    zb, wb, steps = best_diagonal_z(Ld, w_lo)
    best = ZVariant(
        "best",
        zb,
        wb,
        f"max w over diagonal Z, I ⪯ Z ⪯ {BEST_Z_COND:g}·I ({steps} bisection steps)",
    )
    used = best if wb > w0 else paper
    return Lemma3Result(used=used, variants=(paper, best), skipped="")
