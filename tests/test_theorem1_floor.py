"""Theorem 1 with the φ floor: V̇1 ≤ −δ̃V1 + c_φ (docs/verification.md, "Theorem 1 with the φ floor").

A stretch of the paper's closed loop with a φ floor is integrated with CVODES on the
symbolic model. Independent truths: the floor's constant c_φ equals the measured excess
of d/dt(φ term of V1) over its floor-free value (central finite differences of the
integrated φ_i, hand-computed l̄_ii from the adjacency); the inequality holds along the
real flow, the floor-free one (c_φ = 0) does not, and an observer without the robust
term λ2 (which the proof needs to dominate the operator's input u0) violates it.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from helpers import integrate, paper_loop

from verify.bounds import theorem1_floor, theorem1_rates
from verify.lyapunov import check_theorem1

PHI_MIN = 0.05  # larger than the shipped 0.005 so the floor dominates within a few seconds
FLOOR = {
    "initial.start": "formation",
    "initial.eta": [0.0, 1.0],
    "leader.eta0": [0.0, 1.0],
    "integration.horizon": 4.0,
    "observer.phi_min": PHI_MIN,
}
H = 1e-5  # finite-difference half step (test only)


@pytest.fixture(scope="module")
def floor_loop(tmp_path_factory):
    sc, gains, cl = paper_loop(FLOOR, "test-t1-floor", tmp_path_factory.mktemp("out"))
    base = np.linspace(0.0, 4.0, 81)
    grid = np.unique(np.concatenate([base, base[1:-1] - H, base[1:-1] + H]))
    opts = {"abstol": 1e-11, "reltol": 1e-11, "max_num_steps": 400000}
    X = integrate(cl, grid, opts)
    return sc, gains, cl, grid, X


def _phi(cl, sc, X):
    return np.column_stack([X[:, cl.layout.slices[("phi", i)]][:, 0] for i in range(sc.N)])


def test_c_phi_equals_the_floor_excess_of_the_phi_term(floor_loop):
    """c_φ = d/dt(2λ2 Σ l̄z φ/ᾱ) − (floor-free value −2λ2 Σ l̄z(α1+ᾱ1)φ/ᾱ), by finite differences."""
    sc, gains, cl, grid, X = floor_loop
    o = sc.observer
    A = np.abs(np.asarray(sc.graph.adjacency, float))
    lbar = A.sum(axis=1) + np.asarray(sc.graph.pinning, float)  # l̄_ii by hand
    np.testing.assert_array_equal(lbar, [1.0, 1.0, 1.0, 2.0, 1.0])  # the paper's graph
    z = np.diag(gains.Z)
    a1, a1b = np.asarray(o.alpha1, float), np.asarray(o.alpha1_bar, float)
    w = 2.0 * gains.lambda2 * lbar * z / a1b
    phi = _phi(cl, sc, X)
    fl = theorem1_floor(sc, gains)
    for tc in (0.5, 1.0, 2.0, 3.5):
        k = int(np.argmin(np.abs(grid - tc)))
        kp, km = int(np.argmin(np.abs(grid - tc - H))), int(np.argmin(np.abs(grid - tc + H)))
        fd = (w @ phi[kp] - w @ phi[km]) / (grid[kp] - grid[km])
        floor_free = -np.sum(w * (a1 + a1b) * phi[k])  # the paper's law φ̇ = −(α1 + ᾱ1)φ
        assert fd - floor_free == pytest.approx(fl.c_phi, rel=1e-5)
    # and the closed form: 2λ2 φ_min Σ l̄ z (α1 + ᾱ1)/ᾱ1
    assert fl.c_phi == pytest.approx(PHI_MIN * np.sum(w * (a1 + a1b)), rel=1e-12)


def test_floor_inequality_holds_and_floor_free_fails(floor_loop):
    sc, gains, cl, grid, X = floor_loop
    fl = theorem1_floor(sc, gains)
    assert fl.rate == theorem1_rates(sc, gains).supported
    chk = check_theorem1(cl, grid, X, fl.rate, offset=fl.c_phi)
    assert chk.ok, chk.where()
    bare = check_theorem1(cl, grid, X, fl.rate)  # c_φ left out: the proof's last step
    assert not bare.ok, "with phi_min > 0 the floor-free inequality should fail near the floor"
    assert bare.t_worst > 1.0  # where φ has reached its floor, not at the start


def _without_robust_term(sc, gains, cl):
    """The same loop with v_i = −λ1 Q ê_i only: λ2 ≥ ‖u0‖ is what the proof needs."""
    t, x = ca.MX.sym("t"), ca.MX.sym("x", cl.layout.nx)
    xdot = cl.ode(t, x)
    outs = dict(zip(cl.outputs.name_out(), cl.outputs(t, x), strict=True))
    Q, B0 = ca.DM(np.atleast_2d(gains.Q)), ca.DM(np.atleast_2d(gains.B0))
    parts, pos = [], 0
    for i in range(sc.N):
        sl = cl.layout.slices[("eta", i)]
        parts.append(xdot[pos : sl.start])
        Qe = ca.mtimes(Q, outs["ehat"][i, :].T)
        robust = gains.lambda2 * Qe / (ca.norm_2(Qe) + outs["phi"][i, 0])
        parts.append(xdot[sl] + ca.mtimes(B0, robust))  # remove −λ2 B0 Qê/(‖Qê‖ + φ)
        pos = sl.stop
    parts.append(xdot[pos:])
    return ca.Function("ode_no_robust", [t, x], [ca.vertcat(*parts)])


def test_observer_without_robust_term_violates_the_floor_inequality(floor_loop):
    sc, gains, cl, grid, X = floor_loop
    fl = theorem1_floor(sc, gains)
    chk = check_theorem1(
        cl, grid, X, fl.rate, offset=fl.c_phi, ode=_without_robust_term(sc, gains, cl)
    )
    assert not chk.ok, "without lambda2 the input u0 is not dominated: the inequality must fail"
    assert "fails for network" in chk.where()
