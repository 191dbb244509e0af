"""The unknown-input observer (6)–(8): its error obeys ẽ̇ = (ΦA0 − ΘC0)ẽ for any unknown input."""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.linalg as sla

from symbolic.uio import UIOMatrices, uio_function
from symbolic.uio import uio_matrices as uio_from_gamma_phi
from synthesis.assumptions import uio_matrices as gamma_phi

PAPER = (
    np.array([[0.0, 1.0], [0.0, 0.0]]),
    np.array([[0.0], [1.0]]),
    np.array([[1.0, 1.0], [2.0, 2.0]]),
)
# a 3-state leader with 2 inputs and 3 outputs; Assumption 2 holds (checked below)
THREE = (
    np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -0.5]]),
    np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
    np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]]),
)


def uio_matrices(A0, B0, C0, Theta) -> UIOMatrices:
    """The UIO with eq. (7)'s Γ, Φ (the ones synthesis stores in the gains)."""
    Gamma, Phi = gamma_phi(B0, C0)
    return uio_from_gamma_phi(A0, C0, Gamma, Phi, Theta)


def _theta(A0, B0, C0):
    mats = uio_matrices(A0, B0, C0, np.zeros((A0.shape[0], C0.shape[0])))
    PA = mats.Phi @ A0
    P = sla.solve_continuous_are(PA.T, C0.T, np.eye(A0.shape[0]), np.eye(C0.shape[0]))
    return P @ C0.T


def _simulate(A0, B0, C0, Theta, w, x0, mu0, times):
    """Integrate ẋ = A0x + B0w(t) (the neighbourhood error) and the UIO fed with ψ = C0x."""
    m = A0.shape[0]
    uio = uio_function(uio_matrices(A0, B0, C0, Theta))
    t = ca.SX.sym("t")
    x, mu = ca.SX.sym("x", m), ca.SX.sym("mu", m)
    mudot, _ = uio(mu, ca.DM(C0) @ x)
    ode = ca.vertcat(ca.DM(A0) @ x + ca.DM(B0) @ w(t), mudot)
    I = ca.integrator(
        "I",
        "cvodes",
        {"t": t, "x": ca.vertcat(x, mu), "ode": ode},
        0.0,
        times,
        {"reltol": 1e-11, "abstol": 1e-12, "max_num_steps": 100000},
    )
    X = np.array(I(x0=np.concatenate([x0, mu0]))["xf"])
    return X[:m], X[m:]


def _check(A0, B0, C0, w):
    Theta = _theta(A0, B0, C0)
    mats = uio_matrices(A0, B0, C0, Theta)
    assert np.allclose(mats.Phi @ B0, 0, atol=1e-12)  # Φ B0 = 0 is what removes the input
    assert np.linalg.eigvals(mats.F).real.max() < 0
    rng = np.random.default_rng(3)
    m = A0.shape[0]
    x0, mu0 = rng.normal(size=m), rng.normal(size=m)
    times = np.linspace(0.1, 4.0, 9)
    X, MU = _simulate(A0, B0, C0, Theta, w, x0, mu0, times)
    etilde = MU + mats.Gamma @ C0 @ X - X  # ê − e, eq. (8)
    e0 = mu0 + mats.Gamma @ C0 @ x0 - x0
    exact = np.column_stack([sla.expm(mats.F * tk) @ e0 for tk in times])
    assert np.max(np.abs(etilde - exact)) < 1e-8 * max(1.0, np.abs(e0).max())
    # and the error really is independent of the (large, rough) input: x itself is not small
    assert np.abs(X).max() > 10 * np.abs(etilde).max()


def test_uio_error_is_matrix_exponential_paper_leader():
    _check(*PAPER, lambda t: 25 * ca.sin(7 * t) + 5 * t**2 + 3 * ca.fabs(ca.sin(3 * t)))


def test_uio_error_is_matrix_exponential_three_state_leader():
    A0, B0, C0 = THREE
    # Assumption 2: rank C0B0 = rank B0 = p, and no unstable invariant zeros
    assert np.linalg.matrix_rank(C0 @ B0) == np.linalg.matrix_rank(B0) == B0.shape[1]
    _check(A0, B0, C0, lambda t: ca.vertcat(30 * ca.cos(5 * t), 12 * ca.exp(0.3 * t)))


def test_literal_signs_do_not_remove_the_input():
    """The printed signs taken literally (Φ = I + ΓC0 with the positive Γ) leave B0 in the error.

    This is why the signs are reconstructed (docs/fidelity.md, D1).
    """
    A0, B0, C0 = PAPER
    mats = uio_matrices(A0, B0, C0, _theta(A0, B0, C0))
    Phi_literal = np.eye(2) + mats.Gamma @ C0
    assert np.abs(Phi_literal @ B0).max() > 0.5
    # the paper's own sign convention (Γ' = −Γ, Φ = I + Γ'C0) is the same observer
    assert np.allclose(np.eye(2) + (-mats.Gamma) @ C0, mats.Phi)


def test_unobservable_mode_of_paper_leader():
    """For C0 = [[1,1],[2,2]] the mode at −1 of ΦA0 cannot be moved by any Θ (docs/reading.md, 'Unknown-input observer')."""
    A0, B0, C0 = PAPER
    rng = np.random.default_rng(0)
    for _ in range(5):
        Theta = rng.normal(size=(2, 2))
        ev = np.linalg.eigvals(uio_matrices(A0, B0, C0, Theta).F)
        assert np.min(np.abs(ev + 1.0)) < 1e-9
