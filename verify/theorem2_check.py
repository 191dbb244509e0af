"""Theorem 2's pointwise check: eq. (38) with V̇2 exact (AD), per follower.

V̇2i ≤ −χᵀKχ − ½k2‖θ̂ − d‖² + ½k2‖d‖² (+ Σ_r θ̂_r(|χ_r| − χ_r sgn_ε(χ_r)) with a boundary
layer; + the σ-modification's exact term −(gσ/γ)(ĝ − 1/g)(ĝ − ĝ0) when that law is on;
+ ∂V2i/∂t = (ġ/(2γ))(ĝ² − 1/g²) when g_i varies), with g_i(t) at each sample
(docs/verification.md, 'Theorem 2 (controller)' and 'Theorem 2 on intervals').
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from core.scenario import Scenario
from verify.bounds import VerifyConfig, VerifyError
from verify.lyapunov import (
    InequalityCheck,
    _fast,
    _make,
    agent_block,
    evaluate,
    evaluate_p,
    lyapunov_derivative,
    outputs_at,
    state_block,
)


def sgn_eps(chi: np.ndarray, mode: str, width: float) -> np.ndarray:
    """The sign function the controller uses: exact, sat(χ/ε) or tanh(χ/ε).

    Parameters
    ----------
    chi : ndarray
        Argument, element-wise.
    mode : {"exact", "sat", "tanh"}
        ``options.sign``.
    width : float
        Boundary-layer width ε (unused for ``exact``).
    """
    if mode == "exact":
        return np.sign(chi)
    if mode == "sat":
        return np.clip(chi / width, -1.0, 1.0)
    if mode == "tanh":
        return np.tanh(chi / width)
    raise VerifyError(f"options.sign = {mode!r}: expected exact, sat or tanh")


def theorem2_rhs(
    scenario: Scenario,
    agent: int,
    chi: np.ndarray,
    thetahat: np.ndarray,
    ghat: np.ndarray,
    g: float | np.ndarray,
    gdot: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Right side of eq. (38) for one follower, with the slack of a smoothed sign.

    Parameters
    ----------
    scenario : Scenario
    agent : int
        0-based.
    chi, thetahat : ndarray
        (K, n).
    ghat : ndarray
        (K,).
    g : float or ndarray
        Actuator health g_i at the K samples (or one constant).
    gdot : ndarray, optional
        ġ_i at the K samples; its exact term ∂V2/∂t = (ġ/(2γ))(ĝ² − 1/g²) is added
        (docs/verification.md, 'Theorem 2 on intervals').

    Returns
    -------
    rhs, scale : ndarray
        (K,) the bound and the magnitude of its terms (for the round-off allowance).
    """
    ctrl, opts = scenario.controller, scenario.options
    K = np.asarray(ctrl.k1[agent], float)
    k2 = float(ctrl.k2[agent])
    d = np.asarray(scenario.followers[agent].d, float)
    quad = np.einsum("kr,r,kr->k", chi, K, chi)  # χᵀKχ
    # eq. (36) with eq. (37): −(θ̂ − d)ᵀk2θ̂ ≤ −½k2‖θ̂ − d‖² + ½k2‖d‖²
    th = 0.5 * k2 * np.sum((thetahat - d) ** 2, axis=1)
    const = 0.5 * k2 * float(d @ d)
    rhs = -quad - th + const  # eq. (38)
    scale = quad + th + const
    if opts.sign != "exact":  # boundary layer: θ̂ᵀ(|χ| − χ∘sgn_ε(χ)) ≥ 0
        slack = np.sum(
            thetahat * (np.abs(chi) - chi * sgn_eps(chi, opts.sign, opts.sign_width)), axis=1
        )
        rhs = rhs + slack
        scale = scale + np.abs(slack)
    gam = float(ctrl.gamma[agent])
    if "sigma" in opts.ghat_law:  # exact σ term of (g/γ) g̃ ĝ̇
        sig = float(ctrl.sigma[agent])
        term = -(g * sig / gam) * (ghat - 1.0 / g) * (ghat - float(ctrl.ghat_ref[agent]))
        rhs = rhs + term
        scale = scale + np.abs(term)
    if gdot is not None and np.any(gdot != 0.0):  # a varying health: ∂V2/∂t of the ĝ term
        term = gdot / (2.0 * gam) * (ghat**2 - 1.0 / np.asarray(g) ** 2)
        rhs = rhs + term
        scale = scale + np.abs(term)
    return rhs, scale


