"""Fault-tolerant controller: tracking error and sliding variable (28), control law (29), ablation (42).

An optional actuator limit (:func:`saturate`) clips the torque the follower receives.

The controller of follower i sees its own p_i, q_i, its observer's η_i, η̇_i,
η̈_i, the formation offset b_i (and ḃ_i, b̈_i) and its adaptive states; it never
sees the actuator health g_i or the bias f_i.
"""

from __future__ import annotations

import casadi as ca

from core.models.base import ELModel


def sign_function(x: ca.SX, mode: str, width: float) -> ca.SX:
    """sgn(x) element-wise: ``exact``, ``sat`` (sat(x/ε)) or ``tanh`` (tanh(x/ε)), ε = width.

    The boundary layers (docs/fidelity.md, D5) make the right-hand side Lipschitz for
    variable-step integrators; ``exact`` is the paper's sign function.

    Parameters
    ----------
    x : casadi.SX
        Argument.
    mode : {"exact", "sat", "tanh"}
        ``options.sign``.
    width : float
        Boundary-layer width ε (unused for ``exact``).
    """
    if mode == "exact":
        return ca.sign(x)
    if mode == "sat":
        return ca.fmin(ca.fmax(x / width, -1.0), 1.0)
    if mode == "tanh":
        return ca.tanh(x / width)
    raise ValueError(f"unknown sign mode {mode!r}")


def saturate(u: ca.SX, u_max: ca.SX) -> ca.SX:
    """The applied torque sat(u) = min(max(u, −u_max), u_max), component-wise.

    A hard clip: exactly u below the limit, exactly ±u_max beyond it. It is
    Lipschitz (constant 1), so the closed loop keeps unique solutions; its
    Jacobian jumps where a component meets the limit, which costs a variable-step
    integrator a few rejected steps there (docs/fidelity.md, actuator saturation).

    Parameters
    ----------
    u : casadi.SX
        The torque of the control law (29) (or (42)).
    u_max : casadi.SX
        The limit u_max_i > 0 (a scalar, applied to every component).
    """
    return ca.fmin(ca.fmax(u, -u_max), u_max)


def controller_function(
    model: ELModel, C0, *, sign: str, sign_width: float, ablation: bool
) -> ca.Function:
    """One follower's controller as a Function.

    Inputs ``p, q, eta, etadot, etaddot, b, bdot, bddot, thetahat, ghat, Lambda, k1``
    (Lambda and k1 are the diagonals of Λ_i and K_i). Outputs ``et``, ``etdot``,
    ``chi``, ``Psi`` and ``u``. With feedforward off the caller passes ḃ = b̈ = 0,
    which is eq. (29) exactly as printed.

    Parameters
    ----------
    model : ELModel
        The follower's Euler–Lagrange model (M, C, G).
    C0 : ndarray
        n×m leader output matrix.
    sign : {"exact", "sat", "tanh"}
        Sign function in Ψ_i (:func:`sign_function`).
    sign_width : float
        Its boundary-layer width ε.
    ablation : bool
        True for eq. (42), u = Ψ (no ĝ factor).
    """
    n = model.n
    m = C0.shape[1]
    C0 = ca.DM(C0)
    p, q = ca.SX.sym("p", n), ca.SX.sym("q", n)
    eta, etadot, etaddot = (ca.SX.sym(s, m) for s in ("eta", "etadot", "etaddot"))
    b, bdot, bddot = (ca.SX.sym(s, n) for s in ("b", "bdot", "bddot"))
    thetahat, ghat = ca.SX.sym("thetahat", n), ca.SX.sym("ghat")
    Lam, k1 = ca.SX.sym("Lambda", n), ca.SX.sym("k1", n)
    M, Cm, G = model.M(p), model.C(p, q), model.forces(p, q)  # G, and D with dissipation
    et = p - C0 @ eta - b  # eq. (28)
    etdot = q - C0 @ etadot - bdot  # eq. (28)
    chi = etdot + Lam * et  # eq. (28): χ_si = ė_ti + Λ_i e_ti
    Psi = (
        Cm @ q
        + G
        + M @ (C0 @ etaddot + bddot - Lam * etdot)
        - Cm @ chi
        - thetahat * sign_function(chi, sign, sign_width)
        - k1 * chi
    )  # eq. (29): Ψ_i
    u = Psi if ablation else ghat * Psi  # eq. (42) ablation: u = Ψ; eq. (29): u = ĝ Ψ
    return ca.Function(
        "controller",
        [p, q, eta, etadot, etaddot, b, bdot, bddot, thetahat, ghat, Lam, k1],
        [et, etdot, chi, Psi, u],
        [
            "p",
            "q",
            "eta",
            "etadot",
            "etaddot",
            "b",
            "bdot",
            "bddot",
            "thetahat",
            "ghat",
            "Lambda",
            "k1",
        ],
        ["et", "etdot", "chi", "Psi", "u"],
    )
