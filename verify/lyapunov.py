"""Exact Lyapunov derivatives by automatic differentiation, and the pointwise checks.

V̇ = ∂V/∂x · f(t, x) + ∂V/∂t is built symbolically from the closed loop's
``outputs`` (V1, V2) and ``ode`` functions with CasADi (``jtimes`` and
``jacobian``); it is then evaluated at the stored states. No sampled data is
ever differenced here (the test suite differences V only to cross-check).

Theorem 1 (eq. (27)): V̇1 ≤ −δ̃ V1; with the φ floor φ_min > 0, V̇1 ≤ −δ̃ V1 + c_φ.
Theorem 2 (eqs. (36)–(38)): per follower,
V̇2i ≤ −χᵀKχ − ½k2‖θ̂ − d‖² + ½k2‖d‖² (+ Σ_r θ̂_r(|χ_r| − χ_r sgn_ε(χ_r)) with a boundary
layer; + the σ-modification's exact term −(gσ/γ)(ĝ − 1/g)(ĝ − ĝ0) when that law is on).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from core.scenario import Scenario
from verify.bounds import VerifyConfig, VerifyError


@dataclass(frozen=True)
class InequalityCheck:
    """A pointwise inequality lhs ≤ rhs evaluated at every output time.

    Attributes
    ----------
    claim : str
        What was checked.
    agent : int | None
        0-based follower, or None for a network-wide function.
    t, lhs, rhs : ndarray
        Times and both sides.
    holds : ndarray of bool
        lhs ≤ rhs + rtol·scale at each time.
    fraction : float
        Share of output times where it holds.
    worst : float
        max(lhs − rhs) (≤ 0 when it holds everywhere).
    t_worst : float
        Time of ``worst``.
    """

    claim: str
    agent: int | None
    t: np.ndarray
    lhs: np.ndarray
    rhs: np.ndarray
    holds: np.ndarray
    fraction: float
    worst: float
    t_worst: float

    @property
    def ok(self) -> bool:
        return bool(self.holds.all())

    def where(self) -> str:
        """One line saying where the inequality fails worst (or that it does not)."""
        who = "network" if self.agent is None else f"follower {self.agent + 1}"
        if self.ok:
            return f"{self.claim} holds for {who} at all {len(self.t)} output times"
        k = int(np.argmax(self.lhs - self.rhs))
        return (
            f"{self.claim} fails for {who}: worst at t = {self.t_worst:.4g} s, "
            f"lhs = {self.lhs[k]:.6g} > rhs = {self.rhs[k]:.6g}; holds at {100 * self.fraction:.1f}% "
            "of output times"
        )


def _make(claim, agent, t, lhs, rhs, scale, rtol) -> InequalityCheck:  # noqa: ANN001
    gap = lhs - rhs
    holds = gap <= rtol * scale
    k = int(np.argmax(gap))
    return InequalityCheck(
        claim=claim,
        agent=agent,
        t=t,
        lhs=lhs,
        rhs=rhs,
        holds=holds,
        fraction=float(holds.mean()) if len(holds) else 1.0,
        worst=float(gap[k]),
        t_worst=float(t[k]),
    )


def output_names(cl: Any) -> list[str]:
    """Names of the closed loop's outputs.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    """
    return list(cl.outputs.name_out())


def symbolic_outputs(cl: Any, t: Any, x: Any) -> dict[str, Any]:
    """Call ``cl.outputs`` on symbols and return {name: expression}.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    t : casadi.SX or MX
        Time symbol.
    x : casadi.SX or MX
        State symbol (nx entries).
    """
    res = cl.outputs.call([t, x])
    return dict(zip(cl.outputs.name_out(), res, strict=True))


