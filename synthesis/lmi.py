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

from core.errors import SynthesisError
from synthesis.lmi_matrices import lmi15_matrix, lmi15_matrix_P, lmi16_matrix

# Solver tolerances set explicitly, and the strictness margin ε >= 10 × each of them.
SOLVER_TOL = {"CLARABEL": 1e-8, "SCS": 1e-7}
LMI_EPS = 1e-6
# Bound X ⪯ CAP_FACTOR·scale·I used only when an analytic centre does not exist (unbounded set).
CAP_FACTOR = 10.0
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

    Parameters
    ----------
    prob : cvxpy.Problem
        The problem; solved in place.
    solvers : tuple of str, optional
        Solvers to try in order; default :data:`SOLVERS`.
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


def _sym_basis(m: int) -> list[np.ndarray]:
    """Basis E_ij (i <= j) of the symmetric m×m matrices."""
    out = []
    for i in range(m):
        for j in range(i, m):
            E = np.zeros((m, m))
            E[i, j] = E[j, i] = 1.0
            out.append(E)
    return out


def _centre_polish(
    blocks: list[tuple[np.ndarray, list[np.ndarray]]], x0: np.ndarray, *, iters: int = 60
) -> np.ndarray | None:
    """Newton's method for the analytic centre max Σ_j log det(M_j0 + Σ_k x_k M_jk).

    The barrier is self-concordant and strictly concave on a bounded set, so Newton
    from the solver's (interior) point converges quadratically to the unique centre;
    this removes the solver's ~sqrt(tolerance) error in the argument. Returns None
    if the start is not strictly interior or Newton fails.
    """

    def mats(x: np.ndarray) -> list[np.ndarray]:
        return [M0 + sum(xk * Mk for xk, Mk in zip(x, Ms, strict=True)) for M0, Ms in blocks]

    def value(x: np.ndarray) -> float:
        tot = 0.0
        for M in mats(x):
            try:
                Lc = np.linalg.cholesky(0.5 * (M + M.T))
            except np.linalg.LinAlgError:
                return -np.inf
            tot += 2.0 * float(np.log(np.diag(Lc)).sum())
        return tot

    x = np.asarray(x0, dtype=float).copy()
    f = value(x)
    if not np.isfinite(f):
        return None
    K = x.size
    for _ in range(iters):
        g = np.zeros(K)
        H = np.zeros((K, K))
        for M, (_, Ms) in zip(mats(x), blocks, strict=True):
            Mi = np.linalg.inv(0.5 * (M + M.T))
            W = [Mi @ Mk for Mk in Ms]
            g += np.array([np.trace(Wk) for Wk in W])
            H -= np.array([[np.sum(Wk * Wl.T) for Wl in W] for Wk in W])
        try:
            dx = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            return None
        dec = float(g @ dx)  # Newton decrement squared (H is negative definite)
        if dec < 1e-24:
            break
        t = 1.0
        while t > 1e-12:
            fn = value(x + t * dx)
            if fn >= f + 0.25 * t * dec:
                break
            t *= 0.5
        else:
            return None
        x, f = x + t * dx, fn
    return x


# --------------------------------------------------------------------------- LMI (15)
@dataclass(frozen=True)
class TResult:
    """Result of LMI (15): T, Q = B0ᵀT⁻¹ and the solver's report.

    ``feasible`` says whether (15) holds; ``cap`` is the bound T ⪯ cap·I (or P ⪯ cap·I)
    added when the feasible set is unbounded, else None.
    """

    T: np.ndarray
    Q: np.ndarray
    info: SolveInfo
    feasible: bool
    cap: float | None = None  # the bound X ⪯ cap·I, when the feasible set needed one


