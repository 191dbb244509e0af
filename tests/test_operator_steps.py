"""The recovery metric after an operator step: the slot the controller tracks (its blend
below ``tau_threshold`` included) against hand computations and the controller's own
target, recovery times on signals whose answer is known, and on a step trajectory."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pandas as pd
import pytest
from helpers import PAPER

from symbolic.formation import formation_offset
from verify.operator_steps import (
    classify,
    deviation,
    formation_rule,
    recoveries,
    recovery_summary,
    recovery_time,
    slots,
    step_peak_u,
    step_starts,
)


def test_recovery_time_of_a_known_signal():
    t = np.round(np.arange(0.0, 10.0, 0.01), 10)
    dev = np.where((t >= 4.0) & (t < 5.3), 1.0, 0.01)  # off its slot from 4 s to 5.3 s
    assert recovery_time(t, dev, 4.0, 8.0, 0.05) == pytest.approx(1.3)
    assert recovery_time(t, dev, 6.0, 8.0, 0.05) == 0.0  # never above the level
    assert recovery_time(t, np.ones_like(t), 4.0, 8.0, 0.05) == math.inf  # never back
    with_nan = np.where(t < 5.0, np.nan, dev)  # a slot that cannot be computed is not skipped
    assert math.isnan(recovery_time(t, with_nan, 4.0, 8.0, 0.05))
    assert classify(1.3, 4.0, 2.0) == "recovered"
    assert classify(2.5, 4.0, 2.0) == "late"
    assert classify(math.inf, 2.0, 2.0) == "late"  # 2 s passed and it is still out
    assert classify(math.inf, 1.0, 2.0) == "undefined"  # the next step came first
    assert classify(math.nan, 4.0, 2.0) == "undefined"


def test_the_formation_rule_is_the_rotation_outside_the_threshold_and_b0_at_rest():
    rng = np.random.default_rng(3)
    eps, b0 = 1.5, np.array([1.0, 4.0])
    d = rng.normal(size=(200, 2)) * 3
    d = d[np.hypot(d[:, 0], d[:, 1]) >= eps]
    ang = np.arctan2(d[:, 1], d[:, 0])
    rot = np.stack(
        [np.cos(ang) * b0[0] - np.sin(ang) * b0[1], np.sin(ang) * b0[0] + np.cos(ang) * b0[1]], 1
    )
    np.testing.assert_allclose(formation_rule(d, b0, eps), rot, atol=1e-12)
    np.testing.assert_allclose(formation_rule(np.zeros((1, 2)), b0, eps), [b0], atol=1e-15)


def test_the_formation_rule_inside_the_threshold_by_hand_and_against_the_controller():
    """d = (0, 0.75), ε = 1.5: u = 1/4, w = 3/4, q = (1 + 3/8 + 27/128 + 135/1024)/1.5 =
    1759/1536, κ = (3/4)⁴ (5 − 3) = 81/128; b0 = (4, 0): b = (4κ, 4·0.75·q)."""
    got = formation_rule(np.array([[0.0, 0.75]]), np.array([4.0, 0.0]), 1.5)
    np.testing.assert_allclose(got, [[4 * 81 / 128, 3 * 1759 / 1536]], rtol=1e-14)
    # the controller's CasADi rule (symbolic/formation.py), a second implementation
    e, b = ca.SX.sym("e", 2), ca.SX.sym("b", 2)
    f = ca.Function("b", [e, b], [formation_offset(e, b, 1.5)])
    rng = np.random.default_rng(4)
    for d in rng.uniform(-2.0, 2.0, size=(100, 2)):
        b0 = rng.normal(size=2)
        want = np.array(f(d, b0)).ravel()
        np.testing.assert_allclose(formation_rule(d[None], b0, 1.5)[0], want, atol=1e-12)


def _frame(sc, offsets: dict[float, float]) -> tuple[pd.DataFrame, np.ndarray]:
    """η0 = (1, 0) (y0 = (1, 2), η̇0 = (0, u0)), followers exactly on their slots, follower
    1 moved off by 0.3 on each [start, end) of ``offsets``; the slot of follower 1 by hand."""
    t = np.round(np.arange(0.0, 20.0 + 1e-9, 0.01), 10)
    u0 = sc.leader.u0_numpy(t)[0]
    v = u0  # d = (0, u0); ε = 1.5 > |u0|: the blend, as in the docstring above with v
    w = 1 - v**2 / 1.5**2
    q = (1 + w / 2 + 3 * w**2 / 8 + 5 * w**3 / 16) / 1.5
    kappa = w**4 * (5 - 4 * w)
    slot1 = np.stack([1 + 4 * kappa, 2 + 4 * v * q], 1)  # b0 of follower 1 = (4, 0)
    cols = {"t": t, "eta0_1": np.ones_like(t), "eta0_2": np.zeros_like(t)}
    s = slots(sc, pd.DataFrame(cols), np.ones(sc.N))
    off = np.zeros_like(t)
    for a, b in offsets.items():
        off[(t >= a) & (t < b)] = 0.3
    for i in range(sc.N):
        p = s[:, i, :] + (off[:, None] * np.array([0.6, 0.8]) if i == 0 else 0.0)
        cols.update({f"p{i + 1}_1": p[:, 0], f"p{i + 1}_2": p[:, 1]})
    return pd.DataFrame(cols), slot1


def test_recoveries_on_a_hand_made_trajectory():
    api = pytest.importorskip("generated.api")
    u0 = ["0.75*step(t - 4) - 0.75*step(t - 5)"]
    sc = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 0.0}, variant="hand")
    df, slot1 = _frame(sc, {4.0: 5.5, 19.0: 21.0})
    np.testing.assert_allclose(slots(sc, df, np.ones(5))[:, 0, :], slot1, atol=1e-12)
    dev = deviation(sc, df, np.ones(5))
    assert np.max(np.abs(dev[:, 1:])) < 1e-12 and np.max(dev[:, 0]) == pytest.approx(0.3)
    got = recoveries(sc, df, np.ones(5))  # follower 1 is the only pinned one
    assert [(r.start, r.follower, r.outcome) for r in got] == [
        (4.0, 0, "undefined"),  # still out at 5 s, when the release came 1 s later
        (5.0, 0, "late"),  # back at 5.5 s, out again from 19 s to the horizon
    ]
    assert math.isinf(got[1].time) and got[1].peak == pytest.approx(0.3)
    df, _ = _frame(sc, {4.0: 4.3, 5.0: 6.25})
    got = recoveries(sc, df, np.ones(5))
    assert [r.outcome for r in got] == ["recovered", "recovered"]
    assert [r.time for r in got] == pytest.approx([0.3, 1.25])
    summary = recovery_summary(got)
    assert summary["step_recovery_s"] == pytest.approx(1.25)
    assert (summary["step_pairs"], summary["step_pairs_late"], summary["step_pairs_undefined"]) == (
        2,
        0,
        0,
    )


def test_step_starts_of_raw_and_shaped_steps():
    api = pytest.importorskip("generated.api")
    u0 = ["0.5*cos(t) + 1.2*step(t - 6) - 1.2*step(t - 9)"]
    raw = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 0.0}, variant="raw")
    shaped = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 1.0}, variant="shaped")
    assert step_starts(raw) == [6.0, 9.0]
    assert step_starts(shaped) == [6.0, 9.0]  # breakpoints 6, 7, 9, 10
    assert step_starts(api.load(PAPER, None, variant="paper")) == []


@pytest.mark.slow
def test_recovery_on_a_step_trajectory(tmp_path):
    """The paper's loop with a unit step and its release (the library of
    tests/test_shaping.py's slow test). The slot from the leader's state agrees with the
    controller's own target C0 η_1 + b_1 (logged) to the observer's error away from the
    steps; the raw step throws the pinned follower off its slot, the default shaping keeps
    it within 0.05."""
    api = pytest.importorskip("generated.api")
    from core.graph import base_gauge

    out = {}
    for name, rise in (("raw", {"leader.u0_rise": 0.0}), ("default", {})):
        over = {
            "leader.u0": ["1.0*step(t - 3) - 1.0*step(t - 5)"],
            "integration.horizon": 7.0,
            **rise,
        }
        res = api.run(PAPER, overrides=over, variant=name, out_root=tmp_path, progress=False)
        sc = api.load(PAPER, over, variant=name)
        h = base_gauge(sc.graph.adjacency, sc.graph.pinning)
        df = res.frame
        s = slots(sc, df, h)[:, 0, :]
        target = df[["eta1_1", "eta1_2"]].to_numpy() @ np.asarray(sc.leader.C0).T
        target = target + df[["b1_1", "b1_2"]].to_numpy()
        t = df["t"].to_numpy()
        calm = (t > 2.0) & (np.abs(t - 3) > 0.5) & (np.abs(t - 5) > 0.5) & (np.abs(t - 6) > 0.5)
        # the two differ by the observer's error: C0 (η_1 − η0) (‖C0‖ = √10) and b's change
        err = np.abs(df[["eta1_1", "eta1_2"]].to_numpy() - df[["eta0_1", "eta0_2"]].to_numpy())
        assert err[calm].max() < 1e-3
        np.testing.assert_allclose(s[calm], target[calm], atol=5e-3)
        # the exact rotation R(τ0) b_10 (no blend) is not what the controller tracks here:
        # the leader is slower than tau_threshold = 1.5 before and during the press
        d = df[["eta0_2"]].to_numpy().ravel(), sc.leader.u0_numpy(t)[0]
        ang = np.arctan2(d[1], d[0])
        exact = (
            target - df[["b1_1", "b1_2"]].to_numpy() + 4.0 * np.stack([np.cos(ang), np.sin(ang)], 1)
        )
        assert np.abs(exact[calm] - target[calm]).max() > 20 * 5e-3
        out[name] = recoveries(sc, df, h)
    assert [r.start for r in out["raw"]] == [3.0, 5.0]
    assert max(r.peak for r in out["raw"]) > 0.05
    assert all(r.time > 0 for r in out["raw"] if r.outcome != "undefined")
    assert all(r.outcome == "recovered" for r in out["default"])
    assert max(r.peak for r in out["default"]) < max(r.peak for r in out["raw"])


def test_step_peak_u_sees_only_the_seconds_after_each_step():
    api = pytest.importorskip("generated.api")
    u0 = ["0.75*step(t - 4) - 0.75*step(t - 5)"]
    sc = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 0.0}, variant="hand")
    df, _ = _frame(sc, {})
    t = df["t"].to_numpy()
    for i in range(1, sc.N + 1):
        for r in (1, 2):
            df[f"u{i}_{r}"] = np.ones_like(t)
    df.loc[np.isclose(t, 6.5), "u3_2"] = -50.0  # 1.5 s after the release
    df.loc[np.isclose(t, 12.0), "u1_1"] = 80.0  # long after both steps
    assert step_peak_u(sc, df) == pytest.approx(math.hypot(1.0, 50.0), rel=1e-15)  # ‖u_3‖
    assert step_peak_u(sc, df, window=1.0) == pytest.approx(math.sqrt(2.0), rel=1e-15)
    paper = api.load(PAPER, None, variant="paper")
    assert math.isnan(step_peak_u(paper, df))


def test_windows_of_no_event_one_event_and_events_past_the_horizon():
    """Each event's window runs to the next event or just past the last output time; no
    event (a sample without steps or switches) has no window."""
    from verify.operator_steps import windows

    t = np.linspace(0.0, 20.0, 201)
    assert windows(t, []) == []
    assert windows(t, [25.0]) == []
    (w,) = windows(t, [5.0, 30.0])
    assert w[0] == 5.0 and 20.0 < w[1] < 20.0 + 1e-9
    assert windows(t, [5.0, 10.0])[0] == (5.0, 10.0)
