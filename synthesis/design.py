"""Observer gains designed for Theorem 1's decay rates: LMIs (15) and (16) as GEVPs.

Theorem 1's supported rate is δ̃ = min{δ1 − δ̂1, α̃1, δ2 − δ̂2}: the decay rates δ1 of LMI (15)
and δ2 of LMI (16) are what the observer's guarantee is made of. Each LMI with its rate free
is a generalised-eigenvalue problem (GEVP): for a fixed δ it is an LMI, and if (X, δ) is
feasible so is (X, δ') for every δ' < δ (X ≻ 0), so the largest δ is found by bisection on
cvxpy feasibility problems (Clarabel, SCS as fall-back: :func:`synthesis.lmi.solve`).

Unbounded gains buy unbounded rates (LMI (15): δ1 grows without bound as T → 0 and
Q = B0ᵀT⁻¹ grows), so each rate is maximised under a cap on its gain's norm:

- LMI (15): ‖Q‖ ≤ q_max through T ⪰ (‖B0‖/q_max) I, since ‖B0ᵀT⁻¹‖ ≤ ‖B0‖ ‖T⁻¹‖
  (convex and sufficient; the achieved ‖Q‖ is reported);
- LMI (16): ‖Θ‖ ≤ θ_max through Ω ⪰ I and ‖Y‖ ≤ θ_max, Y = ΩΘ, since
  ‖Θ‖ = ‖Ω⁻¹Y‖ ≤ ‖Y‖ (the spectral-norm bound is the LMI [[θI, Y], [Yᵀ, θI]] ⪰ 0).

The derivation is in docs/synthesis.md, 'Design'. An independent check of every answer is
:func:`lmi15_rate` / :func:`lmi16_rate`: the largest δ for which a *given* T (or Ω, Θ)
satisfies the LMI, a symmetric-definite generalised eigenvalue (scipy), no bisection and no
solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from core.errors import SynthesisError
from synthesis.api import theorem1_lambda2
from synthesis.lmi_matrices import lmi15_matrix, lmi16_matrix

#: relative width at which the bisection on δ stops
REL_TOL = 1e-3
#: the designed rate is this fraction below the largest feasible one, so the LMI holds with room
RATE_BACKOFF = 0.02
#: each feasibility problem is solved at δ(1 + SOLVE_MARGIN) and accepted only if numpy's
#: eigenvalues confirm δ: the solver's own tolerance never decides feasibility
SOLVE_MARGIN = 1e-4
#: only Clarabel inside the bisection; its point, even "inaccurate", counts only when numpy's
#: eigenvalues confirm it
BISECT_SOLVERS = ("CLARABEL",)
ACCEPTED = ("optimal", "optimal_inaccurate")


def lmi15_rate(A0: np.ndarray, B0: np.ndarray, T: np.ndarray, lb1: float) -> float:
    """The largest δ with A0T + TA0ᵀ − λ̄1B0B0ᵀ + δT ⪯ 0 for this T ≻ 0 (eq. (15)).

    It is the smallest generalised eigenvalue of (−(A0T + TA0ᵀ − λ̄1B0B0ᵀ), T).

    Parameters
    ----------
    A0, B0 : ndarray
        The leader's matrices.
    T : ndarray
        m×m, symmetric positive definite.
    lb1 : float
        λ̄1.
    """
    M = lmi15_matrix(A0, B0, T, lb1, 0.0)
    return float(sla.eigh(-0.5 * (M + M.T), 0.5 * (T + T.T), eigvals_only=True).min())


def lmi16_rate(
    Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, Theta: np.ndarray, Omega: np.ndarray
) -> float:
    """The largest δ with (ΦA0 − ΘC0)ᵀΩ + Ω(ΦA0 − ΘC0) + δΩ ⪯ 0 for this Ω ≻ 0 (eq. (16)).

    Parameters
    ----------
    Phi, A0, C0 : ndarray
        Φ = I − ΓC0 and the leader's matrices.
    Theta, Omega : ndarray
        The UIO gain and Ω ≻ 0.
    """
    M = lmi16_matrix(Phi, A0, C0, Theta, Omega, 0.0)
    return float(sla.eigh(-0.5 * (M + M.T), 0.5 * (Omega + Omega.T), eigvals_only=True).min())


@dataclass(frozen=True)
class Rate15:
    """LMI (15) designed: the largest δ1 under ‖Q‖ ≤ q_max and the gains at the designed δ1.

    Attributes
    ----------
    q_max : float
        The cap on ‖Q‖.
    delta_max : float
        Largest feasible δ1 (bisection, relative width :data:`REL_TOL`).
    delta : float
        The designed δ1 = (1 − :data:`RATE_BACKOFF`) δ_max.
    T, Q : ndarray
        At ``delta``: T ⪰ (‖B0‖/q_max) I and Q = B0ᵀT⁻¹.
    steps : int
        Feasibility problems solved.
    """

    q_max: float
    delta_max: float
    delta: float
    T: np.ndarray
    Q: np.ndarray
    steps: int


@dataclass(frozen=True)
class Rate16:
    """LMI (16) designed: the largest δ2 under ‖Θ‖ ≤ θ_max and the gains at the designed δ2.

    Attributes
    ----------
    theta_max : float
        The cap on ‖Θ‖.
    delta_max, delta : float
        Largest feasible δ2 and the designed one.
    Omega, Theta : ndarray
        At ``delta``.
    steps : int
        Feasibility problems solved.
    """

    theta_max: float
    delta_max: float
    delta: float
    Omega: np.ndarray
    Theta: np.ndarray
    steps: int


def _bisect(feasible, hi: float) -> tuple[float, int]:  # noqa: ANN001
    """Largest δ in (0, hi) with ``feasible(δ)`` (monotone), to relative width REL_TOL."""
    lo, steps = 0.0, 0
    if not feasible(hi * 1e-4):
        raise SynthesisError("no positive decay rate is feasible under the cap")
    lo = hi * 1e-4
    while hi - lo > REL_TOL * hi:
        mid = 0.5 * (lo + hi)
        steps += 1
        if feasible(mid):
            lo = mid
        else:
            hi = mid
    return lo, steps


def _lmi15_point(A0, B0, lb1, d1, tau, eps):  # noqa: ANN001, ANN202
    """T with T ⪰ τI and LMI (15) ⪯ −εI at δ1 = d1, closest to τI (None if infeasible)."""
    import cvxpy as cp

    from synthesis.lmi import solve

    m = A0.shape[0]
    T = cp.Variable((m, m), symmetric=True)
    d_solve = d1 * (1.0 + SOLVE_MARGIN)
    t_solve = tau * (1.0 + SOLVE_MARGIN)
    cons = [T >> t_solve * np.eye(m), lmi15_matrix(A0, B0, T, lb1, d_solve) << -eps * np.eye(m)]
    prob = cp.Problem(cp.Minimize(cp.norm(T, "fro")), cons)
    info = solve(prob, solvers=BISECT_SOLVERS)
    if info.status not in ACCEPTED or T.value is None:
        return None
    Tv = 0.5 * (T.value + T.value.T)
    # accepted only if numpy confirms it (eigenvalues, not the solver's word)
    if np.linalg.eigvalsh(Tv).min() < tau or lmi15_rate(A0, B0, Tv, lb1) < d1:
        return None
    return Tv


def design_lmi15(A0: np.ndarray, B0: np.ndarray, lb1: float, q_max: float) -> Rate15:
    """Maximise δ1 of LMI (15) under ‖Q‖ ≤ q_max (a GEVP, bisection on feasibility problems).

    Parameters
    ----------
    A0, B0 : ndarray
        The leader's matrices.
    lb1 : float
        λ̄1 of LMI (15).
    q_max : float
        Cap on ‖Q‖ = ‖B0ᵀT⁻¹‖ (spectral norm).

    Returns
    -------
    Rate15
    """
    A0, B0 = np.atleast_2d(A0).astype(float), np.atleast_2d(B0).astype(float)
    m = A0.shape[0]
    tau = float(np.linalg.norm(B0, 2)) / q_max  # T ⪰ τI ⇒ ‖Q‖ ≤ ‖B0‖/τ = q_max
    # tr(A0T + TA0ᵀ − λ̄1B0B0ᵀ + δT) < 0 with T ⪰ τI: δ < λ̄1‖B0‖²_F/(mτ) + 2‖A0‖
    hi = lb1 * float(np.sum(B0**2)) / (m * tau) + 2.0 * float(np.linalg.norm(A0, 2)) + 1.0
    eps = 1e-9 * max(1.0, tau)

    def feasible(d: float) -> bool:
        return _lmi15_point(A0, B0, lb1, d, tau, eps) is not None

    dmax, steps = _bisect(feasible, hi)
    delta = (1.0 - RATE_BACKOFF) * dmax
    T = _lmi15_point(A0, B0, lb1, delta, tau, eps)
    if T is None:  # the bisection's lower end was feasible, so a smaller rate is too
        raise SynthesisError(f"LMI (15) at delta1 = {delta:.4g} not confirmed by eigenvalues")
    Q = B0.T @ np.linalg.inv(T)
    return Rate15(q_max, dmax, delta, T, Q, steps + 1)


def _lmi15_given_Q_point(A0, B0, Q, lb1, d1, eps):  # noqa: ANN001, ANN202
    """T = P⁻¹ with B0ᵀP = Q, P ≻ 0 and LMI (15) at δ1 = d1 (None if infeasible)."""
    import cvxpy as cp

    from synthesis.lmi import solve
    from synthesis.lmi_matrices import lmi15_matrix_P

    m = A0.shape[0]
    P = cp.Variable((m, m), symmetric=True)
    d_solve = d1 * (1.0 + SOLVE_MARGIN)
    M = lmi15_matrix_P(A0, Q, P, lb1, d_solve)
    cons = [P >> eps * np.eye(m), B0.T @ P == Q, 0.5 * (M + M.T) << -eps * np.eye(m)]
    prob = cp.Problem(cp.Minimize(cp.norm(P, "fro")), cons)
    info = solve(prob, solvers=BISECT_SOLVERS)
    if info.status not in ACCEPTED or P.value is None:
        return None
    Pv = 0.5 * (P.value + P.value.T)
    if np.linalg.eigvalsh(Pv).min() <= 0:
        return None
    T = np.linalg.inv(Pv)
    if lmi15_rate(A0, B0, 0.5 * (T + T.T), lb1) < d1:
        return None
    return 0.5 * (T + T.T)


def design_lmi15_given_Q(A0: np.ndarray, B0: np.ndarray, Q: np.ndarray, lb1: float) -> Rate15:
    """The largest δ1 of LMI (15) for a *given* Q (an LMI in P = T⁻¹ with B0ᵀP = Q).

    Parameters
    ----------
    A0, B0 : ndarray
        The leader's matrices.
    Q : ndarray
        The given p×m gain.
    lb1 : float
        λ̄1.

    Returns
    -------
    Rate15
        With ``q_max`` = ‖Q‖.
    """
    A0, B0 = np.atleast_2d(A0).astype(float), np.atleast_2d(B0).astype(float)
    Q = np.atleast_2d(np.asarray(Q, float))
    m = A0.shape[0]
    # tr(PA0 + A0ᵀP − λ̄1QᵀQ + δP) < 0: δ < λ̄1‖Q‖²_F/tr P − 2tr(PA0)/tr P; tr P ≥ ‖Q‖²/‖B0ᵀ‖...
    # no closed form bound on tr P from below is needed: the bisection doubles hi until infeasible
    eps = 1e-9
    hi = 1.0
    while _lmi15_given_Q_point(A0, B0, Q, lb1, hi, eps) is not None and hi < 1e6:
        hi *= 2.0

    def feasible(d: float) -> bool:
        return _lmi15_given_Q_point(A0, B0, Q, lb1, d, eps) is not None

    dmax, steps = _bisect(feasible, hi)
    delta = (1.0 - RATE_BACKOFF) * dmax
    T = _lmi15_given_Q_point(A0, B0, Q, lb1, delta, eps)
    if T is None:
        raise SynthesisError(f"LMI (15) at delta1 = {delta:.4g} not confirmed by eigenvalues")
    del m
    return Rate15(float(np.linalg.norm(Q, 2)), dmax, delta, T, Q, steps + 1)


def _lmi16_point(Phi, A0, C0, d2, theta_max, eps):  # noqa: ANN001, ANN202
    """(Ω, Θ) with Ω ⪰ I, ‖Y‖ ≤ θ_max, LMI (16) ⪯ −εI at δ2 = d2 (None if infeasible)."""
    import cvxpy as cp

    from synthesis.lmi import solve

    m, n = A0.shape[0], C0.shape[0]
    Om = cp.Variable((m, m), symmetric=True)
    Y = cp.Variable((m, n))
    PA = Phi @ A0
    d_solve = d2 * (1.0 + SOLVE_MARGIN)
    M = PA.T @ Om + Om @ PA - C0.T @ Y.T - Y @ C0 + d_solve * Om  # eq. (16) with Y = ΩΘ
    t_solve = theta_max * (1.0 - SOLVE_MARGIN)
    norm_y = cp.bmat([[t_solve * np.eye(m), Y], [Y.T, t_solve * np.eye(n)]])
    cons = [Om >> np.eye(m), 0.5 * (M + M.T) << -eps * np.eye(m), norm_y >> 0]
    prob = cp.Problem(cp.Minimize(cp.sum_squares(Om) + cp.sum_squares(Y)), cons)
    info = solve(prob, solvers=BISECT_SOLVERS)
    if info.status not in ACCEPTED or Om.value is None:
        return None
    Omega = 0.5 * (Om.value + Om.value.T)
    if np.linalg.eigvalsh(Omega).min() <= 0:
        return None
    Theta = np.linalg.solve(Omega, Y.value)
    if np.linalg.norm(Theta, 2) > theta_max:
        return None
    if lmi16_rate(Phi, A0, C0, Theta, Omega) < d2:
        return None
    return Omega, Theta


def design_lmi16(Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, theta_max: float) -> Rate16:
    """Maximise δ2 of LMI (16) under ‖Θ‖ ≤ θ_max (a GEVP, bisection on feasibility problems).

    Parameters
    ----------
    Phi, A0, C0 : ndarray
        Φ = I − ΓC0 and the leader's matrices.
    theta_max : float
        Cap on ‖Θ‖ (spectral norm).

    Returns
    -------
    Rate16
    """
    A0, C0 = np.atleast_2d(A0).astype(float), np.atleast_2d(C0).astype(float)
    # δ2 < −2 max Re λ(ΦA0 − ΘC0) ≤ 2 ‖ΦA0 − ΘC0‖ ≤ 2(‖ΦA0‖ + θ_max ‖C0‖)
    hi = 2.0 * (np.linalg.norm(Phi @ A0, 2) + theta_max * np.linalg.norm(C0, 2)) + 1.0
    eps = 1e-9

    def feasible(d: float) -> bool:
        return _lmi16_point(Phi, A0, C0, d, theta_max, eps) is not None

    dmax, steps = _bisect(feasible, float(hi))
    delta = (1.0 - RATE_BACKOFF) * dmax
    pt = _lmi16_point(Phi, A0, C0, delta, theta_max, eps)
    if pt is None:
        raise SynthesisError(f"LMI (16) at delta2 = {delta:.4g} not confirmed by eigenvalues")
    return Rate16(theta_max, dmax, delta, pt[0], pt[1], steps + 1)


def layer_residual(lambda1: float, lambda2: float, phi: float, u: float) -> float:
    """The ‖Qê‖ at which eq. (9)'s v balances an unknown input of size u in the layer.

    The positive root s of λ1 s + λ2 s/(s + φ) = u: the observer's quasi-steady residual
    for a follower that hears the leader while u0 moves slowly (docs/synthesis.md,
    'Observer: the robust term'). With λ2 > u it is below φu/(λ2 − u) for every λ1 ≥ 0; with λ2 = u it
    is about sqrt(uφ/λ1).

    Parameters
    ----------
    lambda1, lambda2 : float
        The observer's linear and robust gains.
    phi : float
        φ_i (at the floor: φ_min).
    u : float
        ‖u0‖ (at most α).
    """
    if lambda1 == 0.0:
        return phi * u / (lambda2 - u) if lambda2 > u else float("inf")
    # eq. (9) at rest in the layer: λ1 s² + (λ1φ + λ2 − u)s − uφ = 0, its positive root
    # in the form that does not cancel
    b = lambda1 * phi + lambda2 - u
    return float(2.0 * u * phi / (b + np.sqrt(b * b + 4.0 * lambda1 * u * phi)))


@dataclass(frozen=True)
class RobustTerm:
    """The robust term −λ2Qê/(‖Qê‖ + φ_i) of eq. (9), designed.

    Attributes
    ----------
    lambda2, phi_min : float
        The designed gain and floor.
    slope : float
        λ2/φ_min, the layer's slope at the floor (kept from the scenario; inf at φ_min = 0).
    given_lambda2, given_phi_min : float
        The scenario's own (λ2 left to synthesis: (1 + margin)α).
    """

    lambda2: float
    phi_min: float
    slope: float
    given_lambda2: float
    given_phi_min: float


def design_robust_term(obs, alpha: float, factor: float) -> RobustTerm:  # noqa: ANN001
    """λ2 = factor·α, φ_min scaled with it so that the layer's slope λ2/φ_min stays.

    Inside the boundary layer the robust term is a gain λ2/φ_i: that slope is what makes
    the loop stiff (the oracle's η⃛_i carries it), so it is kept at the scenario's. With
    λ2 = α the term cancels ‖u0‖ = α only as ‖Qê‖/φ → ∞ and the residual is the linear
    term's, sqrt(αφ_min/λ1); with λ2 > α it is below φ_min α/(λ2 − α) = α·factor/(slope
    (factor − 1)) (:func:`layer_residual`), at factor 2 twice its infimum α/slope.
    Theorem 1 needs λ2 ≥ α; its floor constant c_φ grows with λ2φ_min.

    Parameters
    ----------
    obs : core.model.Observer
        The scenario's observer (its λ2, φ_min, margin).
    alpha : float
        The design's bound on ‖u0‖.
    factor : float
        ``design.robust_gain`` (> 1).
    """
    given = theorem1_lambda2(obs, alpha)
    lambda2 = factor * alpha
    phi_min = float(obs.phi_min) * lambda2 / given
    if np.any(np.asarray(obs.phi0, float) <= phi_min):
        raise SynthesisError(
            f"design.robust_gain = {factor:g}: phi_min = {phi_min:.4g} would reach phi0; "
            "a smaller robust_gain or a larger observer.phi0"
        )
    slope = lambda2 / phi_min if phi_min > 0 else float("inf")
    return RobustTerm(lambda2, phi_min, slope, given, float(obs.phi_min))


#: points of each observer front (caps, geometric up to the cap)
FRONT_POINTS = 7
#: the front's smallest cap, as a fraction of the largest
FRONT_SPAN = 1.0 / 64.0
#: caps when neither ``[design]`` nor the scenario gives one (‖Q‖, ‖Θ‖)
DEFAULT_Q_MAX = 100.0
DEFAULT_THETA_MAX = 10.0


@dataclass(frozen=True)
class ObserverDesign:
    """The observer's designed gains (LMIs (15), (16)) and the fronts they were chosen on.

    Attributes
    ----------
    front15, front16 : tuple
        :class:`Rate15` per ‖Q‖ cap, :class:`Rate16` per ‖Θ‖ cap (increasing caps; the
        last is the cap).
    given15, given16 : Rate15 or Rate16 or None
        The largest rate of the scenario's own Q (Θ) when it gives one (then kept).
    designed_Q, designed_Theta : bool
        Whether Q (Θ) was designed (else the scenario's is kept).
    delta1, delta2 : float
        The designed rates (no more than Theorem 1's δ̃ can use: :func:`useful_rates`).
    T, Q, Omega, Theta : ndarray
        The gains at the designed rates.
    robust : RobustTerm
        The robust term's designed λ2 and φ_min (:func:`design_robust_term`).
    """

    front15: tuple[Rate15, ...]
    front16: tuple[Rate16, ...]
    given15: Rate15 | None
    given16: Rate16 | None
    delta1: float
    delta2: float
    T: np.ndarray
    Q: np.ndarray
    Omega: np.ndarray
    Theta: np.ndarray
    robust: RobustTerm
    designed_Q: bool
    designed_Theta: bool

    def overrides(self) -> dict[str, object]:
        """The observer's keys of the designed scenario (δ̂ = δ/2; λ1 and k1 by synthesis)."""
        out: dict[str, object] = {
            "observer.delta1": float(self.delta1),
            "observer.delta2": float(self.delta2),
            # δ̂(δ − δ̂) is largest at δ̂ = δ/2: k1 ∝ 1/(δ̂1δ̂2) and δ̃ ≤ δ − δ̂ both gain
            "observer.delta1_hat": float(self.delta1) / 2.0,
            "observer.delta2_hat": float(self.delta2) / 2.0,
        }
        if self.designed_Q:
            out["observer.Q"] = np.round(self.Q, 12).tolist()
        if self.designed_Theta:
            out["observer.Theta"] = np.round(self.Theta, 12).tolist()
        out["observer.lambda2"] = self.robust.lambda2
        out["observer.phi_min"] = self.robust.phi_min
        return out


def useful_rates(alpha1_tilde: float, delta2: float) -> tuple[float, float]:
    """The δ1, δ2 beyond which Theorem 1's δ̃ = min{δ1 − δ̂1, α̃1, δ2 − δ̂2} gains nothing.

    With δ̂ = δ/2, δ̃ = min{δ1/2, α̃1, δ2/2}: δ2 is useful up to 2α̃1, δ1 up to min{2α̃1, δ2}.

    Parameters
    ----------
    alpha1_tilde : float
        min_i α1i (the φ law's rate).
    delta2 : float
        The δ2 reached (LMI (16) is designed first).
    """
    return min(2.0 * alpha1_tilde, delta2), 2.0 * alpha1_tilde


def _caps(top: float) -> np.ndarray:
    return top * np.geomspace(FRONT_SPAN, 1.0, FRONT_POINTS)


def _given_theta_rate(Phi, A0, C0, Theta) -> Rate16:  # noqa: ANN001
    """The largest δ2 of LMI (16) for a given Θ: −2 max Re λ(ΦA0 − ΘC0), and Ω at 98 % of it.

    With Θ fixed, (16) is a Lyapunov inequality: feasible for some Ω ≻ 0 exactly when
    ΦA0 − ΘC0 + (δ2/2)I is Hurwitz; Ω solves the Lyapunov equation at the designed rate.
    """
    Ac = Phi @ A0 - Theta @ C0
    dmax = -2.0 * float(np.max(np.linalg.eigvals(Ac).real))
    if dmax <= 0:
        raise SynthesisError("the given Theta leaves Phi A0 - Theta C0 unstable: no rate")
    delta = (1.0 - RATE_BACKOFF) * dmax
    As = Ac + 0.5 * delta * np.eye(Ac.shape[0])
    Omega = sla.solve_continuous_lyapunov(As.T, -np.eye(Ac.shape[0]))
    Omega = 0.5 * (Omega + Omega.T)
    Omega /= np.linalg.eigvalsh(Omega).min()  # Ω ⪰ I, as the synthesis normalises it
    return Rate16(float(np.linalg.norm(Theta, 2)), dmax, delta, Omega, np.asarray(Theta), 0)


def observer_design(scenario) -> ObserverDesign:  # noqa: ANN001
    """Design the observer's rates (and Q, Θ where the scenario leaves them to synthesis).

    A gain the scenario gives is kept and its own largest rate is taken (for Q a GEVP in
    P = T⁻¹, for Θ an eigenvalue); a gain left to synthesis is designed under its cap.
    Either way the rate is no more than Theorem 1's δ̃ can use (:func:`useful_rates`).
    The fronts (rate against cap) are computed for the report in both cases.

    Parameters
    ----------
    scenario : core.scenario.Scenario
        With a ``design`` table: its ``Q_max``, ``Theta_max`` and ``alpha``.

    Returns
    -------
    ObserverDesign
    """
    from synthesis.assumptions import uio_matrices

    spec, lead, obs = scenario.design, scenario.leader, scenario.observer
    A0, B0, C0 = (np.atleast_2d(np.asarray(M, float)) for M in (lead.A0, lead.B0, lead.C0))
    _, Phi = uio_matrices(B0, C0)
    q_top = spec.Q_max or (np.linalg.norm(obs.Q, 2) if obs.Q is not None else DEFAULT_Q_MAX)
    t_top = spec.Theta_max or (
        np.linalg.norm(obs.Theta, 2) if obs.Theta is not None else DEFAULT_THETA_MAX
    )
    a1 = float(np.min(obs.alpha1))
    # LMI (16) first: δ1 is useful only up to δ2 (δ̃ = min{δ1/2, α̃1, δ2/2})
    front16 = [design_lmi16(Phi, A0, C0, float(c)) for c in _caps(float(t_top))]
    _, need2 = useful_rates(a1, 0.0)
    if obs.Theta is None:
        r16 = front16[-1]  # the largest rate under the cap
    else:
        r16 = _given_theta_rate(Phi, A0, C0, np.atleast_2d(np.asarray(obs.Theta, float)))
    delta2, Omega, Theta = r16.delta, r16.Omega, r16.Theta
    if delta2 > need2:  # more than the theorem uses: re-solved at the useful rate
        if obs.Theta is None:
            pt = _lmi16_point(Phi, A0, C0, need2, r16.theta_max, 1e-9)
        else:
            pt = (_given_theta_rate(Phi, A0, C0, Theta).Omega, Theta)
        if pt is not None:
            delta2, (Omega, Theta) = need2, pt
    front15 = [design_lmi15(A0, B0, obs.lambda_bar1, float(c)) for c in _caps(float(q_top))]
    need1, _ = useful_rates(a1, delta2)
    if obs.Q is None:
        r15 = front15[-1]
        tau = float(np.linalg.norm(B0, 2)) / r15.q_max
        solve_at = lambda d: _lmi15_point(A0, B0, obs.lambda_bar1, d, tau, 1e-9 * max(1.0, tau))  # noqa: E731
    else:
        Qg = np.atleast_2d(np.asarray(obs.Q, float))
        r15 = design_lmi15_given_Q(A0, B0, Qg, obs.lambda_bar1)
        solve_at = lambda d: _lmi15_given_Q_point(A0, B0, Qg, obs.lambda_bar1, d, 1e-9)  # noqa: E731
    delta1, T = r15.delta, r15.T
    if delta1 > need1:
        T1 = solve_at(need1)
        if T1 is not None:
            delta1, T = need1, T1
    alpha = spec.alpha if spec.alpha is not None else lead.alpha
    return ObserverDesign(
        front15=tuple(front15),
        front16=tuple(front16),
        given15=None if obs.Q is None else r15,
        given16=None if obs.Theta is None else r16,
        delta1=float(delta1),
        delta2=float(delta2),
        T=T,
        Q=B0.T @ np.linalg.inv(T) if obs.Q is None else np.atleast_2d(np.asarray(obs.Q, float)),
        Omega=Omega,
        Theta=Theta,
        robust=design_robust_term(obs, alpha, spec.robust_gain),
        designed_Q=obs.Q is None,
        designed_Theta=obs.Theta is None,
    )