def _unbounded(A0: np.ndarray, d1: float, B0: np.ndarray | None = None) -> bool:
    """Does the feasible set of LMI (15) have a recession direction?

    In T: T + tN stays feasible for N ⪰ 0 with L(N) = ĀN + NĀᵀ ⪯ 0, Ā = A0 + (δ1/2)I;
    such N ≠ 0 exists iff Ā has an eigenvalue with Re <= 0 (so the test is exact).
    In P = T⁻¹ with B0ᵀP = Q fixed: N ⪰ 0, B0ᵀN = 0, NĀ + ĀᵀN ⪯ 0, trace N = 1 is a small
    SDP feasibility problem.
    """
    m = A0.shape[0]
    Ab = A0 + 0.5 * d1 * np.eye(m)
    if B0 is None:
        return bool(np.linalg.eigvals(Ab).real.min() <= 0)
    N = cp.Variable((m, m), symmetric=True)
    R = cp.Variable((m, m), symmetric=True)
    cons = [N >> 0, cp.trace(N) == 1, B0.T @ N == 0, R == -(N @ Ab + Ab.T @ N), R >> 0]
    info = solve(cp.Problem(cp.Minimize(0), cons))
    return info.status == "optimal"


def _centre(X: cp.Variable, S: cp.Variable, cons: list, cap: float | None) -> SolveInfo:
    """Analytic centre max log det X + log det S (+ log det(cap·I − X) when the set is
    unbounded, e.g. when A0 + (δ1/2)I has stable modes, and X ⪯ cap·I)."""
    m = X.shape[0]
    obj = cp.log_det(X) + cp.log_det(S)
    if cap is not None:
        U = cp.Variable((m, m), symmetric=True)
        obj = obj + cp.log_det(U)
        cons = cons + [U == cap * np.eye(m) - X]
    return solve(cp.Problem(cp.Maximize(obj), cons))


def _polish_affine(
    X0: np.ndarray,
    dirs: list[np.ndarray],
    others: list[tuple[np.ndarray, list[np.ndarray]]],
    cap: float | None,
) -> np.ndarray | None:
    """Polish X = X0 + Σ x_k D_k to the analytic centre of log det X + Σ log det(others) (+ cap)."""
    m = X0.shape[0]
    blocks = [(X0, dirs), *others]
    if cap is not None:
        blocks.append((cap * np.eye(m) - X0, [-D for D in dirs]))
    x = _centre_polish(blocks, np.zeros(len(dirs)))
    if x is None:
        return None
    return _sym(X0 + sum(xk * D for xk, D in zip(x, dirs, strict=True)))


def synth_T(A0: np.ndarray, B0: np.ndarray, lb1: float, d1: float) -> TResult:
    """Solve LMI (15) for T ≻ 0 (analytic centre), then Q = B0ᵀT⁻¹.

    The feasible set is bounded when A0 + (δ1/2)I is anti-stable (the paper's double
    integrator); otherwise T ⪯ cap·I with cap = :data:`CAP_FACTOR`·λ̄1‖B0‖²/δ1 (the
    scale A0T + δ1T ~ λ̄1B0B0ᵀ suggests) is added and recorded.

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    lb1 : float
        λ̄1 > 0.
    d1 : float
        δ1 > 0.

    Raises
    ------
    SynthesisError
        LMI (15) is infeasible for these λ̄1, δ1 (named), or no solver succeeded.
    """
    m = A0.shape[0]
    T = cp.Variable((m, m), symmetric=True)
    S = cp.Variable((m, m), symmetric=True)  # S = −F, symmetric by construction
    F = lmi15_matrix(A0, B0, T, lb1, d1)  # eq. (15)
    cons = [S == -F, T >> LMI_EPS * np.eye(m), S >> LMI_EPS * np.eye(m)]
    cap = CAP_FACTOR * lb1 * float(np.linalg.norm(B0, 2)) ** 2 / d1
    used_cap = cap if _unbounded(A0, d1) else None
    info = _centre(T, S, cons, used_cap)
    if info.status != "optimal" or T.value is None:
        raise SynthesisError(
            f"observer: LMI (15) in T is infeasible or unsolved for lambda_bar1 = {lb1:g}, "
            f"delta1 = {d1:g} ({info.solver}: {info.status}); lower delta1 or raise lambda_bar1"
        )
    Tv = _sym(np.asarray(T.value))
    # polish to the exact analytic centre: −F(Tv + D) = −F(Tv) − L(D), L(D) = A0D + DA0ᵀ + δ1D
    Es = _sym_basis(m)
    others = [(-lmi15_matrix(A0, B0, Tv, lb1, d1), [-(A0 @ E + E @ A0.T + d1 * E) for E in Es])]
    Tp = _polish_affine(Tv, Es, others, used_cap)
    if Tp is not None:
        Fp = lmi15_matrix(A0, B0, Tp, lb1, d1)
        if np.linalg.eigvalsh(Tp)[0] >= LMI_EPS and np.linalg.eigvalsh(-Fp)[0] >= LMI_EPS:
            Tv = Tp
    Qv = B0.T @ np.linalg.inv(Tv)  # Q = B0ᵀT⁻¹ (eq. (9))
    return TResult(T=Tv, Q=Qv, info=info, feasible=True, cap=used_cap)


