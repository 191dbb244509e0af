"""Unknown-input observer of the neighbourhood error, eqs. (6)–(8) (docs/reading.md, 'Unknown-input observer').

Sign reconstruction (the extraction lost the minus signs; see docs/closed-loop.md):
``Γ = B0[(C0B0)ᵀ(C0B0)]⁻¹(C0B0)ᵀ``, ``Φ = I − ΓC0`` (so ``ΦB0 = 0``),
``μ̇ = (ΦA0 − ΘC0) μ + [Θ(I − C0Γ) + ΦA0Γ] ψ``, ``ê = μ + Γψ``; then the error
``ẽ = ê − e_η`` obeys ``ẽ̇ = (ΦA0 − ΘC0) ẽ`` for any unknown input.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from synthesis.gains import Gains


@dataclass(frozen=True)
class UIOMatrices:
    """Constant matrices of the UIO.

    Attributes
    ----------
    Gamma, Phi : ndarray
        m×n and m×m, eq. (7).
    F : ndarray
        m×m error matrix ``ΦA0 − ΘC0`` (Hurwitz by LMI (16)).
    K : ndarray
        m×n input matrix of ψ, ``Θ(I − C0Γ) + ΦA0Γ``.
    """

    Gamma: np.ndarray
    Phi: np.ndarray
    F: np.ndarray
    K: np.ndarray


def uio_matrices(
    A0: np.ndarray, C0: np.ndarray, Gamma: np.ndarray, Phi: np.ndarray, Theta: np.ndarray
) -> UIOMatrices:
    """The two system matrices of the UIO, eqs. (7)–(8), from Γ, Φ and Θ.

    Parameters
    ----------
    A0, C0 : ndarray
        Leader matrices (m×m, n×m).
    Gamma, Phi : ndarray
        m×n and m×m, eq. (7) (``Φ B0 = 0``; synthesis computes and certifies them).
    Theta : ndarray
        m×n observer gain.
    """
    A0, C0, Gamma, Phi, Theta = (
        np.atleast_2d(np.asarray(a, dtype=float)) for a in (A0, C0, Gamma, Phi, Theta)
    )
    F = Phi @ A0 - Theta @ C0  # eq. (8)
    K = Theta @ (np.eye(C0.shape[0]) - C0 @ Gamma) + Phi @ A0 @ Gamma  # eq. (7)
    return UIOMatrices(Gamma=Gamma, Phi=Phi, F=F, K=K)


def uio_of(gains: Gains) -> UIOMatrices:
    """The UIO of the certified gains: their A0, C0, Γ, Φ and Θ (nothing recomputed).

    Parameters
    ----------
    gains : Gains
        Synthesised (or hand-made) gains.
    """
    return uio_matrices(gains.A0, gains.C0, gains.Gamma, gains.Phi, gains.Theta)


def uio_function(mats: UIOMatrices) -> ca.Function:
    """One agent's UIO as a Function ``(mu, psi) -> (mudot, ehat)``, eq. (7).

    Parameters
    ----------
    mats : UIOMatrices
        Γ, F = ΦA0 − ΘC0 and K from :func:`uio_matrices`.
    """
    m, n = mats.Gamma.shape
    mu = ca.SX.sym("mu", m)
    psi = ca.SX.sym("psi", n)
    mudot = ca.DM(mats.F) @ mu + ca.DM(mats.K) @ psi  # eq. (7)
    ehat = mu + ca.DM(mats.Gamma) @ psi  # eq. (7)
    return ca.Function("uio", [mu, psi], [mudot, ehat], ["mu", "psi"], ["mudot", "ehat"])
