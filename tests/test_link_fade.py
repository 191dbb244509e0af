"""Link losses with fading weights (``graph.link_fade``; docs/verification.md, 'Link losses').

Independent truths: the fade's polynomial and its derivatives against central differences;
the weights at a time inside a fade against the convex combination of the hand-built
L + B of the paper graph with a link cut; the oracle's η̈_i (which takes the weights' rates)
against a central difference of η̇_i along the flow (t, x(t)); the compiled vector field
against the numpy reference (verify/reference.py: its own chain rule); a link lost and
restored run by the native driver and by CVODES through CasADi; and the kick of raw
switching (torques above 1e5) that the fade removes.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_switching import LB_BASE, LB_CUT, PIN, paper_with

from core.graph import DEFAULT_LINK_FADE, fade_jets, weights_at
from core.scenario import load_scenario

pytestmark = pytest.mark.slow  # the run fixtures compile and integrate

# follower 4 loses follower 2 at 1.5 s and hears it again from 2.2 s (3 s runs)
LOSS = [(1.5, 4, 2, 0.0), (2.2, 4, 2, 1.0)]
SHORT = "horizon = 20.0 => horizon = 3.0"


def test_fade_is_C2_with_its_derivatives():
    x = np.linspace(-0.2, 1.2, 1401)
    s, ds, dds = fade_jets(x)
    assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) >= 0)
    h = 1e-6
    for f, df in ((0, ds), (1, dds)):
        fd = (fade_jets(x + h)[f] - fade_jets(x - h)[f]) / (2 * h)
        np.testing.assert_allclose(df, fd, atol=1e-4)  # O(h) at the ends, where σ‴ jumps
    # σ' and σ'' vanish at both ends: the weights' rates are continuous through a switch
    for end in (0.0, 1.0):
        assert fade_jets(end)[1] == 0.0 and fade_jets(end)[2] == 0.0


def test_weights_fade_between_the_hand_built_topologies(tmp_path):
    sc = load_scenario(paper_with(tmp_path, [(5.0, 4, 2, 0.0), (10.0, 4, 2, 1.0)], fade=2.0))
    assert load_scenario(paper_with(tmp_path, LOSS, SHORT, fade=None)).graph.link_fade == (
        DEFAULT_LINK_FADE
    )
    for t, c in ((4.0, 0.0), (5.0, 0.0), (5.5, 0.103515625), (6.0, 0.5), (7.0, 1.0), (9.9, 1.0)):
        L, a = weights_at(sc.graph, t)
        np.testing.assert_allclose(L, (1 - c) * LB_BASE + c * LB_CUT, atol=1e-15)
        np.testing.assert_allclose(a, PIN, atol=0)
    np.testing.assert_allclose(weights_at(sc.graph, 11.0)[0], LB_CUT + (LB_BASE - LB_CUT) * 0.5)
    # the rates: central differences of the weights
    h = 1e-5
    for t in (5.3, 6.0, 6.9, 10.4):
        for d in (1, 2):
            fd = (weights_at(sc.graph, t + h, d - 1)[0] - weights_at(sc.graph, t - h, d - 1)[0]) / (
                2 * h
            )
            np.testing.assert_allclose(weights_at(sc.graph, t, d)[0], fd, atol=1e-5)
    # raw switching: the topology that holds, no rates
    raw = load_scenario(paper_with(tmp_path, [(5.0, 4, 2, 0.0), (10.0, 4, 2, 1.0)], fade=0.0))
    np.testing.assert_array_equal(weights_at(raw.graph, 5.0)[0], LB_CUT)
    assert not weights_at(raw.graph, 5.0, 1)[0].any()


@pytest.fixture(scope="module")
def faded(tmp_path_factory):
    from symbolic.closed_loop import build_closed_loop
    from verify.reference import Reference, hand_gains

    tmp = tmp_path_factory.mktemp("fade")
    sc = load_scenario(paper_with(tmp, [(5.0, 4, 2, 0.0), (5.5, 4, 2, 1.0)], fade=1.0))
    g = hand_gains(sc)
    return sc, build_closed_loop(sc, g), Reference(sc, g)


def _state(cl, rng):
    lay = cl.layout
    x = cl.x0 + rng.normal(size=lay.nx)
    for i in range(lay.N):  # inside the adaptive states' domains
        x[lay.slices[("phi", i)]] = rng.uniform(0.05, 1.0)
        x[lay.slices[("ghat", i)]] = rng.uniform(1.0, 2.0)
        x[lay.slices[("thetahat", i)]] = rng.uniform(0.0, 3.0, 2)
    return x


def test_faded_vector_field_is_the_numpy_reference(faded):
    sc, cl, ref = faded
    lay = cl.layout
    rng = np.random.default_rng(11)
    # before, inside both overlapping fades (the restore starts before the loss has faded),
    # after both
    for t in (4.9, 5.2, 5.7, 6.2, 7.0):
        x = _state(cl, rng)
        got, want = np.asarray(cl.ode(t, x)).ravel(), ref.rhs(t, x)
        for name in lay.agent_offsets:
            idx = np.concatenate([np.arange(lay.nx)[lay.slices[(name, i)]] for i in range(lay.N)])
            scale = max(np.abs(want[idx]).max(), 1.0)
            assert np.abs(got[idx] - want[idx]).max() <= 1e-10 * scale, (t, name)


def test_oracle_derivatives_are_the_time_derivatives_along_the_flow_in_a_fade(faded):
    """η̈_i and η⃛_i (eq. (29)'s feed-forward) = d/dt of η̇_i, η̈_i along (t, x(t)), weights' rates included."""
    sc, cl, _ = faded
    names = cl.outputs.name_out()
    rng = np.random.default_rng(3)
    x = _state(cl, rng)
    for k in range(sc.N):  # a converged-looking observer: every φ at 0.5, η_i near η0
        x[cl.layout.slices[("phi", k)]] = 0.5

    def out(t, xx, name):
        return np.asarray(cl.outputs(t, xx)[names.index(name)])

    t, h = 5.4, 1e-6
    f = np.asarray(cl.ode(t, x)).ravel()
    for lo, hi in (("etadot", "etaddot"), ("etaddot", "eta3dot")):
        fd = (out(t + h, x + h * f, lo) - out(t - h, x - h * f, lo)) / (2 * h)
        got = out(t, x, hi)
        scale = np.abs(got).max()
        assert np.abs(got - fd).max() <= 1e-5 * scale, (hi, np.abs(got - fd).max(), scale)
    # the weights' rate term is not negligible here: without it follower 4's ψ̇ differs
    Ld, ad = weights_at(sc.graph, t, 1)
    S = _ref_split(faded, x)
    C0 = np.asarray(sc.leader.C0, float)
    term = Ld @ S["eta"] @ C0.T - np.outer(ad, C0 @ S["eta0"])
    assert np.abs(term[3]).max() > 1e-3


def _ref_split(faded, x):
    return faded[2].split(x)


@pytest.fixture(scope="module")
def loss_runs(tmp_path_factory):
    from generated import api

    tmp = tmp_path_factory.mktemp("loss-runs")
    runs = {}
    for key, fade, method in (
        ("raw", 0.0, "native"),
        ("fade", 0.5, "native"),
        ("fade-cvodes", 0.5, "cvodes"),
    ):
        (tmp / key).mkdir()
        path = paper_with(tmp / key, LOSS, SHORT, fade=fade)
        runs[key] = api.run(path, out_root=tmp / key / "out", progress=False, method=method)
    return runs


def _peak_u(frame, since: float) -> float:
    t = frame["t"].to_numpy()
    w = t >= since
    return max(
        float(np.linalg.norm(frame[[f"u{i}_1", f"u{i}_2"]].to_numpy()[w], axis=1).max())
        for i in range(1, 6)
    )


def test_a_lost_and_restored_link_kicks_raw_switching_and_not_the_fade(loss_runs):
    assert all(r.meta["complete"] for r in loss_runs.values())
    raw, fade = _peak_u(loss_runs["raw"].frame, 1.5), _peak_u(loss_runs["fade"].frame, 1.5)
    before = _peak_u(loss_runs["raw"].frame.query("t < 1.5"), 1.0)
    assert raw > 1e5 and fade < 5 * before < 1e3, (raw, fade, before)


def test_native_and_cvodes_agree_through_a_fade(loss_runs):
    a, b = loss_runs["fade"].frame, loss_runs["fade-cvodes"].frame
    t = a["t"].to_numpy()
    w = t >= 1.0
    for block, rel in (("p", 2e-4), ("eta", 1e-6)):
        cols = [
            c for c in a.columns if c.startswith(block) and c[len(block) : len(block) + 1].isdigit()
        ]
        x, y = a[cols].to_numpy()[w], b[cols].to_numpy()[w]
        scale = np.abs(y).max()
        assert np.abs(x - y).max() <= rel * scale, (block, np.abs(x - y).max(), scale)
    # and the comparison can see a difference of models: raw switching is far from both
    r = loss_runs["raw"].frame
    cols = [c for c in a.columns if c.startswith("p") and c[1:2].isdigit()]
    assert np.abs(r[cols].to_numpy()[w] - b[cols].to_numpy()[w]).max() > 100 * 2e-4 * 25


def test_switch_recoveries_of_every_follower(loss_runs, tmp_path):
    from verify.link_recovery import peak_u_late, switch_recoveries, switch_summary
    from verify.operator_steps import deviation

    run = loss_runs["fade"]
    sc = load_scenario(paper_with(tmp_path, LOSS, SHORT, fade=0.5))
    h = np.ones(sc.N)
    items = switch_recoveries(sc, run.frame, h)
    assert [(r.start, r.end) for r in items[:: sc.N]] == [(1.5, 2.2), (2.2, 3.0 + 1e-12)]
    assert [r.follower for r in items] == list(range(sc.N)) * 2
    t = run.frame["t"].to_numpy()
    dev = deviation(sc, run.frame, h)
    for r in items:  # the recovery time by hand: the last output time above 0.05, plus one step
        w = (t >= r.start) & (t < r.end)
        above = np.flatnonzero(dev[w, r.follower] > 0.05)
        want = (
            0.0
            if not above.size
            else t[w][above[-1] + 1] - r.start
            if above[-1] + 1 < w.sum()
            else np.inf
        )
        assert r.time == pytest.approx(want)
        assert r.outcome == (
            "recovered" if want <= 2.0 else "undefined" if np.isinf(want) else "late"
        )
    s = switch_summary(items)
    assert s["switch_pairs"] == 10 and s["switch_pairs_late"] + s["switch_pairs_undefined"] <= 10
    assert peak_u_late(run.frame, sc.N, sc.n) == pytest.approx(_peak_u(run.frame, 1.0))


def test_V2_is_continuous_through_a_faded_switch_and_jumps_raw(faded, tmp_path):
    """Theorem 2's comparison lemma needs V2_i absolutely continuous ('Link losses', item 3)."""
    from symbolic.closed_loop import build_closed_loop
    from verify.reference import hand_gains

    sc, cl, _ = faded
    raw_sc = load_scenario(paper_with(tmp_path, [(5.0, 4, 2, 0.0), (5.5, 4, 2, 1.0)], fade=0.0))
    raw = build_closed_loop(raw_sc, hand_gains(raw_sc))
    x = _state(cl, np.random.default_rng(5))
    k = cl.outputs.name_out().index("V2")
    for loop, jumps in ((cl, False), (raw, True)):
        before = np.asarray(loop.outputs(5.0 - 1e-12, x)[k]).ravel()
        at = np.asarray(loop.outputs(5.0, x)[k]).ravel()
        assert np.allclose(before[[0, 1, 2]], at[[0, 1, 2]], rtol=1e-12)  # not downstream
        if jumps:
            assert abs(at[3] - before[3]) > 1e-3 * abs(before[3])  # follower 4 loses follower 2
        else:
            np.testing.assert_allclose(at, before, rtol=1e-9)


def test_switches_made_no_ops_run_the_graph_without_losses(tmp_path):
    """The study's no-loss baseline (sweep.worker.link_baseline) is the run without switches."""
    from generated import api

    noop = [(t, i, j, 1.0) for t, i, j, _ in LOSS]  # each switch sets the base weight a_42 = 1
    runs = {}
    for key, sw in (("noop", noop), ("none", [])):
        (tmp_path / key).mkdir()
        path = paper_with(tmp_path / key, sw, SHORT, fade=0.5)
        runs[key] = api.run(path, out_root=tmp_path / key / "out", progress=False).frame
    cols = [c for c in runs["none"].columns if c[:1] in "pu" and c[1:2].isdigit()]
    a, b = runs["noop"][cols].to_numpy(), runs["none"][cols].to_numpy()
    assert np.abs(a - b).max() <= 1e-5 * np.abs(b).max()
