"""Follower model library: derived M, C, G against closed forms; Properties 1 and 2."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from helpers import TWO_LINK_PAPER as PAPER
from helpers import two_link_closed_form

from core.errors import ScenarioError
from core.models import REGISTRY, ModelSpec, build_model, register
from core.models.derive import check_properties, euler_lagrange_matrices


@pytest.mark.parametrize(
    "params",
    [PAPER, {"m1": 1.3, "m2": 0.7, "r1": 0.6, "r2": 1.1, "J1": 0.2, "J2": 2.5, "g0": 3.0}],
)
def test_two_link_matches_closed_forms(params):
    mdl = build_model("two_link", params)
    rng = np.random.default_rng(7)
    for _ in range(50):
        p = rng.uniform(-4, 4, 2)
        q = rng.uniform(-3, 3, 2)
        M, C, G = two_link_closed_form(p, q, **params)
        np.testing.assert_allclose(np.array(mdl.M(p)), M, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.array(mdl.C(p, q)), C, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.array(mdl.G(p)).ravel(), G, rtol=1e-12, atol=1e-12)


def test_two_link_mass_bounds():
    lo, hi = build_model("two_link").M_bounds
    # independent: M depends on cos p2 only; eigenvalues of the closed form over c in [-1, 1]
    evs = [
        np.linalg.eigvalsh(two_link_closed_form([0.0, x], [0, 0], **PAPER)[0])
        for x in np.linspace(0, np.pi, 20001)
    ]
    assert lo == pytest.approx(min(e[0] for e in evs), rel=1e-9)
    assert hi == pytest.approx(max(e[-1] for e in evs), rel=1e-9)
    assert lo == pytest.approx(5.08, abs=0.01) and hi == pytest.approx(11.24, abs=0.01)


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_properties_symbolically(name):
    """Property 1: M = Mᵀ ≻ 0 (leading minors); Property 2: Ṁ − 2C simplifies to exactly skew."""
    mdl = build_model(name)
    M, C, p, q = mdl.sympy_M, mdl.sympy_C, mdl.sympy_p, mdl.sympy_q
    n = mdl.n
    assert sp.simplify(M - M.T).is_zero_matrix
    Mdot = sp.Matrix(n, n, lambda i, j: sum(sp.diff(M[i, j], p[k]) * q[k] for k in range(n)))
    S = Mdot - 2 * C
    assert sp.simplify(S + S.T).is_zero_matrix  # exactly zero, not numerically small
    assert (mdl.checks["property1"], mdl.checks["property2"]) == ("exact", "exact")
    # a Rayleigh function R adds D = ∂R/∂q and its check; nothing else
    assert set(mdl.checks) == {"property1", "property2"} | (
        {"dissipation"} if mdl.D is not None else set()
    )
    # numerically too: xᵀ(Ṁ − 2C)x = 0 and λ_min(M) within M_bounds at random states
    rng = np.random.default_rng(3)
    for _ in range(20):
        pv, qv, x = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.normal(size=n)
        Mv = np.array(mdl.M(pv))
        ev = np.linalg.eigvalsh(Mv)
        assert mdl.M_bounds[0] - 1e-9 <= ev[0] and ev[-1] <= mdl.M_bounds[1] + 1e-9
        eps = 1e-6  # Ṁ along q by central differences of the CasADi M (independent of sympy)
        Mdot_v = (np.array(mdl.M(pv + eps * qv)) - np.array(mdl.M(pv - eps * qv))) / (2 * eps)
        Sv = Mdot_v - 2 * np.array(mdl.C(pv, qv))
        assert abs(x @ Sv @ x) < 1e-6 * (1 + np.abs(Sv).max())
        if mdl.D is not None:  # ∂D/∂q ⪰ 0 by central differences of the CasADi D
            Dq = np.column_stack(
                [
                    (np.array(mdl.D(pv, qv + eps * e)) - np.array(mdl.D(pv, qv - eps * e))).ravel()
                    / (2 * eps)
                    for e in np.eye(n)
                ]
            )
            assert np.linalg.eigvalsh((Dq + Dq.T) / 2).min() > -1e-6 * (1 + np.abs(Dq).max())


def test_point_mass_models():
    m2 = build_model("point_mass_2d", {"m": 2.0})
    assert m2.n == 2 and m2.M_bounds == (2.0, 2.0)
    np.testing.assert_allclose(np.array(m2.M([1.0, -2.0])), 2.0 * np.eye(2))
    np.testing.assert_allclose(np.array(m2.C([1.0, -2.0], [3.0, 4.0])), np.zeros((2, 2)))
    np.testing.assert_allclose(np.array(m2.G([1.0, -2.0])).ravel(), [0.0, 0.0])
    m3 = build_model("point_mass_3d", {"m": 1.2, "g0": 9.81})
    assert m3.n == 3 and m3.M_bounds == pytest.approx((1.2, 1.2))
    np.testing.assert_allclose(np.array(m3.M([0.0, 1.0, 5.0])), 1.2 * np.eye(3))
    np.testing.assert_allclose(np.array(m3.C([0, 1, 5], [1, 2, 3])), np.zeros((3, 3)))
    np.testing.assert_allclose(np.array(m3.G([0.0, 1.0, 5.0])).ravel(), [0.0, 0.0, 1.2 * 9.81])


def test_christoffel_derivation_on_a_known_case():
    """Polar point mass: T = ½m(ṙ² + r²θ̇²) has the textbook C = [[0, −mrθ̇], [mrθ̇, mrṙ]]."""
    r, th, rd, thd, m = sp.symbols("r theta rd thd m", positive=True)
    T = sp.Rational(1, 2) * m * (rd**2 + r**2 * thd**2)
    M, C, G = euler_lagrange_matrices(T, sp.Integer(0), [r, th], [rd, thd])
    assert sp.simplify(M - sp.diag(m, m * r**2)).is_zero_matrix
    assert sp.simplify(C - sp.Matrix([[0, -m * r * thd], [m * r * thd, m * r * rd]])).is_zero_matrix
    assert G.is_zero_matrix


def test_property_failures_raise_toolkit_errors():
    x, v = sp.symbols("x v", real=True)
    with pytest.raises(ScenarioError, match="Property 1"):
        check_properties(sp.Matrix([[-1]]), sp.Matrix([[0]]), [x], [v], "bad")
    with pytest.raises(ScenarioError, match="Property 1"):  # indefinite for some angle
        check_properties(sp.Matrix([[sp.cos(x)]]), sp.Matrix([[0]]), [x], [v], "bad")
    with pytest.raises(ScenarioError, match="Property 2"):  # C not from Christoffel symbols
        M = sp.Matrix([[2 + sp.cos(x)]])
        check_properties(M, sp.Matrix([[0]]), [x], [v], "bad")


def test_unknown_model_and_parameter():
    with pytest.raises(ScenarioError, match="unknown model"):
        build_model("quadcopter_9000")
    with pytest.raises(ScenarioError, match="two_link.mass"):
        build_model("two_link", {"mass": 1.0})


def test_adding_a_model_is_one_registration():
    def lag(prm):
        p, q = sp.symbols("th", real=True), sp.symbols("w", real=True)
        ml2 = sp.nsimplify(prm["ml2"])
        return sp.Rational(1, 2) * ml2 * q**2, -sp.cos(p), [p], [q]

    name = "_test_pendulum"
    try:
        register(ModelSpec(name=name, n=1, defaults={"ml2": 2.0}, lagrangian=lag))
        mdl = build_model(name)
        assert mdl.M_bounds == (2.0, 2.0)
        assert float(np.array(mdl.G([0.5])).ravel()[0]) == pytest.approx(np.sin(0.5))
    finally:
        REGISTRY.pop(name, None)


def test_dissipation_is_checked_and_enters_as_dr_dq():
    from core.models.derive import check_dissipation

    x, y, v, w = sp.symbols("x y v w", real=True)
    # viscous friction with a state-dependent coefficient: D = dR/dq, dD/dq >= 0
    R = sp.Rational(1, 2) * (2 + sp.cos(x)) * v**2 + sp.Rational(1, 2) * w**2
    D = sp.Matrix([sp.diff(R, v), sp.diff(R, w)])
    assert check_dissipation(D, [x, y], [v, w], "ok").startswith("sampled")
    assert check_dissipation(sp.Matrix([3 * v, w]), [x, y], [v, w], "ok") == "exact"
    with pytest.raises(ScenarioError, match="dissipation: dD/dq has eigenvalue"):
        check_dissipation(sp.Matrix([-v, w]), [x, y], [v, w], "bad")  # negative friction
    with pytest.raises(ScenarioError, match="not symmetric"):
        check_dissipation(sp.Matrix([w, 0]), [x, y], [v, w], "bad")  # not a gradient

    def lag(prm):
        p, q = sp.symbols("th", real=True), sp.symbols("w", real=True)
        c = sp.nsimplify(prm["c"])
        return sp.Rational(1, 2) * q**2, -sp.cos(p), [p], [q], sp.Rational(1, 2) * c * q**2

    name = "_test_damped_pendulum"
    try:
        register(ModelSpec(name=name, n=1, defaults={"c": 0.7}, lagrangian=lag))
        mdl = build_model(name)
        assert float(np.array(mdl.D([0.5], [2.0])).ravel()[0]) == pytest.approx(1.4)
        assert mdl.checks["dissipation"] == "exact"
        assert build_model("two_link").D is None  # no Rayleigh function: no dissipation
    finally:
        REGISTRY.pop(name, None)
