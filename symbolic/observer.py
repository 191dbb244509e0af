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


def _gain_matrices(g: ObserverGains) -> list[ca.DM]:
    """Q, then the UIO's F, K and Γ, each with its structural zeros dropped."""
    return [ca.sparsify(ca.DM(np.atleast_2d(M))) for M in (g.Q, g.uio.F, g.uio.K, g.uio.Gamma)]


def gain_values(g: ObserverGains) -> np.ndarray:
    """The gains a parametric observer reads from its ``prm`` after (α1i + ᾱ1i, φ_min).

    λ1, λ2, then the nonzeros of Q, F = ΦA0 − ΘC0, K and Γ (column-major): the observer
    of eqs. (7), (9) with these as runtime numbers and only their patterns as structure
    (:func:`gain_pattern`).

    Parameters
    ----------
    g : ObserverGains
    """
    nz = [np.asarray(M.nonzeros(), float) for M in _gain_matrices(g)]
    return np.concatenate([[g.lambda1, g.lambda2], *nz])


def gain_pattern(g: ObserverGains) -> list[list[int]]:
    """Where Q, F, K and Γ are nonzero (what a parametric observer compiles in).

    Parameters
    ----------
    g : ObserverGains
    """
    return [
        np.asarray(ca.DM(M.sparsity(), 1)).astype(int).ravel().tolist() for M in _gain_matrices(g)
    ]


def observer_function(g: ObserverGains, parametric: bool = False) -> ca.Function:
    """One agent's observer flow as a Function.

    Inputs ``so`` (μ_i, η_i, φ_i), ``psi`` (n) and ``prm`` = (α1i + ᾱ1i, φ_min), followed
    when ``parametric`` by :func:`gain_values` (the gains then runtime numbers on the
    patterns of ``g``'s). Outputs ``sodot`` (μ̇_i, η̇_i, φ̇_i), ``v`` (p) and ``ehat`` (m).

    Parameters
    ----------
    g : ObserverGains
        Gains of eq. (9) and the UIO matrices (their values, or only their patterns).
    parametric : bool
        Read the gains from ``prm`` instead of writing them into the code.
    """
    m = g.A0.shape[0]
    n = g.uio.Gamma.shape[1]
    so = ca.SX.sym("so", 2 * m + 1)
    psi = ca.SX.sym("psi", n)
    mats = _gain_matrices(g) if parametric else []
    prm = ca.SX.sym("prm", 2 + (2 + sum(M.nnz() for M in mats) if parametric else 0))
    mu, eta, phi = so[:m], so[m : 2 * m], so[2 * m]
    alpha_sum, phi_min = prm[0], prm[1]
    if parametric:
        lam1, lam2, k, sym = prm[2], prm[3], 4, []
        for M in mats:
            sym.append(ca.SX(M.sparsity(), prm[k : k + M.nnz()]))
            k += M.nnz()
        Q, F, K, Gam = sym
        mudot, ehat = F @ mu + K @ psi, mu + Gam @ psi  # eq. (7)
    else:
        lam1, lam2, Q = g.lambda1, g.lambda2, ca.DM(g.Q)
        mudot, ehat = uio_function(g.uio)(mu, psi)  # eq. (7)
    Qe = Q @ ehat
    v = -lam1 * Qe - lam2 * Qe / (safe_norm(Qe) + phi)  # eq. (9)
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
