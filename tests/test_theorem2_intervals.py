"""Theorem 2 restarted on intervals: restart points per follower, constants per interval, and
the operator-step reproduction (docs/verification.md, 'Theorem 2 on intervals').

The reproduction: the paper scenario with u0 = cos t + 0.8 step(t − 14), unshaped. At
t = 14 s the pinned follower's χ_1, hence V2_1, jumps with u0 (measured: V2_1 from 23.9 to
7.9e8 at the same state); eq. (38) holds on both sides. The comparison lemma started from
V2(0) over the whole run fails after the step (the old row); restarted from the measured
V2_1(t_k⁺) it holds, and a trajectory whose V2_1 does not jump (a forged log) fails it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from helpers import PAPER

from verify import claims as CL
from verify.bounds import BAND, comparison_reaching_time, theorem2_constants
from verify.intervals import (
    Cause,
    covered_fraction,
    follower_pieces,
    operator_jumps,
    u0_dependence,
)
from verify.table import bounds_table, failures

STEP_U0 = ["cos(t) + 0.8*step(t - 14)"]


def _load(overrides: dict):
    from generated import api

    return api.load(PAPER, overrides)


# ------------------------------------------------------------------------- restart points
def test_abrupt_fault_restarts_only_its_own_follower():
    sc = _load({"followers[2].faults": [{"type": "abrupt", "onset": 6.0, "severity": 0.4}]})
    p2 = follower_pieces(sc, 1)
    assert [(p.start, p.end) for p in p2] == [(0.0, 6.0), (6.0, 20.0)]
    assert p2[1].causes == (Cause.HEALTH_JUMP,) and p2[1].constant
    np.testing.assert_allclose([p2[0].g_lo, p2[1].g_lo], [0.95, 0.95 * 0.6], rtol=1e-12)
    for i in (0, 2, 3, 4):  # another follower's fault enters no other derivation
        assert [(p.start, p.end) for p in follower_pieces(sc, i)] == [(0.0, 20.0)]


def test_ramp_is_a_varying_piece_with_its_rate():
    sc = _load(
        {"followers[1].faults": [{"type": "ramp", "onset": 5.0, "severity": 0.4, "duration": 2.0}]}
    )
    p = follower_pieces(sc, 0)
    assert [(x.start, x.end) for x in p] == [(0.0, 5.0), (5.0, 7.0), (7.0, 20.0)]
    assert p[1].causes == (Cause.HEALTH_KINK,) and not p[1].constant
    np.testing.assert_allclose(p[1].gdot, 0.95 * 0.4 / 2.0, rtol=1e-9)  # slope of the ramp
    assert p[0].constant and p[2].constant
    np.testing.assert_allclose([p[1].g_lo, p[1].g_hi], [0.95 * 0.6, 0.95], rtol=1e-6)


def test_intermittent_fault_switches_at_every_edge():
    fault = {"type": "intermittent", "onset": 4.0, "severity": 0.3, "period": 2.0, "duty": 0.5}
    sc = _load({"followers[3].faults": [fault]})
    starts = [x.start for x in follower_pieces(sc, 2)]
    assert starts == [0.0, *np.arange(4.0, 20.0, 1.0).tolist()]
    assert all(x.constant for x in follower_pieces(sc, 2))


def test_operator_jumps_are_steps_not_kinks_and_not_shaped_steps():
    assert operator_jumps(_load({"leader.u0": STEP_U0, "leader.u0_rise": 0})) == (14.0,)
    assert operator_jumps(_load({"leader.u0": ["0.1*abs(t - 3)"]})) == ()
    assert operator_jumps(_load({"leader.u0": STEP_U0, "leader.u0_rise": 1.0})) == ()
    sc = _load({"leader.u0": STEP_U0, "leader.u0_rise": 0})
    assert [x.start for x in follower_pieces(sc, 0, u0_dep=True)] == [0.0, 14.0]
    assert [x.start for x in follower_pieces(sc, 1, u0_dep=False)] == [0.0]


def test_covered_fraction_of_overlapping_windows():
    assert covered_fraction([(0, 2), (1, 3), (5, 6)], 10.0) == pytest.approx(0.4)
    assert covered_fraction([(-1, 20)], 10.0) == 1.0 and covered_fraction([], 10.0) == 0.0


# ------------------------------------------------------------------------- constants
def test_a_varying_health_adds_its_rate_term_or_is_outside_the_theory(paper_scenario):
    sc = paper_scenario
    c0 = theorem2_constants(sc, 0, health=(0.57, 0.95, 0.0))
    c1 = theorem2_constants(sc, 0, health=(0.57, 0.95, 0.19))
    gam, gmin = float(sc.controller.gamma[0]), float(sc.controller.g_min)
    hi = 1.0 / gmin + BAND * (1.0 / gmin - 1.0)
    want = 0.19 / (2.0 * gam) * max(hi**2, 1.0 / 0.57**2)  # (ġ/(2γ)) max(ĝ², 1/g²)
    assert c0.rate_term == 0.0 and c1.rate_term == pytest.approx(want, rel=1e-12)
    assert c1.chi_v_var == pytest.approx(c0.chi_v_var + want, rel=1e-12)
    # the σ term is convex in g: its value at the worse end of [0.57, 0.95]
    sig, g0 = float(sc.controller.sigma[0]), float(sc.controller.ghat_ref[0])
    ends = [sig * g * (1 / g - g0) ** 2 / (2 * gam) for g in (0.57, 0.95)]
    assert c0.ghat_term == pytest.approx(max(ends), rel=1e-12)
    sigma_only = replace(sc, options=replace(sc.options, ghat_law="sigma"))
    c2 = theorem2_constants(sigma_only, 0, health=(0.57, 0.95, 0.19))
    assert not c2.provable and c2.why_not.startswith("outside the theory: g_1 varies")


# ------------------------------------------------------------------------- the reproduction
@pytest.fixture(scope="module")
def step_run(tmp_path_factory):
    from generated import api
    from verify.pipeline import Run, verify_run

    root = tmp_path_factory.mktemp("out")
    ov = {"leader.u0": STEP_U0, "leader.u0_rise": 0}
    res = api.run(PAPER, overrides=ov, out_root=root, progress=False)
    sc = api.load(PAPER, ov)
    gains, _ = api.ensure_gains(sc, root)
    v = verify_run(Run(sc, res.frame, res.trajectory.x, res.meta, root), out_root=root)
    return sc, gains, res, v


def test_chi_depends_on_u0_only_for_the_pinned_follower(step_run):
    from verify.lyapunov import closed_loop

    sc, gains, _, _ = step_run
    dep = u0_dependence(closed_loop(sc, gains), sc)
    assert dep.tolist() == (np.asarray(sc.graph.pinning) > 0).tolist() == [True] + [False] * 4


def test_V2_jumps_with_u0_and_eq38_holds_on_both_sides(step_run):
    from verify.lyapunov import check_theorem2, closed_loop, evaluate_p, fast_functions

    sc, gains, res, _ = step_run
    cl = closed_loop(sc, gains)
    t = res.trajectory.t
    k = int(np.flatnonzero(np.isclose(t, 14.0))[0])
    tt, XX = np.array([14.0 - 1e-9, 14.0 + 1e-9]), np.vstack([res.trajectory.x[k]] * 2)
    V, _, chi = evaluate_p(fast_functions(cl, "test-step"), "V2", tt, XX, cl.p0)
    assert V[1, 0, 0] > 1e6 * V[0, 0, 0]  # follower 1: the same state, u0 one step higher
    np.testing.assert_allclose(V[1, 1:, 0], V[0, 1:, 0], rtol=1e-9)  # the others: no jump
    assert np.linalg.norm(chi[1, 0]) > 1e4 * np.linalg.norm(chi[0, 0])
    assert all(chk.ok for chk in check_theorem2(cl, sc, tt, XX))


def test_the_comparison_lemma_from_V2_0_over_the_whole_run_fails(step_run):
    sc, _, res, _ = step_run
    df = res.frame
    c = theorem2_constants(sc, 0)
    tc = comparison_reaching_time(c.Omega_var, c.chi_v_var, df["V2_1"].iloc[0], 0.5)
    t = df["t"].to_numpy()
    chi = np.linalg.norm(df[["chi1_1", "chi1_2"]].to_numpy(), axis=1)
    assert tc < 14.0 and chi[t >= tc].max() > 1e3 * c.chi_bar_var  # the old row: 1.65e4 > 4.45


def test_restarted_rows_hold_and_say_where_they_are_not_stated(step_run):
    _, _, _, v = step_run
    tb = v.table
    assert failures(tb).empty
    one = tb[(tb["agent"] == "1") & tb["claim_id"].isin(CL.TRACKING)]
    held = one[one["kind"] == "guaranteed"]
    assert len(held) == 4 and held["holds"].all() and (held["t_end"] < 14.0).all()
    after = one[one["t_start"] >= 14.0]
    assert len(after) == 4 and after["holds"].isna().all()
    assert after["note"].str.contains("interval 2 of 2 .from operator step at t = 14 s.").all()
    assert after["note"].str.contains("comparison-lemma time .* beyond the horizon").all()
    # the envelope from V2(t_s) bounds each interval's transient, the step's too
    env = tb[(tb["agent"] == "1") & tb["claim_id"].isin(CL.ENVELOPE)]
    assert len(env) == 4 and (env["kind"] == "guaranteed").all() and env["holds"].all()
    assert sorted(env["t_start"].round(6).unique()) == [0.0, 14.01]
    # the others are not restarted: one interval each, guaranteed
    others = tb[(tb["agent"] != "1") & (tb["claim_id"] == CL.T2_CHI.id)]
    assert len(others) == 4 and (others["kind"] == "guaranteed").all() and others["holds"].all()


def test_the_restarted_rows_fail_on_forged_trajectories(step_run):
    sc, gains, res, _ = step_run
    dep = np.array([True, False, False, False, False])
    # χ_1 thirty times larger before the step: interval 1's row fails
    df = res.frame.copy()
    before = df["t"] < 14.0
    df.loc[before, ["chi1_1", "chi1_2"]] *= 30.0
    bad = failures(bounds_table(sc, df, gains=gains, u0_dep=dep))
    assert ((bad["claim_id"] == CL.T2_CHI.id) & (bad["agent"] == "1")).any()
    assert ((bad["claim_id"] == CL.T2_CHI_ENV.id) & (bad["agent"] == "1")).any()
    # a log whose V2_1 does not jump at the step: restarted from it, the lemma gives t_c at
    # once and the row on [14, 20] s fails on the real χ_1
    df = res.frame.copy()
    k = int(np.searchsorted(df["t"].to_numpy(), 14.0, side="right"))
    df.loc[k, "V2_1"] = float(df["V2_1"].iloc[k - 2])
    bad = failures(bounds_table(sc, df, gains=gains, u0_dep=dep))
    late = bad[(bad["agent"] == "1") & (bad["t_start"] >= 14.0)]
    assert (late["claim_id"] == CL.T2_CHI.id).any() and math.isfinite(late["t_start"].min())
    assert {CL.T2_CHI_ENV.id, CL.DEF1_ENV.id} <= set(late["claim_id"])


# ------------------------------------------------------------------------- every row exists
def _frame_for(sc):
    """The synthetic trajectory on the scenario's horizon, widened to its leader's size m."""
    from verify.synthetic import synthetic_trajectory

    df = synthetic_trajectory(N=sc.N, horizon=sc.integration.horizon)
    extra = {}
    for k in range(3, sc.m + 1):
        extra[f"eta0_{k}"] = 0.0
        for i in range(1, sc.N + 1):
            extra[f"eta{i}_{k}"] = df[f"eta0_{k - 2}"] * 0.0
            extra[f"eeta{i}_{k}"] = 0.0
    return df.assign(**extra)


@pytest.mark.parametrize("path", sorted((PAPER.parent).glob("*.toml")), ids=lambda p: p.name)
def test_every_row_a_derivation_gives_exists_or_says_why(path):
    from core.scenario import load_scenario

    sc = load_scenario(path)
    tb = bounds_table(sc, _frame_for(sc))
    for i in range(sc.N):
        rows = tb[tb["agent"] == str(i + 1)]
        count = rows["claim_id"].value_counts()
        k = len(follower_pieces(sc, i))  # one set of provable rows per interval
        want = {
            CL.T2_CHI_PAPER.id: 1,
            CL.T2_E_PAPER.id: sc.n,
            CL.LEMMA2_PAPER.id: sc.n,
            CL.LEMMA1_PAPER.id: 1,
            CL.DEF1_PAPER.id: 1,
            CL.T2_CHI.id: k,
            CL.T2_E.id: sc.n * k,
            CL.DEF1_DERIVED.id: k,
        }
        assert {c: int(count.get(c, 0)) for c in want} == want, (path.name, i + 1)
    empty = tb[tb["holds"].isna()]
    assert (empty["kind"] == "info").all()
    assert empty["note"].str.match(r"not evaluated: \S").all()


# ------------------------------------------------------------------------- zero bounds
def test_zero_bounds_are_asymptotic_claims_and_the_sentence_counts_the_rows(paper_scenario):
    from verify.report import paper_t2_sentence
    from verify.rows import held_mask
    from verify.synthetic import synthetic_trajectory

    sc = paper_scenario
    sc0 = replace(sc, followers=tuple(replace(fo, d=np.zeros(sc.n)) for fo in sc.followers))
    df = synthetic_trajectory()
    tb = bounds_table(sc0, df)
    rows = tb[tb["claim_id"].isin([CL.T2_CHI_PAPER.id, CL.T2_E_PAPER.id])]
    assert len(rows) == sc.N * (1 + sc.n) and (rows["bound"] == 0).all()
    assert rows["note"].str.startswith("asymptotic claim (bound 0").all()
    assert rows["holds"].all()  # the synthetic errors decay exponentially
    text = paper_t2_sentence(rows)
    assert f"{len(rows)} rows have bound 0" in text and f"of which {len(rows)} decay" in text
    assert "positive bound" not in text  # no ratio is taken over NaN
    # errors that stop decaying on the tail: the asymptotic claim fails
    flat = df.copy()
    t = flat["t"].to_numpy()
    for i in range(sc.N):
        for r in range(sc.n):
            flat[f"chi{i + 1}_{r + 1}"] = 0.1 * (1 + (t > 15))
            flat[f"et{i + 1}_{r + 1}"] = 0.1 * (1 + (t > 15))
    rows = bounds_table(sc0, flat)
    rows = rows[rows["claim_id"].isin([CL.T2_CHI_PAPER.id, CL.T2_E_PAPER.id])]
    assert not rows["holds"].any()
    n_held = int(held_mask(rows).sum())
    assert f"of which {n_held} decay" in paper_t2_sentence(rows)


# ------------------------------------------------------------------------- faults
@pytest.fixture(scope="module")
def faults_run(tmp_path_factory):
    """scenarios/faults-example.toml (5 s): abrupt, ramp, intermittent faults and a bias."""
    from generated import api
    from verify.pipeline import Run, verify_run

    path = PAPER.parent / "faults-example.toml"
    root = tmp_path_factory.mktemp("out")
    res = api.run(path, out_root=root, progress=False)
    sc = api.load(path)
    v = verify_run(Run(sc, res.frame, res.trajectory.x, res.meta, root), out_root=root)
    return sc, res, v


def test_the_ramp_term_is_dV2_dt_and_eq38_holds_with_it(faults_run):
    """Follower 2's ramp (g from 0.95 to 0.71 over [0.2, 3.2] s): ∂V2/∂t at a fixed state,
    by central differences of the closed loop's V2 output in t, is (ġ/(2γ))(ĝ² − 1/g²), the
    term (38) adds; with it (38) holds at every output time."""
    from verify.lyapunov import (
        closed_loop,
        evaluate_p,
        fast_functions,
        health_at,
        state_block,
        theorem2_rhs,
    )

    sc, res, v = faults_run
    assert failures(v.table).empty
    cl = closed_loop(sc, v.gains)
    t, X = res.trajectory.t, res.trajectory.x
    fns = fast_functions(cl, "test-ramp")
    _, Vd, chi = evaluate_p(fns, "V2", t, X, cl.p0)
    i = 1  # not pinned: χ_2 does not depend on t at a fixed state
    g, gdot = health_at(sc, i, t)
    ramp = (t > 0.25) & (t < 3.15)
    np.testing.assert_allclose(gdot[ramp], -0.95 * 0.25 / 3.0, rtol=1e-9)
    assert np.all(gdot[t > 3.3] == 0.0)
    gh = state_block(cl, X, ("ghat", i))[:, 0]
    gam = float(sc.controller.gamma[i])
    k = np.flatnonzero(ramp)[::40]
    h = 1e-5
    Vp = evaluate_p(fns, "V2", t[k] + h, X[k], cl.p0)[0][:, i, 0]
    Vm = evaluate_p(fns, "V2", t[k] - h, X[k], cl.p0)[0][:, i, 0]
    want = gdot[k] / (2 * gam) * (gh[k] ** 2 - 1 / g[k] ** 2)
    np.testing.assert_allclose((Vp - Vm) / (2 * h), want, rtol=1e-5)
    assert np.abs(want).min() > 0.1  # a term of size, not round-off
    th = state_block(cl, X, ("thetahat", i))
    rhs, scale = theorem2_rhs(sc, i, chi[:, i, :], th, gh, g, gdot)
    lhs = Vd[:, i, 0]
    assert np.all(lhs - rhs <= 1e-7 * (scale + np.abs(lhs)))


def test_fault_rows_are_per_follower_and_per_interval(faults_run):
    sc, _, v = faults_run
    tb = v.table
    for i in range(sc.N):
        pieces = follower_pieces(sc, i)
        chi = tb[(tb["agent"] == str(i + 1)) & (tb["claim_id"] == CL.T2_CHI_ENV.id)]
        assert len(chi) == len(pieces)  # one envelope row per interval, each evaluated
        assert (chi["kind"] == "guaranteed").all() and chi["holds"].all()
    # the ramp's interval carries the health-rate term in its constants
    ramp = tb[(tb["agent"] == "2") & (tb["claim_id"] == CL.T2_CHI.id)]
    notes = " ".join(ramp["note"])
    assert "health ramp start/end at t = 0.2 s" in notes


# ------------------------------------------------------------------------- headline
def test_the_headline_never_says_a_bare_pass_without_tracking_rows(paper_scenario):
    from verify.headline import coverage, headline_lines, run_numbers, verdict
    from verify.synthetic import synthetic_trajectory
    from verify.table import gauge

    sc = paper_scenario
    df = synthetic_trajectory()
    tb = bounds_table(sc, df)
    head = headline_lines(tb, [])
    assert head[0].startswith("PASS: all ") and len(head) == 1 + sc.N
    off = replace(sc, options=replace(sc.options, feedforward=False))  # (38) not guaranteed
    tb_off = bounds_table(off, df)
    line = verdict(tb_off, coverage(tb_off, (0.0, 20.0)))
    assert line.startswith("PASS WITH GAPS") and "follower(s) 1, 2, 3, 4, 5" in line
    # the three numbers, against the synthetic signals computed here
    nums = run_numbers(sc, df, gauge(sc), 0.5, 1.0)
    t = df["t"].to_numpy()
    tail = t >= 10.0 - 1e-9
    et = [np.hypot(df[f"et{i}_1"], df[f"et{i}_2"]).to_numpy() for i in range(1, sc.N + 1)]
    best = max(range(sc.N), key=lambda i: et[i][tail].max())
    assert nums[1].agent == best + 1 and nums[1].value == pytest.approx(et[best][tail].max())
    assert nums[1].t == pytest.approx(t[tail][np.argmax(et[best][tail])])
    assert nums[2].what == "peak |u_i| after t = 1 s" and nums[2].window[0] == pytest.approx(1.0)
    # a start-up longer than the horizon: the whole run, and the label says so
    whole = run_numbers(sc, df, gauge(sc), 0.5, 1e3)[2]
    assert whole.window[0] == 0.0 and "over the run (horizon shorter than 1000 s)" in whole.text()
    # a failing row: FAIL, with the count
    bad = tb.copy()
    k = bad.index[bad["kind"] == "guaranteed"][0]
    bad.loc[k, "holds"] = False
    assert verdict(bad, coverage(bad, (0.0, 20.0))).startswith("FAIL: 1 check(s) failed")


# ------------------------------------------------------------------------- last interval
def test_covered_at_the_ultimate_level_on_the_last_interval(step_run):
    """verify.headline.ultimate_from: the followers not restarted are covered from their own
    comparison-lemma time on; follower 1, restarted by the step at 14 s with t_c beyond the
    horizon, is not, although its first interval's rows all hold."""
    from verify.headline import ultimate_from

    sc, gains, res, v = step_run
    tb, t1 = v.table, float(res.frame["t"].iloc[-1])
    assert math.isnan(ultimate_from(tb, 1, t1))
    for a in range(2, 6):
        chi = tb[(tb["agent"] == str(a)) & (tb["claim_id"] == CL.T2_CHI.id)]
        assert len(chi) == 1 and bool(chi["holds"].iloc[0])
        assert ultimate_from(tb, a, t1) == pytest.approx(float(chi["t_start"].iloc[0]))
        assert ultimate_from(tb, a, t1) < t1


def test_the_last_interval_is_not_covered_on_a_wrong_trajectory_or_a_short_horizon(step_run):
    from verify.headline import ultimate_from

    sc, gains, res, _ = step_run
    dep = np.array([True, False, False, False, False])
    t1 = float(res.frame["t"].iloc[-1])
    # follower 3 logged 10 m off its slot on the last 2 s: its derived Definition 1 row
    # fails, so its last interval is not covered (the others still are)
    df = res.frame.copy()
    df.loc[df["t"] >= t1 - 2.0, ["p3_1", "p3_2"]] += 10.0
    tb = bounds_table(sc, df, gains=gains, u0_dep=dep)
    assert math.isnan(ultimate_from(tb, 3, t1)) and math.isfinite(ultimate_from(tb, 2, t1))
    # a horizon of 8 s ends before every comparison-lemma time of the paper's gains
    short = res.frame[res.frame["t"] <= 8.0].reset_index(drop=True)
    tb = bounds_table(sc, short, gains=gains, u0_dep=dep)
    assert all(math.isnan(ultimate_from(tb, a, 8.0)) for a in range(1, 6))