def check_given_Q(A0: np.ndarray, B0: np.ndarray, Q: np.ndarray, lb1: float, d1: float) -> TResult:
    """Is the given Q = B0ᵀT⁻¹ for some T satisfying LMI (15)? An LMI in P = T⁻¹.

    With B0ᵀP = Q fixed, T⁻¹B0B0ᵀT⁻¹ = QᵀQ and (15) multiplied by P on both sides is
    linear in P. Returns the analytic centre when feasible (with P ⪯ cap·I,
    cap = :data:`CAP_FACTOR`·λ̄1‖Q‖²/δ1, if the set is unbounded); otherwise the P that
    minimises λ_max of the LMI matrix (``feasible=False``), so downstream code still
    has a T to work with while the violation is reported.

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    Q : ndarray
        p×m gain given by the scenario.
    lb1 : float
        λ̄1 > 0.
    d1 : float
        δ1 > 0.
    """
    m = A0.shape[0]
    Q = np.asarray(Q, dtype=float)
    P = cp.Variable((m, m), symmetric=True)
    S = cp.Variable((m, m), symmetric=True)
    G = lmi15_matrix_P(A0, Q, P, lb1, d1)  # eq. (15) in P = T⁻¹
    base = [S == -G, B0.T @ P == Q, P >> LMI_EPS * np.eye(m)]
    cap = CAP_FACTOR * max(1.0, lb1 * float(np.linalg.norm(Q, 2)) ** 2 / d1)
    used_cap = cap if _unbounded(A0, d1, B0) else None
    info = _centre(P, S, base + [S >> LMI_EPS * np.eye(m)], used_cap)
    if info.status == "optimal" and P.value is not None:
        Pv = _sym(np.asarray(P.value))
        # polish over {P : B0ᵀP = Q}: P = Pv + Σ x_k N_k with B0ᵀN_k = 0
        Es = _sym_basis(m)
        Amap = np.array([(B0.T @ E).ravel() for E in Es]).T  # columns: B0ᵀE_k
        _, sv, Vt = np.linalg.svd(Amap)
        rank = int((sv > 1e-12 * max(1.0, sv[0] if sv.size else 0.0)).sum())
        Ns = [sum(v * E for v, E in zip(row, Es, strict=True)) for row in Vt[rank:]]
        if Ns:
            G0 = -lmi15_matrix_P(A0, Q, Pv, lb1, d1)
            others = [(G0, [-(N @ A0 + A0.T @ N + d1 * N) for N in Ns])]
            Pp = _polish_affine(Pv, Ns, others, used_cap)
            if Pp is not None:
                Gp = lmi15_matrix_P(A0, Q, Pp, lb1, d1)
                if np.linalg.eigvalsh(Pp)[0] >= LMI_EPS and np.linalg.eigvalsh(-Gp)[0] >= LMI_EPS:
                    Pv = Pp
        return TResult(T=_sym(np.linalg.inv(Pv)), Q=Q, info=info, feasible=True, cap=used_cap)
    # least violation, bounded so the problem stays well posed
    s_ = cp.Variable()
    prob2 = cp.Problem(cp.Minimize(s_), base + [S >> -s_ * np.eye(m), P << cap * np.eye(m)])
    info2 = solve(prob2)
    if P.value is None:
        raise SynthesisError(
            f"observer.Q: no symmetric P ≻ 0 with B0ᵀP = Q exists ({info2.solver}: {info2.status}); "
            "give a Q for which [[*, Q]] completes to a positive definite T⁻¹"
        )
    Pv = _sym(np.asarray(P.value))
    return TResult(T=_sym(np.linalg.inv(Pv)), Q=Q, info=info, feasible=False, cap=cap)


