"""The formation rule b_i(η̇_i) (symbolic/formation.py, docs/closed-loop.md 'Formation rule').

Independent truths: a direct numpy rotation by atan2 (exact where ‖d‖ ≥ ε), the closed form
d/‖d‖ of the outer branch and its derivatives (C³ matching across ‖d‖ = ε), finite
differences of b along a curve (ḃ, b̈ by AD), and the hand-written numpy chain rule of
verify/reference.py (a second implementation).
"""

from __future__ import annotations

from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from symbolic.formation import formation_function, formation_offset
from verify.reference import Reference

EPS = 0.5


def rotation(tau: float) -> np.ndarray:
    return np.array([[np.cos(tau), -np.sin(tau)], [np.sin(tau), np.cos(tau)]])


def jets(expr_of_d, order: int = 3) -> ca.Function:
    """b and its Jacobians in d up to ``order`` as one Function (d, b0) -> (J0, ..., J_order)."""
    d, b0 = ca.SX.sym("d", 2), ca.SX.sym("b0", 2)
    out = [expr_of_d(d, b0)]
    for _ in range(order):
        out.append(ca.jacobian(ca.vec(out[-1]), d))
    return ca.Function("jets", [d, b0], out)


RULE = jets(lambda d, b0: formation_offset(d, b0, EPS))
# the outer branch written independently: R(τ) = [[d1, −d2], [d2, d1]]/‖d‖, no branch, no blend
EXACT = jets(
    lambda d, b0: ca.vertcat(ca.horzcat(d[0], -d[1]), ca.horzcat(d[1], d[0])) @ b0 / ca.norm_2(d)
)


def test_exact_rotation_at_and_above_threshold():
    rng = np.random.default_rng(1)
    for k in range(200):
        r = EPS * (1.0 if k < 20 else 10 ** rng.uniform(0, 3))
        a = rng.uniform(-np.pi, np.pi)
        d = r * np.array([np.cos(a), np.sin(a)])
        b0 = rng.normal(size=2) * 5
        want = rotation(np.arctan2(d[1], d[0])) @ b0
        got = np.array(RULE(d, b0)[0]).ravel()
        assert np.abs(got - want).max() <= 1e-12 * max(1.0, np.abs(b0).max())


def test_identity_at_zero_and_finite_derivatives():
    b0 = np.array([3.0, -4.0])
    vals = RULE([0.0, 0.0], b0)
    np.testing.assert_array_equal(np.array(vals[0]).ravel(), b0)
    for J in vals:
        assert np.all(np.isfinite(np.array(J)))
    # ḃ, b̈ along a curve through d = 0 (the paper scenario's start: η̇_i(0) = 0, η̈_i(0) ≠ 0)
    f = formation_function(2, 2, EPS)
    out = f([0.0, 0.0], [116.0, -3.0], [40.0, 7.0], b0)
    np.testing.assert_array_equal(np.array(out[0]).ravel(), b0)
    assert all(np.all(np.isfinite(np.array(o))) for o in out)


@pytest.mark.parametrize("order", [0, 1, 2, 3])
def test_c3_across_threshold(order):
    """Inside-branch derivatives at ‖d‖ = ε(1 − δ) tend to the exact rotation's at ε like O(δ)."""
    rng = np.random.default_rng(2 + order)
    for _ in range(10):
        a = rng.uniform(-np.pi, np.pi)
        u = np.array([np.cos(a), np.sin(a)])
        b0 = rng.normal(size=2) * 3
        ref = np.array(EXACT(EPS * u, b0)[order])
        scale = np.abs(ref).max() + np.abs(b0).max() / EPS**order
        errs = []
        for delta in (1e-3, 1e-4, 1e-5):
            inner = np.array(RULE(EPS * (1 - delta) * u, b0)[order])
            outer = np.array(RULE(EPS * (1 + delta) * u, b0)[order])
            np.testing.assert_allclose(
                outer, np.array(EXACT(EPS * (1 + delta) * u, b0)[order]), rtol=0, atol=1e-11 * scale
            )
            errs.append(np.abs(inner - ref).max() / scale)
        # a jump leaves an O(1) error at every δ; continuity (with a bounded next derivative
        # on each side) makes it O(δ): 100x smaller over two decades of δ
        assert errs[2] < 0.02 * errs[0] + 1e-10


def curve(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """η̇(t) through 0 at t = 0 and across ‖η̇‖ = ε, with its two time derivatives."""
    d = np.array([0.9 * t + 0.3 * t**2, 0.4 * np.sin(2 * t)])
    dd = np.array([0.9 + 0.6 * t, 0.8 * np.cos(2 * t)])
    ddd = np.array([0.6, -1.6 * np.sin(2 * t)])
    return d, dd, ddd


def test_ad_derivatives_match_finite_differences_along_a_curve():
    f = formation_function(2, 2, EPS)
    b0 = np.array([2.0, -4.0])
    h = 1e-5

    def ev(t):
        d, dd, ddd = curve(t)
        return [np.array(o).ravel() for o in f(d, dd, ddd, b0)]

    crossed = set()
    for t in np.linspace(-0.3, 1.5, 37):
        crossed.add(bool(np.linalg.norm(curve(t)[0]) < EPS))
        b, bd, bdd = ev(t)
        bp, bm = ev(t + h), ev(t - h)
        # central differences err by h²/6 times the next derivative (~1e-11 · 1e4 near ε)
        np.testing.assert_allclose(bd, (bp[0] - bm[0]) / (2 * h), rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(bdd, (bp[1] - bm[1]) / (2 * h), rtol=1e-6, atol=1e-5)
    assert crossed == {True, False}  # the curve is tested on both sides of the threshold


def test_numpy_reference_matches_casadi_rule():
    """verify/reference.py's hand chain rule (second implementation) against the AD rule."""
    rng = np.random.default_rng(7)
    N = 64
    b0 = rng.normal(size=(N, 2)) * 3
    r = EPS * rng.uniform(0, 2, N)
    r[:4] = [0.0, EPS, EPS * (1 - 1e-9), EPS * (1 + 1e-9)]
    a = rng.uniform(-np.pi, np.pi, N)
    d = np.stack([r * np.cos(a), r * np.sin(a), rng.normal(size=N)], 1)  # m = 3
    dd, ddd = rng.normal(size=(N, 3)) * 5, rng.normal(size=(N, 3)) * 20
    fake = SimpleNamespace(b0=b0, n=2, m=3, opts=SimpleNamespace(tau_threshold=EPS))
    got = Reference.formation(fake, d, dd, ddd)
    f = formation_function(3, 2, EPS)
    for i in range(N):
        want = f(d[i], dd[i], ddd[i], b0[i])
        for g, w in zip(got, want, strict=True):
            w = np.array(w).ravel()
            np.testing.assert_allclose(g[i], w, rtol=1e-12, atol=1e-12 * (1 + np.abs(w).max()))
