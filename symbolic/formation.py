"""Time-varying formation b_i = R(τ_i) b_i0, τ_i = atan2(η̇_i⁽²⁾, η̇_i⁽¹⁾) (docs/reading.md, 'Formation').

Rule where η̇_i is near zero (the paper leaves τ_i undefined there): with
``d = (η̇_i⁽¹⁾, η̇_i⁽²⁾)``, ``r² = ‖d‖²`` and ``ε = options.tau_threshold``,

    b_i = [[c, −s], [s, c]] b_i0 + κ b_i0,   c = d1/√(r²+ε²), s = d2/√(r²+ε²), κ = ε²/(r²+ε²).

Since R(atan2(d2, d1)) = [[d1, −d2], [d2, d1]]/r exactly, this is
``b_i = ρ R(τ_i) b_i0 + κ b_i0`` with ``ρ = r/√(r²+ε²)``: for r ≫ ε it is the
paper's rotation up to a relative O(ε²/r²); at r = 0 it is b_i0 (angle faded to
zero); in between it blends smoothly. It is C∞ in η̇_i, so ḃ_i and b̈_i exist
everywhere (no branch cut, unlike a faded atan2 angle). For n ≠ 2 (or m < 2)
there is no planar rotation and b_i = b_i0 is constant.
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
        Fading threshold ε (``options.tau_threshold``).
    """
    n = b0.numel()
    if n != 2 or etadot.numel() < 2:
        return b0
    d1, d2 = etadot[0], etadot[1]
    g = d1**2 + d2**2 + eps**2
    c, s = d1 / ca.sqrt(g), d2 / ca.sqrt(g)
    kappa = eps**2 / g
    R = ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))  # ρ R(τ_i), τ_i = atan2(d2, d1)
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
        Fading threshold ε (``options.tau_threshold``).

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