def lyapunov_derivative(cl: Any, name: str, ode: ca.Function | None = None) -> ca.Function:
    """``(t, x) -> (V, V̇)`` with V̇ = ∂V/∂x f(t, x) + ∂V/∂t exact (AD).

    Parameters
    ----------
    cl : ClosedLoop
        Provides ``outputs`` (with output ``name``) and ``ode``.
    name : str
        Output holding V (scalar V1 or the N-vector V2).
    ode : casadi.Function, optional
        A different vector field (e.g. a deliberately wrong adaptive law).

    Returns
    -------
    casadi.Function
    """
    f = ode if ode is not None else cl.ode
    t = ca.MX.sym("t")
    x = ca.MX.sym("x", cl.layout.nx)
    outs = symbolic_outputs(cl, t, x)
    if name not in outs:
        raise VerifyError(
            f"closed loop has no output {name!r} (outputs: {', '.join(outs)}); update verify"
        )
    V = ca.vec(outs[name])  # V1 (1×1) or V2 (N×1)
    xdot = f.call([t, x])[0]
    # eq. (18)–(26) (V̇1) and eq. (33)–(35) (V̇2) are derived in the paper by hand; here the
    # derivative along the flow is exact: ∂V/∂x · f + ∂V/∂t
    Vdot = ca.jtimes(V, x, xdot) + ca.jacobian(V, t)
    return ca.Function(f"{name}_dot", [t, x], [V, Vdot], ["t", "x"], [name, f"{name}_dot"])


def evaluate(fun: ca.Function, t: np.ndarray, X: np.ndarray) -> list[np.ndarray]:
    """Evaluate a ``(t, x) -> ...`` function at K samples; X is (K, nx).

    Parameters
    ----------
    fun : casadi.Function
        A Function of ``(t, x)``.
    t : ndarray
        K sample times.
    X : ndarray
        (K, nx) states at those times.

    Returns
    -------
    list of ndarray
        One (K, rows, cols) array per output.
    """
    K = len(t)
    res = fun.map(K)(np.asarray(t, dtype=float).reshape(1, K), np.asarray(X, dtype=float).T)
    res = res if isinstance(res, tuple | list) else [res]
    out = []
    for j, r in enumerate(res):
        rows, cols = fun.size_out(j)
        a = np.asarray(ca.DM(r).full(), dtype=float)  # rows × (cols·K), sample k in block k
        out.append(a.reshape(rows, K, cols).transpose(1, 0, 2))
    return out


def outputs_at(cl: Any, t: np.ndarray, X: np.ndarray) -> dict[str, np.ndarray]:
    """All outputs at K samples: {name: (K, rows, cols)}; per-agent outputs have row i = agent i.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    t : ndarray
        K sample times.
    X : ndarray
        (K, nx) states at those times.
    """
    vals = evaluate(cl.outputs, t, X)
    return dict(zip(cl.outputs.name_out(), vals, strict=True))


def agent_block(vals: dict[str, np.ndarray], name: str, agent: int) -> np.ndarray:
    """Agent ``agent``'s row of a per-agent output: (K, cols).

    Parameters
    ----------
    vals : dict
        Outputs as returned by :func:`outputs_at`.
    name : str
        Output name.
    agent : int
        0-based follower index.
    """
    if name not in vals:
        raise VerifyError(f"closed loop has no output {name!r}; update verify")
    return vals[name][:, agent, :]


def state_block(cl: Any, X: np.ndarray, key: Any) -> np.ndarray:
    """Columns of the state for layout key ``key``: (K, width).

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    X : ndarray
        (K, nx) states.
    key : str or tuple
        Layout key: ``"eta0"`` or ``(name, agent)``.
    """
    if key not in cl.layout.slices:
        raise VerifyError(f"closed loop layout has no state {key!r}")
    return X[:, cl.layout.slices[key]]