def min_lambda_bar1_for_Q(A0: np.ndarray, B0: np.ndarray, Q: np.ndarray, d1: float) -> float:
    """Smallest λ̄1 for which the given Q satisfies LMI (15) with margin ε (jointly linear).

    The feasible set grows with λ̄1 (−λ̄1QᵀQ ⪯ 0), so the feasible range is
    (min, ∞). Returns ``inf`` when no λ̄1 works.

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    Q : ndarray
        p×m gain given by the scenario.
    d1 : float
        δ1 > 0.
    """
    m = A0.shape[0]
    P = cp.Variable((m, m), symmetric=True)
    lb = cp.Variable()
    G = lmi15_matrix_P(A0, Q, P, lb, d1)  # eq. (15) in P = T⁻¹
    cons = [B0.T @ P == Q, P >> LMI_EPS * np.eye(m), -G >> LMI_EPS * np.eye(m), lb >= 0]
    prob = cp.Problem(cp.Minimize(lb), cons)
    info = solve(prob)
    if info.status != "optimal" or lb.value is None:
        return float("inf")
    return float(lb.value)


# --------------------------------------------------------------------------- LMI (16)
@dataclass(frozen=True)
class OmegaResult:
    """Result of LMI (16): Ω, Θ, the solver's report and whether (16) holds (``feasible``)."""

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

    Parameters
    ----------
    Phi : ndarray
        m×m, Φ = I − ΓC0.
    A0 : ndarray
        m×m leader state matrix.
    C0 : ndarray
        n×m leader output matrix.
    d2 : float
        δ2 > 0, the rate certified.
    rel_margin : float
        The LMI is solved at δ2(1 + rel_margin).

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
    """With Θ given, LMI (16) is an LMI in Ω alone: find Ω (Ω ⪰ I, min ‖Ω‖_F) or report it fails.

    Parameters
    ----------
    Phi : ndarray
        m×m, Φ = I − ΓC0.
    A0 : ndarray
        m×m leader state matrix.
    C0 : ndarray
        n×m leader output matrix.
    Theta : ndarray
        m×n observer gain given by the scenario.
    d2 : float
        δ2 > 0.
    """
    m = A0.shape[0]
    Om = cp.Variable((m, m), symmetric=True)
    S = cp.Variable((m, m), symmetric=True)
    F = lmi16_matrix(Phi, A0, C0, Theta, Om, d2)  # eq. (16)
    cons = [S == -F, S >> LMI_EPS * np.eye(m), Om >> np.eye(m)]
    prob = cp.Problem(cp.Minimize(cp.sum_squares(Om)), cons)
    info = solve(prob)
    if info.status == "optimal" and Om.value is not None:
        return OmegaResult(_sym(np.asarray(Om.value)), np.asarray(Theta, float), info, True)
    return OmegaResult(np.eye(m), np.asarray(Theta, float), info, False)
