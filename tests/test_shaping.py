"""Operator command shaping (``leader.u0_rise``, ``u0_shape``), ``smoothstep`` and
``prefilter``, against closed forms, an ODE solution and the loader's default."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from helpers import PAPER
from scipy.integrate import solve_ivp

from core.errors import ScenarioError
from core.expressions import parse_expression
from core.shaping import DEFAULT_RISE, default_rise, shaped_steps, step_onsets
from verify.reference import _dual


def _closed_form(x: np.ndarray) -> np.ndarray:
    """3s² − 2s³ with s = clip(x, 0, 1), written out independently of the parser."""
    s = np.minimum(np.maximum(x, 0.0), 1.0)
    return 3 * s**2 - 2 * s**3


def _critical_form(x: np.ndarray) -> np.ndarray:
    """1 − (1 + x)e^(−x) for x > 0, 0 before, written out independently of the parser."""
    xp = np.maximum(x, 0.0)
    return np.where(x > 0, 1.0 - np.exp(-xp) - xp * np.exp(-xp), 0.0)


def _three_ways(text: str, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e = parse_expression(text)
    t = ca.SX.sym("t")
    f = ca.Function("f", [t], [e.casadi(t)])
    dual = np.array([_dual(e.node, float(x))[0] for x in ts])
    return e.numpy(ts), np.array(f(ts)).ravel(), dual


def test_smoothstep_numpy_casadi_and_dual_agree_with_the_closed_form():
    ts = np.linspace(0.0, 4.0, 401)
    want = _closed_form((ts - 2) / 0.5)
    for got in _three_ways("smoothstep((t - 2)/0.5)", ts):
        np.testing.assert_allclose(got, want, atol=1e-15)


def test_smoothstep_is_continuously_differentiable_with_its_kinks_as_breakpoints():
    e = parse_expression("smoothstep((t - 2)/0.5)")
    slopes = [_dual(e.node, x)[1] for x in (1.999999, 2.0, 2.000001, 2.499999, 2.5, 2.500001)]
    np.testing.assert_allclose(slopes, 0.0, atol=1e-4)  # no jump of the slope at either end
    assert _dual(e.node, 2.25)[1] == pytest.approx(1.5 / 0.5)  # peak slope 1.5 / rise
    assert e.breakpoints() == (2.0, 2.5)


def test_prefilter_numpy_casadi_and_dual_agree_with_the_closed_form():
    ts = np.linspace(0.0, 8.0, 801)
    want = _critical_form((ts - 2) / 0.5)
    for got in _three_ways("prefilter((t - 2)/0.5)", ts):
        np.testing.assert_allclose(got, want, atol=1e-15)


def test_prefilter_is_the_step_response_of_a_critically_damped_filter():
    """y'' + 2y'/τ + y/τ² = u/τ², u = step(t − 2), from rest: scipy's solution of the
    ODE is the expression, and its derivative is the dual number's (x e^(−x)/τ)."""
    tau, t0 = 0.5, 2.0
    e = parse_expression(f"prefilter((t - {t0})/{tau})")

    def f(t, y):
        u = 1.0 if t >= t0 else 0.0
        return [y[1], (u - y[0] - 2 * tau * y[1]) / tau**2]

    ts = np.linspace(0.0, 8.0, 161)
    sol = solve_ivp(f, (0, 8), [0.0, 0.0], t_eval=ts, rtol=1e-10, atol=1e-12, max_step=0.01)
    np.testing.assert_allclose(e.numpy(ts), sol.y[0], atol=1e-7)
    np.testing.assert_allclose([_dual(e.node, float(x))[1] for x in ts], sol.y[1], atol=1e-6)


def test_prefilter_is_c1_with_its_curvature_jump_at_the_onset():
    tau = 0.25
    e = parse_expression(f"prefilter((t - 3)/{tau})")
    slope = [_dual(e.node, x)[1] for x in (3 - 1e-7, 3.0, 3 + 1e-7)]
    np.testing.assert_allclose(slope, 0.0, atol=1e-5)  # the slope does not jump
    h = 1e-5  # second derivative just after the onset: 1/τ² (the filter's initial curvature)
    curv = (_dual(e.node, 3 + 2 * h)[1] - _dual(e.node, 3 + h)[1]) / h
    assert curv == pytest.approx(1 / tau**2, rel=1e-3)
    assert max(_dual(e.node, x)[1] for x in np.linspace(3, 6, 3001)) == pytest.approx(
        1 / (np.e * tau), rel=1e-6
    )  # peak slope 1/(eτ) at x = 1
    assert e.breakpoints() == (3.0,)


def test_shaped_steps_keep_the_change_and_bound_its_rate():
    e = parse_expression("cos(t) + 0.8*step(t - 14) - 1.8*step(t - 15)")
    s = shaped_steps(e, 0.5)
    ts = np.linspace(0.0, 20.0, 20001)
    away = (np.abs(ts - 14.25) > 0.25) & (np.abs(ts - 15.25) > 0.25)
    np.testing.assert_allclose(s.numpy(ts)[away], e.numpy(ts)[away], atol=1e-12)
    jump = np.diff(s.numpy(ts) - np.cos(ts)) / np.diff(ts)  # the shaped part alone
    assert np.max(np.abs(jump)) <= 1.8 * 1.5 / 0.5 + 1e-6
    assert parse_expression(s.text).node == s.node  # its text reads back as the same tree
    assert shaped_steps(parse_expression("2*cos(t)"), 0.5).text == "2*cos(t)"