# --------------------------------------------------------------------------- Theorem 1
def check_theorem1(
    cl: Any,
    t: np.ndarray,
    X: np.ndarray,
    rate: float,
    *,
    claim: str = "dV1/dt <= -delta V1",
    config: VerifyConfig | None = None,
    offset: float = 0.0,
    ode: ca.Function | None = None,
) -> InequalityCheck:
    """V̇1 ≤ −δ̃ V1 + c (eq. (27) when c = 0) at every sample, with V̇1 exact.

    With the φ floor the proof gives c = c_φ (:func:`verify.bounds.theorem1_floor`,
    derivation in docs/verification.md).

    Parameters
    ----------
    cl : ClosedLoop
    t : ndarray
        (K,) times.
    X : ndarray
        (K, nx) states.
    rate : float
        δ̃ to check.
    claim : str
        Label.
    config : VerifyConfig, optional
    offset : float
        c ≥ 0 added to the right side (the φ floor's constant c_φ).
    ode : casadi.Function, optional
        A different vector field (tests: a deliberately wrong observer).

    Returns
    -------
    InequalityCheck
    """
    cfg = config or VerifyConfig()
    V, Vd = evaluate(lyapunov_derivative(cl, "V1", ode), t, X)
    V, Vd = V[:, 0, 0], Vd[:, 0, 0]
    rhs = -rate * V + offset  # eq. (27); + c_φ with the φ floor
    scale = np.abs(Vd) + rate * np.abs(V) + abs(offset) + 1e-300
    return _make(claim, None, np.asarray(t, float), Vd, rhs, scale, cfg.rtol)


# --------------------------------------------------------------------------- Theorem 2
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
    g: float,
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
    g : float
        Actuator health (constant).

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
    if "sigma" in opts.ghat_law:  # exact σ term of (g/γ) g̃ ĝ̇
        sig, gam = float(ctrl.sigma[agent]), float(ctrl.gamma[agent])
        term = -(g * sig / gam) * (ghat - 1.0 / g) * (ghat - float(ctrl.ghat_ref[agent]))
        rhs = rhs + term
        scale = scale + np.abs(term)
    return rhs, scale


def theorem2_guaranteed(scenario: Scenario) -> tuple[bool, str]:
    """Whether eq. (38) must hold pointwise for this scenario's closed loop, and why not.

    Parameters
    ----------
    scenario : Scenario
        The scenario (its options, health functions and ĝ law).
    """
    o = scenario.options
    if o.ablation:
        return False, "ablation (42): no fault-tolerant factor, V2's adaptive term does not cancel"
    if not o.feedforward:
        return False, "feedforward off: eq. (29) as printed omits b-dot, b-ddot (section 9.2)"
    if o.derivatives != "oracle":
        return False, "filtered derivatives: their error joins the disturbance (section 6)"
    if scenario.followers and any(fo.g.breakpoints for fo in scenario.followers):
        return False, "time-varying health g_i(t): V2's weight g/(2 gamma) changes in time"
    if "projection" in o.ghat_law:
        from symbolic.adaptive import BAND

        hi = 1.0 / scenario.controller.g_min
        band = BAND * (hi - 1.0)
        for i, fo in enumerate(scenario.followers):
            if not 1.0 + band <= 1.0 / fo.g.minimum <= hi - band:
                return False, (
                    f"1/g_{i + 1} = {1 / fo.g.minimum:.4g} outside the projection interval "
                    f"[{1 + band:.4g}, {hi - band:.4g}]: the projection may increase dV2/dt"
                )
    return True, "exact feedforward (oracle): must hold up to round-off"


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
    V, Vd = evaluate(lyapunov_derivative(cl, "V2", ode), t, X)
    Vd = Vd[:, :, 0]  # (K, N)
    vals = outputs_at(cl, t, X)
    out = []
    for i in range(scenario.N):
        chi = agent_block(vals, "chi", i)
        th = state_block(cl, X, ("thetahat", i))
        gh = state_block(cl, X, ("ghat", i))[:, 0]
        g = float(scenario.followers[i].g.minimum)
        rhs, scale = theorem2_rhs(scenario, i, chi, th, gh, g)
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
