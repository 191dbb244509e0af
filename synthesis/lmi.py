"""LMIs (15) and (16) through cvxpy: Clarabel first, SCS as the fallback.

Strict inequalities are imposed with an explicit margin ``F ⪯ −εI`` (ε =
:data:`LMI_EPS`, ten times the looser solver tolerance), never as ``≺ 0``.
Every result is re-checked by :mod:`synthesis.certificate` with numpy, without
trusting the solver's status.

Objectives (they make each answer unique and well conditioned, see docs/synthesis.md):

* LMI (15) in T, and in P = T⁻¹ when Q is given: the analytic centre of the
  (bounded) feasible set, max log det(T) + log det(−F). Strictly concave, so the
  answer is unique; it is the point farthest from every boundary in the
  barrier sense, so both T ≻ 0 and F ≺ 0 hold with room to spare.
* LMI (16) in (Ω, Y = ΩΘ): homogeneous, so normalised by Ω ⪰ I, with
  min ‖Ω‖²_F + ‖Y‖²_F: strictly convex (unique), pushes Ω towards I (well
  conditioned) and keeps the observer gain Θ = Ω⁻¹Y moderate.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from symbolic.errors import SynthesisError

# Solver tolerances set explicitly, and the strictness margin ε >= 10 × each of them.
SOLVER_TOL = {"CLARABEL": 1e-8, "SCS": 1e-7}
LMI_EPS = 1e-6
SOLVERS = ("CLARABEL", "SCS")


@dataclass(frozen=True)
class SolveInfo:
    """Which solver answered, its version and status, and the margin ε used."""

    solver: str
    version: str
    status: str
    tol: float
    eps: float


def _solver_version(name: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name.lower())
    except PackageNotFoundError:
        return "unknown"


def solve(prob: cp.Problem, *, solvers: tuple[str, ...] | None = None) -> SolveInfo:
    """Solve with Clarabel, falling back to SCS when Clarabel fails or is inaccurate.

    Returns the info of the last solver tried; the caller inspects ``status``.
    """
    last = SolveInfo("none", "", "not solved", 0.0, LMI_EPS)
    for name in SOLVERS if solvers is None else solvers:
        tol = SOLVER_TOL.get(name, max(SOLVER_TOL.values()))
        opts: dict = {}
        if name == "CLARABEL":
            opts = {"tol_gap_abs": tol, "tol_gap_rel": tol, "tol_feas": tol}
        elif name == "SCS":
            opts = {"eps_abs": tol, "eps_rel": tol, "max_iters": 200000}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                prob.solve(solver=name, **opts)
        except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
            last = SolveInfo(name, _solver_version(name), f"error: {exc}", tol, LMI_EPS)
            continue
        last = SolveInfo(name, _solver_version(name), str(prob.status), tol, LMI_EPS)
        if prob.status == "optimal":
            return last
        if prob.status in ("infeasible", "unbounded"):
            # a clean certificate of infeasibility: the fallback would not change it
            return last
    return last


def _sym(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + M.T)


# --------------------------------------------------------------------------- LMI (15)
def lmi15_matrix(
    A0: np.ndarray, B0: np.ndarray, T: np.ndarray, lb1: float, d1: float
) -> np.ndarray:
    """A0T + TA0ᵀ − λ̄1B0B0ᵀ + δ1T (eq. (15), transposes as the proof needs them)."""
    return A0 @ T + T @ A0.T - lb1 * (B0 @ B0.T) + d1 * T  # eq. (15)


def lmi15_matrix_P(
    A0: np.ndarray, Q: np.ndarray, P: np.ndarray, lb1: float, d1: float
) -> np.ndarray:
    """PA0 + A0ᵀP − λ̄1QᵀQ + δ1P = T⁻¹(eq. (15))T⁻¹ with P = T⁻¹ and Q = B0ᵀP."""
    return P @ A0 + A0.T @ P - lb1 * (Q.T @ Q) + d1 * P  # eq. (15), congruent form


@dataclass(frozen=True)
class TResult:
    T: np.ndarray
    Q: np.ndarray
    info: SolveInfo
    feasible: bool


def synth_T(A0: np.ndarray, B0: np.ndarray, lb1: float, d1: float) -> TResult:
    """Solve LMI (15) for T ≻ 0 (analytic centre), then Q = B0ᵀT⁻¹.

    Raises
    ------
    SynthesisError
        LMI (15) is infeasible for these λ̄1, δ1 (named), or no solver succeeded.
    """
    m = A0.shape[0]
    T = cp.Variable((m, m), symmetric=True)
    S = cp.Variable((m, m), symmetric=True)  # S = −F, symmetric by construction
    F = A0 @ T + T @ A0.T - lb1 * (B0 @ B0.T) + d1 * T  # eq. (15)
    cons = [S == -F, T >> LMI_EPS * np.eye(m), S >> LMI_EPS * np.eye(m)]
    prob = cp.Problem(cp.Maximize(cp.log_det(T) + cp.log_det(S)), cons)
    info = solve(prob)
    if info.status != "optimal" or T.value is None:
        raise SynthesisError(
            f"observer: LMI (15) in T is infeasible or unsolved for lambda_bar1 = {lb1:g}, "
            f"delta1 = {d1:g} ({info.solver}: {info.status}); lower delta1 or raise lambda_bar1"
        )
    Tv = _sym(np.asarray(T.value))
    Qv = B0.T @ np.linalg.inv(Tv)  # Q = B0ᵀT⁻¹ (eq. (9))
    return TResult(T=Tv, Q=Qv, info=info, feasible=True)


def check_given_Q(A0: np.ndarray, B0: np.ndarray, Q: np.ndarray, lb1: float, d1: float) -> TResult:
    """Is the given Q = B0ᵀT⁻¹ for some T satisfying LMI (15)? An LMI in P = T⁻¹.

    With B0ᵀP = Q fixed, T⁻¹B0B0ᵀT⁻¹ = QᵀQ and (15) multiplied by P on both sides is
    linear in P. Returns the analytic centre when feasible; otherwise the P that
    minimises λ_max of the LMI matrix (``feasible=False``), so downstream code still
    has a T to work with while the violation is reported.
    """
    m = A0.shape[0]
    P = cp.Variable((m, m), symmetric=True)
    S = cp.Variable((m, m), symmetric=True)
    G = P @ A0 + A0.T @ P - lb1 * (Q.T @ Q) + d1 * P  # eq. (15) in P = T⁻¹
    base = [S == -G, B0.T @ P == Q, P >> LMI_EPS * np.eye(m)]
    prob = cp.Problem(cp.Maximize(cp.log_det(P) + cp.log_det(S)), base + [S >> LMI_EPS * np.eye(m)])
    info = solve(prob)
    if info.status == "optimal" and P.value is not None:
        Pv = _sym(np.asarray(P.value))
        return TResult(T=np.linalg.inv(Pv), Q=np.asarray(Q, float), info=info, feasible=True)
    # least violation, bounded so the problem stays well posed
    s = cp.Variable()
    cap = 1e6 * (1.0 + float(np.abs(Q).max()) ** 2)
    prob2 = cp.Problem(cp.Minimize(s), base + [S >> -s * np.eye(m), cp.trace(P) <= cap])
    info2 = solve(prob2)
    if P.value is None:
        raise SynthesisError(
            f"observer.Q: no symmetric P ≻ 0 with B0ᵀP = Q exists ({info2.solver}: {info2.status}); "
            "give a Q for which [[*, Q]] completes to a positive definite T⁻¹"
        )
    Pv = _sym(np.asarray(P.value))
    return TResult(T=np.linalg.inv(Pv), Q=np.asarray(Q, float), info=info, feasible=False)


def min_lambda_bar1_for_Q(A0: np.ndarray, B0: np.ndarray, Q: np.ndarray, d1: float) -> float:
    """Smallest λ̄1 for which the given Q satisfies LMI (15) with margin ε (jointly linear).

    The feasible set grows with λ̄1 (−λ̄1QᵀQ ⪯ 0), so the feasible range is
    (min, ∞). Returns ``inf`` when no λ̄1 works.
    """
    m = A0.shape[0]
    P = cp.Variable((m, m), symmetric=True)
    lb = cp.Variable()
    G = P @ A0 + A0.T @ P - lb * (Q.T @ Q) + d1 * P  # eq. (15) in P = T⁻¹
    cons = [B0.T @ P == Q, P >> LMI_EPS * np.eye(m), -G >> LMI_EPS * np.eye(m), lb >= 0]
    prob = cp.Problem(cp.Minimize(lb), cons)
    info = solve(prob)
    if info.status != "optimal" or lb.value is None:
        return float("inf")
    return float(lb.value)


# --------------------------------------------------------------------------- LMI (16)
def lmi16_matrix(
    Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, Theta: np.ndarray, Omega: np.ndarray, d2: float
) -> np.ndarray:
    """(ΦA0 − ΘC0)ᵀΩ + Ω(ΦA0 − ΘC0) + δ2Ω (eq. (16))."""
    Ac = Phi @ A0 - Theta @ C0
    return Ac.T @ Omega + Omega @ Ac + d2 * Omega  # eq. (16)


@dataclass(frozen=True)
class OmegaResult:
    Omega: np.ndarray
    Theta: np.ndarray
    info: SolveInfo
    feasible: bool


def synth_Omega_Theta(
    Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, d2: float, *, rel_margin: float = 0.0
) -> OmegaResult:
    """LMI (16) for Ω ≻ 0 and Θ jointly: Y = ΩΘ, then Θ = Ω⁻¹Y.

    The minimum-norm objective lands on the boundary of the feasible set, so the LMI
    is solved at δ2(1 + rel_margin) and certified at δ2: the certified eigenvalue
    margin is then about rel_margin·δ2·λ_min(Ω) instead of ε.

    Raises
    ------
    SynthesisError
        Infeasible for δ2 (named): δ2 exceeds twice the decay of an unobservable mode.
    """
    m, n = A0.shape[0], C0.shape[0]
    Om = cp.Variable((m, m), symmetric=True)
    Y = cp.Variable((m, n))
    S = cp.Variable((m, m), symmetric=True)
    PA = Phi @ A0
    d2s = d2 * (1.0 + rel_margin)
    F = PA.T @ Om + Om @ PA - C0.T @ Y.T - Y @ C0 + d2s * Om  # eq. (16) with Y = ΩΘ
    cons = [S == -F, S >> LMI_EPS * np.eye(m), Om >> np.eye(m)]
    prob = cp.Problem(cp.Minimize(cp.sum_squares(Om) + cp.sum_squares(Y)), cons)
    info = solve(prob)
    if info.status != "optimal" or Om.value is None:
        ev = np.linalg.eigvals(PA)
        raise SynthesisError(
            f"observer: LMI (16) is infeasible or unsolved for delta2 = {d2:g} ({info.solver}: "
            f"{info.status}); ΦA0 has eigenvalues {np.round(ev, 6).tolist()} and an unobservable "
            "mode at s limits delta2 < -2 Re(s): lower delta2"
        )
    Omv = _sym(np.asarray(Om.value))
    Theta = np.linalg.solve(Omv, np.asarray(Y.value))  # Θ = Ω⁻¹Y
    return OmegaResult(Omega=Omv, Theta=Theta, info=info, feasible=True)


def check_given_Theta(
    Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, Theta: np.ndarray, d2: float
) -> OmegaResult:
    """With Θ given, LMI (16) is an LMI in Ω alone: find Ω (Ω ⪰ I, min ‖Ω‖_F) or report it fails."""
    m = A0.shape[0]
    Om = cp.Variable((m, m), symmetric=True)
    S = cp.Variable((m, m), symmetric=True)
    Ac = Phi @ A0 - Theta @ C0
    F = Ac.T @ Om + Om @ Ac + d2 * Om  # eq. (16)
    cons = [S == -F, S >> LMI_EPS * np.eye(m), Om >> np.eye(m)]
    prob = cp.Problem(cp.Minimize(cp.sum_squares(Om)), cons)
    info = solve(prob)
    if info.status == "optimal" and Om.value is not None:
        return OmegaResult(_sym(np.asarray(Om.value)), np.asarray(Theta, float), info, True)
    return OmegaResult(np.eye(m), np.asarray(Theta, float), info, False)
