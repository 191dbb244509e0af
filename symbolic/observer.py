"""Distributed observer of the leader, eq. (9), with the UIO (6)–(8) inside (docs/reading.md, 'Distributed observer').

One agent's observer state is ``s_o = (μ_i, η_i, φ_i)`` (2m + 1 entries). Its flow
depends only on ``s_o`` and on the measured neighbourhood output ψ_i, never on
the follower's physical state; this is what lets the oracle derivatives
(:mod:`symbolic.derivatives`) differentiate it along the observer network.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from symbolic.uio import UIOMatrices, uio_function


@dataclass(frozen=True)
class ObserverGains:
    """Gains of eq. (9) shared by all agents.

    Attributes
    ----------
    A0, B0 : ndarray
        Leader matrices.
    Q : ndarray
        p×m, ``Q = B0ᵀT⁻¹``.
    lambda1, lambda2 : float
        Linear and unit-vector gains of v_i.
    uio : UIOMatrices
        The UIO of eqs. (6)–(8).
    """

    A0: np.ndarray
    B0: np.ndarray
    Q: np.ndarray
    lambda1: float
    lambda2: float
    uio: UIOMatrices


def safe_norm(y: ca.SX) -> ca.SX:
    """‖y‖ with derivatives that are finite (zero) at y = 0.

    For one component this is |y| (derivative sign y); otherwise the square
    root is taken only where ‖y‖² > 0, so forward-mode AD never forms 0/0.

    Parameters
    ----------
    y : casadi.SX
        Vector.
    """
    if y.numel() == 1:
        return ca.fabs(y)
    s2 = ca.sumsqr(y)
    return ca.if_else(s2 > 0, ca.sqrt(ca.if_else(s2 > 0, s2, 1.0)), 0.0)


def observer_function(g: ObserverGains) -> ca.Function:
    """One agent's observer flow as a Function.

    Inputs ``so`` (μ_i, η_i, φ_i), ``psi`` (n) and ``prm`` = (α1i + ᾱ1i, φ_min).
    Outputs ``sodot`` (μ̇_i, η̇_i, φ̇_i), ``v`` (p) and ``ehat`` (m).

    Parameters
    ----------
    g : ObserverGains
        Gains of eq. (9) and the UIO matrices.
    """
    m = g.A0.shape[0]
    n = g.uio.Gamma.shape[1]
    so = ca.SX.sym("so", 2 * m + 1)
    psi = ca.SX.sym("psi", n)
    prm = ca.SX.sym("prm", 2)
    mu, eta, phi = so[:m], so[m : 2 * m], so[2 * m]
    alpha_sum, phi_min = prm[0], prm[1]
    mudot, ehat = uio_function(g.uio)(mu, psi)  # eq. (7)
    Qe = ca.DM(g.Q) @ ehat
    v = -g.lambda1 * Qe - g.lambda2 * Qe / (safe_norm(Qe) + phi)  # eq. (9)
    etadot = ca.DM(g.A0) @ eta + ca.DM(g.B0) @ v  # eq. (9)
    # eq. (9): φ̇ = −(α1 + ᾱ1)φ; with the floor φ_min (0 = the paper's law) it decays to φ_min
    phidot = -alpha_sum * (phi - phi_min)
    return ca.Function(
        "observer",
        [so, psi, prm],
        [ca.vertcat(mudot, etadot, phidot), v, ehat],
        ["so", "psi", "prm"],
        ["sodot", "v", "ehat"],
    )
