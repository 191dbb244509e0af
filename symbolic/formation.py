"""Time-varying formation b_i = R(τ_i) b_i0, τ_i = atan2(η̇_i⁽²⁾, η̇_i⁽¹⁾) (docs/reading.md, 'Formation').

With ``d = (η̇_i⁽¹⁾, η̇_i⁽²⁾)``, ``s = ‖d‖²``, ``ε = options.tau_threshold`` and
``u = s/ε²``:

    b_i = [[d1 q, −d2 q], [d2 q, d1 q]] b_i0 + κ b_i0,

    q(s) = 1/√s                                   for u ≥ 1,
    q(s) = (1 + w/2 + 3w²/8 + 5w³/16)/ε, w = 1 − u  for u < 1,
    κ(s) = max(1 − u, 0)⁴ (1 + 4u).

Since R(atan2(d2, d1)) = [[d1, −d2], [d2, d1]]/‖d‖, for ‖d‖ ≥ ε this is the paper's
rotation R(τ_i) b_i0 exactly (κ = 0). Below ε the angle is undefined at d = 0 and the
rule blends: the inner q is the third-order Taylor polynomial of 1/√s at s = ε², and
κ = (1 − u)⁴(1 + 4u) (Wendland's C² bump in ‖d‖/ε) has zero first three derivatives at
u = 1 and dκ/du = 0 at u = 0, so b is C³ in d across ‖d‖ = ε
(a polynomial in d inside, smooth outside) and ḃ_i, b̈_i by forward AD are continuous. At
d = 0, b_i = b_i0. For n ≠ 2 (or m < 2) there is no planar rotation and b_i = b_i0.
"""

from __future__ import annotations

import casadi as ca


def formation_offset(etadot: ca.SX, b0: ca.SX, eps: float) -> ca.SX:
    """b_i as a CasADi expression of the agent's own η̇_i and b_i0 (see module docstring).

    Parameters
    ----------
    etadot : casadi.SX
        The agent's estimate η̇_i (m entries; the first two set the angle).
    b0 : casadi.SX
        The formation vector b_i0 (n entries).
    eps : float
        Threshold ε (``options.tau_threshold``): exact rotation for ‖(η̇_i⁽¹⁾, η̇_i⁽²⁾)‖ ≥ ε.
    """
    n = b0.numel()
    if n != 2 or etadot.numel() < 2:
        return b0
    d1, d2 = etadot[0], etadot[1]
    s = d1**2 + d2**2
    w = ca.fmax(1 - s / eps**2, 0)  # 0 outside the disc: both branches stay finite
    q_in = (1 + w / 2 + 3 * w**2 / 8 + 5 * w**3 / 16) / eps  # Taylor of 1/√s at s = ε²
    # floor below ε² so that fmax is never tied where this branch is used (AD of a tie halves)
    q_out = 1 / ca.sqrt(ca.fmax(s, eps**2 / 4))
    q = ca.if_else(s < eps**2, q_in, q_out)
    kappa = w**4 * (5 - 4 * w)  # (1 − u)⁴(1 + 4u): 1 at d = 0, flat at u = 0 and u = 1
    R = ca.vertcat(ca.horzcat(d1 * q, -d2 * q), ca.horzcat(d2 * q, d1 * q))  # R(τ_i) for s ≥ ε²
    return R @ b0 + kappa * b0


def formation_function(m: int, n: int, eps: float) -> ca.Function:
    """b_i and its first two time derivatives from η̇_i, η̈_i, η⃛_i (chain rule by forward AD).

    Parameters
    ----------
    m : int
        Leader state size.
    n : int
        Coordinates per follower.
    eps : float
        Threshold ε (``options.tau_threshold``).

    Returns
    -------
    casadi.Function
        ``(etadot, etaddot, eta3dot, b0) -> (b, bdot, bddot)``.
    """
    e1, e2, e3 = ca.SX.sym("etadot", m), ca.SX.sym("etaddot", m), ca.SX.sym("eta3dot", m)
    b0 = ca.SX.sym("b0", n)
    b = formation_offset(e1, b0, eps)
    bdot = ca.jtimes(b, e1, e2)
    bddot = ca.jtimes(bdot, ca.vertcat(e1, e2), ca.vertcat(e2, e3))
    return ca.Function(
        "formation",
        [e1, e2, e3, b0],
        [b, bdot, bddot],
        ["etadot", "etaddot", "eta3dot", "b0"],
        ["b", "bdot", "bddot"],
    )