def theorem2_guaranteed(scenario: Scenario, agent: int | None = None) -> tuple[bool, str]:
    """Whether eq. (38) must hold pointwise for this scenario's closed loop, and why not.

    Parameters
    ----------
    scenario : Scenario
        The scenario (its options, health functions and ĝ law).
    agent : int, optional
        0-based follower: also its own conditions (1/g_i inside the projection interval
        over the range of g_i). Another follower's health never enters them.
    """
    o = scenario.options
    if o.ablation:
        return False, "ablation (42): no fault-tolerant factor, V2's adaptive term does not cancel"
    if not o.feedforward:
        return False, "feedforward off: eq. (29) as printed omits b-dot, b-ddot (section 9.2)"
    if o.derivatives != "oracle":
        return False, "filtered derivatives: their error joins the disturbance (section 6)"
    agents = range(scenario.N) if agent is None else (agent,)
    if "projection" in o.ghat_law:
        # P = (g/γ) g̃ (Proj(ρ) − ρ) ≤ 0 needs 1/g_i in [1, 1/g_min] over g_i's range: the band
        # lies outside that interval, so its ends, 1/g = 1 (a healthy follower) included, qualify
        from verify.bounds import _run_health, outside_projection

        for i in agents:
            g_lo, g_hi, _ = _run_health(scenario, i)  # the range of g_i over the run
            for gi in (g_lo, g_hi):
                if why := outside_projection(scenario, i, 1.0 / gi):
                    return False, why + ": the projection may increase dV2/dt"
    return True, "exact feedforward (oracle): must hold up to round-off"


def health_at(scenario: Scenario, agent: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """g_i(t) and ġ_i(t) at the samples (ġ by AD of the health expression; 0 when constant).

    Parameters
    ----------
    scenario : Scenario
    agent : int
        0-based follower.
    t : ndarray
        (K,) times.
    """
    from verify.intervals import _gdot

    h = scenario.followers[agent].g
    t = np.asarray(t, float)
    g = np.broadcast_to(np.asarray(h.expr.numpy(t), float), t.shape).copy()
    if h.expr.is_constant():
        return g, np.zeros_like(t)
    return g, _gdot(h, t)


def check_theorem2(
    cl: Any,
    scenario: Scenario,
    t: np.ndarray,
    X: np.ndarray,
    *,
    ode: ca.Function | None = None,
    config: VerifyConfig | None = None,
) -> list[InequalityCheck]:
    """Eq. (38) at every sample for every follower, with V̇2 exact (AD).

    Parameters
    ----------
    cl : ClosedLoop
    scenario : Scenario
    t, X : ndarray
        (K,) times and (K, nx) states.
    ode : casadi.Function, optional
        Alternative vector field (tests: the printed law χᵀMΨ).
    config : VerifyConfig, optional

    Returns
    -------
    list of InequalityCheck
        One per follower.
    """
    cfg = config or VerifyConfig()
    t = np.asarray(t, float)
    fast = _fast(cl, ode, t, X)
    if fast is None:
        V, Vd = evaluate(lyapunov_derivative(cl, "V2", ode), t, X)
        vals = outputs_at(cl, t, X)
    else:
        V, Vd, chi_all = evaluate_p(fast, "V2", t, X, cl.p0)
        vals = {"chi": chi_all}
    Vd = Vd[:, :, 0]  # (K, N)
    out = []
    for i in range(scenario.N):
        chi = agent_block(vals, "chi", i)
        th = state_block(cl, X, ("thetahat", i))
        gh = state_block(cl, X, ("ghat", i))[:, 0]
        g, gdot = health_at(scenario, i, t)
        rhs, scale = theorem2_rhs(scenario, i, chi, th, gh, g, gdot)
        lhs = Vd[:, i]
        out.append(
            _make(
                "dV2/dt <= -chi'K chi - k2/2|th-d|^2 + k2/2|d|^2 (+slack)",
                i,
                t,
                lhs,
                rhs,
                scale + np.abs(lhs),
                cfg.rtol,
            )
        )
    return out
