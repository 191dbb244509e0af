"""The matrices of LMIs (15) and (16), for numbers or cvxpy expressions alike.

They are kept apart from :mod:`synthesis.lmi` (which solves the LMIs with cvxpy) so that
:mod:`synthesis.certificate` re-checks gains with numpy alone, without importing cvxpy:
a run whose gains are reused pays no solver import.
"""

from __future__ import annotations

import numpy as np


# --------------------------------------------------------------------------- LMI (15)
def lmi15_matrix(
    A0: np.ndarray, B0: np.ndarray, T: np.ndarray, lb1: float, d1: float
) -> np.ndarray:
    """A0T + TA0ᵀ − λ̄1B0B0ᵀ + δ1T (eq. (15), transposes as the proof needs them).

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    B0 : ndarray
        m×p leader input matrix.
    T : ndarray or cvxpy expression
        m×m symmetric matrix.
    lb1 : float
        λ̄1.
    d1 : float
        δ1.
    """
    return A0 @ T + T @ A0.T - lb1 * (B0 @ B0.T) + d1 * T  # eq. (15)


def lmi15_matrix_P(
    A0: np.ndarray, Q: np.ndarray, P: np.ndarray, lb1: float, d1: float
) -> np.ndarray:
    """PA0 + A0ᵀP − λ̄1QᵀQ + δ1P = T⁻¹(eq. (15))T⁻¹ with P = T⁻¹ and Q = B0ᵀP.

    Parameters
    ----------
    A0 : ndarray
        m×m leader state matrix.
    Q : ndarray
        p×m, Q = B0ᵀP.
    P : ndarray or cvxpy expression
        m×m symmetric, P = T⁻¹.
    lb1 : float or cvxpy expression
        λ̄1.
    d1 : float
        δ1.
    """
    return P @ A0 + A0.T @ P - lb1 * (Q.T @ Q) + d1 * P  # eq. (15), congruent form


# --------------------------------------------------------------------------- LMI (16)
def lmi16_matrix(
    Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, Theta: np.ndarray, Omega: np.ndarray, d2: float
) -> np.ndarray:
    """(ΦA0 − ΘC0)ᵀΩ + Ω(ΦA0 − ΘC0) + δ2Ω (eq. (16)).

    Parameters
    ----------
    Phi : ndarray
        m×m, Φ = I − ΓC0.
    A0 : ndarray
        m×m leader state matrix.
    C0 : ndarray
        n×m leader output matrix.
    Theta : ndarray
        m×n observer gain Θ.
    Omega : ndarray or cvxpy expression
        m×m symmetric Ω.
    d2 : float
        δ2.
    """
    Ac = Phi @ A0 - Theta @ C0
    return Ac.T @ Omega + Omega @ Ac + d2 * Omega  # eq. (16)
