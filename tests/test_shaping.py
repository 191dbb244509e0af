"""Operator command shaping (``leader.u0_rise``) and ``smoothstep``, against closed forms."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from helpers import PAPER

from core.errors import ScenarioError
from core.expressions import parse_expression
from core.shaping import shaped_steps
from verify.reference import _dual


def _closed_form(x: np.ndarray) -> np.ndarray:
    """3s² − 2s³ with s = clip(x, 0, 1), written out independently of the parser."""
    s = np.minimum(np.maximum(x, 0.0), 1.0)
    return 3 * s**2 - 2 * s**3


def test_smoothstep_numpy_casadi_and_dual_agree_with_the_closed_form():
    e = parse_expression("smoothstep((t - 2)/0.5)")
    ts = np.linspace(0.0, 4.0, 401)
    want = _closed_form((ts - 2) / 0.5)
    t = ca.SX.sym("t")
    f = ca.Function("f", [t], [e.casadi(t)])
    np.testing.assert_allclose(e.numpy(ts), want, atol=1e-15)
    np.testing.assert_allclose(np.array(f(ts)).ravel(), want, atol=1e-15)
    np.testing.assert_allclose([_dual(e.node, float(x))[0] for x in ts], want, atol=1e-15)


def test_smoothstep_is_continuously_differentiable_with_its_kinks_as_breakpoints():
    e = parse_expression("smoothstep((t - 2)/0.5)")
    slopes = [_dual(e.node, x)[1] for x in (1.999999, 2.0, 2.000001, 2.499999, 2.5, 2.500001)]
    np.testing.assert_allclose(slopes, 0.0, atol=1e-4)  # no jump of the slope at either end
    assert _dual(e.node, 2.25)[1] == pytest.approx(1.5 / 0.5)  # peak slope 1.5 / rise
    assert e.breakpoints() == (2.0, 2.5)


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


def test_u0_rise_reaches_the_leader_and_is_refused_where_it_means_nothing():
    api = pytest.importorskip("generated.api")
    u0 = ["cos(t) + 0.8*step(t - 14)"]
    sc = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 0.5}, variant="rise")
    assert "smoothstep" in sc.leader.u0[0].text
    assert api.load(PAPER, {"leader.u0": u0}, variant="raw").leader.u0[0].text == u0[0]
    with pytest.raises(ScenarioError, match="leader.u0_rise"):
        api.load(PAPER, {"leader.u0_rise": -1.0}, variant="neg")


@pytest.mark.slow
def test_a_shaped_operator_step_keeps_the_torques_of_a_smooth_command(tmp_path):
    """A unit step and its release: raw, the oracle feed-forward sends impulses to the
    torques; shaped over 1 s, the torques stay below 1e3 (the paper's 2 cos t: 68-225)."""
    api = pytest.importorskip("generated.api")
    peaks = {}
    for rise in (0.0, 1.0):
        over = {
            "leader.u0": ["1.0*step(t - 3) - 1.0*step(t - 5)"],
            "leader.u0_rise": rise,
            "integration.horizon": 7.0,
        }
        res = api.run(PAPER, overrides=over, variant=f"r{rise}", out_root=tmp_path, progress=False)
        late = res.frame[res.frame["t"] >= 1.0]
        peaks[rise] = float(late.filter(regex=r"^u\d+_\d+$").abs().to_numpy().max())
    assert peaks[0.0] > 1e6
    assert peaks[1.0] < 1e3