def test_the_ramp_is_a_rate_limit_and_the_prefilter_settles_without_overshoot():
    e = parse_expression("0.5*cos(t) + 1.2*step(t - 6) - 1.2*step(t - 9)")
    ts = np.linspace(0.0, 20.0, 40001)
    ramp = shaped_steps(e, 1.0, "ramp").numpy(ts) - 0.5 * np.cos(ts)
    want = 1.2 * (np.clip(ts - 6, 0, 1) - np.clip(ts - 9, 0, 1))  # linear over 1 s
    np.testing.assert_allclose(ramp, want, atol=1e-12)
    pre = shaped_steps(e, 0.5, "prefilter").numpy(ts) - 0.5 * np.cos(ts)
    want = 1.2 * (_critical_form((ts - 6) / 0.5) - _critical_form((ts - 9) / 0.5))
    np.testing.assert_allclose(pre, want, atol=1e-12)
    assert pre.max() <= 1.2 and pre.min() >= -1.2 * 1e-12  # a convex blend: no overshoot
    with pytest.raises(ValueError, match="shape"):
        shaped_steps(e, 1.0, "spline")


def test_step_onsets_are_the_starts_of_raw_and_shaped_steps():
    e = parse_expression("0.5*cos(t) + 1.2*step(t - 6) - 1.2*step(t - 9)")
    assert step_onsets([e]) == [6.0, 9.0]
    for shape in ("smoothstep", "prefilter", "ramp"):
        assert step_onsets([shaped_steps(e, 1.0, shape)]) == [6.0, 9.0], shape
    assert step_onsets([parse_expression("step(t - 2)"), parse_expression("step(t - 2)")]) == [2.0]
    assert step_onsets([parse_expression("2*cos(t)")]) == []


def test_the_default_shapes_only_a_stepped_u0():
    assert default_rise([parse_expression("2*cos(t)")]) == 0.0
    assert default_rise([parse_expression("sat(t - 3)")]) == 0.0  # a ramp has no jump
    assert default_rise([parse_expression("cos(t) + 0.8*step(t - 14)")]) == DEFAULT_RISE > 0


def test_u0_rise_reaches_the_leader_and_is_refused_where_it_means_nothing():
    api = pytest.importorskip("generated.api")
    u0 = ["cos(t) + 0.8*step(t - 14)"]
    sc = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 0.5}, variant="rise")
    assert "smoothstep" in sc.leader.u0[0].text and sc.leader.u0_rise == 0.5
    raw = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 0.0}, variant="raw")
    assert raw.leader.u0[0].text == u0[0] and raw.leader.u0_rise == 0.0
    by_default = api.load(PAPER, {"leader.u0": u0}, variant="default").leader
    want = shaped_steps(parse_expression(u0[0]), DEFAULT_RISE)
    assert by_default.u0[0].text == want.text and by_default.u0_rise == DEFAULT_RISE
    pre = api.load(PAPER, {"leader.u0": u0, "leader.u0_shape": "prefilter"}, variant="pre")
    assert "prefilter" in pre.leader.u0[0].text
    with pytest.raises(ScenarioError, match="leader.u0_rise"):
        api.load(PAPER, {"leader.u0_rise": -1.0}, variant="neg")
    with pytest.raises(ScenarioError, match="leader.u0_shape"):
        api.load(PAPER, {"leader.u0_shape": "spline"}, variant="bad")


def test_the_paper_scenario_is_not_shaped():
    """2 cos t has no step: the default leaves u0, and with it the trajectory, as written
    (the trajectory's bytes are pinned by tests/test_closed_loop.py)."""
    api = pytest.importorskip("generated.api")
    L = api.load(PAPER, None, variant="paper").leader
    assert [e.text for e in L.u0] == ["2*cos(t)"] and L.u0_rise == 0.0


@pytest.mark.slow
def test_a_shaped_operator_step_keeps_the_torques_of_a_smooth_command(tmp_path):
    """A unit step and its release: raw, the oracle feed-forward sends impulses to the
    torques; shaped by the default, the torques stay below 1e3 (the paper's 2 cos t: 68-225)."""
    api = pytest.importorskip("generated.api")
    peaks = {}
    for name, rise in (("raw", {"leader.u0_rise": 0.0}), ("default", {})):
        over = {
            "leader.u0": ["1.0*step(t - 3) - 1.0*step(t - 5)"],
            "integration.horizon": 7.0,
            **rise,
        }
        res = api.run(PAPER, overrides=over, variant=name, out_root=tmp_path, progress=False)
        late = res.frame[res.frame["t"] >= 1.0]
        peaks[name] = float(late.filter(regex=r"^u\d+_\d+$").abs().to_numpy().max())
    assert peaks["raw"] > 1e6
    assert peaks["default"] < 1e3
