"""Runtime parameters of the closed loop (symbolic/parameters.py, Built.bind).

Independent truths: the hand-written numpy closed loop (verify/reference.py) of the
scenario with the new numbers, and CasADi's serialization of the generated Functions
(equal structure keys must mean equal code).
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER

from core.graph import weights_at
from generated import api
from generated.values import CodegenSettings
from symbolic.closed_loop import bind, build_closed_loop
from symbolic.parameters import layout_of, param_values, structure_key
from verify.reference import Reference

#: other numbers, same structure: controller, formation, observer, faults, operator
NUMBERS = {
    "controller.k1": 23.0,
    "controller.Lambda": 31.0,
    "controller.sigma": 0.5,
    "observer.alpha1": 1.7,
    "observer.phi_min": 0.02,
    "followers[2].b0": [1.5, 3.0],
    "followers[3].g": 0.8,
    "followers[1].f": ["3*sin(3*t) + 0.5", "2*sin(2*t) + 1"],
    "leader.u0": ["1.5*cos(t)"],
}


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    out = tmp_path_factory.mktemp("params")
    a = api.load(PAPER)
    b = api.load(PAPER, overrides=NUMBERS, variant="numbers")
    ga, _ = api.ensure_gains(a, out)
    gb, _ = api.ensure_gains(b, out)
    return a, ga, b, gb, build_closed_loop(a, ga)


def states(cl, rng, k=4):
    return [cl.x0 + 0.5 * rng.standard_normal(cl.x0.size) for _ in range(k)]


def test_numbers_are_not_structure(pair):
    a, ga, b, gb, _ = pair
    assert structure_key(a, ga) == structure_key(b, gb)
    assert layout_of(a) == layout_of(b)
    assert not np.array_equal(param_values(a, ga), param_values(b, gb))


def test_bound_loop_is_the_reference_of_the_other_numbers(pair):
    a, ga, b, gb, cl_a = pair
    cl_b = bind(cl_a.parametric, b, gb)
    ref = Reference(b, gb)
    rng = np.random.default_rng(3)
    for t in (0.0, 0.7, 3.1):
        for x in states(cl_b, rng):
            got = np.array(cl_b.ode(t, x)).ravel()
            want = ref.rhs(t, x)
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))
    # and x(0) is b's: its own positions, not a's
    np.testing.assert_array_equal(cl_b.layout.get(cl_b.x0, "p", 1), b.followers[1].p0)


def test_the_sign_of_a_number_is_not_structure(pair, tmp_path):
    # a study that draws signed sizes (operator steps, biases) shares one library
    a, ga, _, _, cl_a = pair
    flipped = {
        "leader.u0": ["-1.5*cos(t)"],
        "followers[1].f": ["-3*sin(3*t) + 0.5", "4*sin(-2*t) + -1"],
    }
    c = api.load(PAPER, overrides=flipped, variant="signs")
    gc, _ = api.ensure_gains(c, tmp_path)
    assert structure_key(c, gc) == structure_key(a, ga)
    cl_c = bind(cl_a.parametric, c, gc)
    ref = Reference(c, gc)
    rng = np.random.default_rng(5)
    for t in (0.0, 0.7, 3.1):
        for x in states(cl_c, rng, k=2):
            want = ref.rhs(t, x)
            got = np.array(cl_c.ode(t, x)).ravel()
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))


def test_equal_keys_mean_equal_code(pair):
    a, ga, b, gb, cl_a = pair
    cl_b = build_closed_loop(b, gb)
    for name in ("ode", "outputs", "dae_dyn"):
        fa = getattr(cl_a.parametric, name).expand()
        fb = getattr(cl_b.parametric, name).expand()
        assert fa.serialize() == fb.serialize(), name


@pytest.mark.parametrize(
    "change",
    [
        {"options.sign": "sat"},
        {"followers[2].g": "0.9 - 0.1*step(t - 5)"},
        {"leader.u0": ["2*sin(t)"]},
        {"graph.pinning": [1.0, 1.0, 0.0, 0.0, 0.0]},
    ],
)
def test_structure_changes_change_the_key(pair, change, tmp_path):
    a, ga, *_ = pair
    c = api.load(PAPER, overrides=change, variant="structure")
    gc, _ = api.ensure_gains(c, tmp_path)
    assert structure_key(c, gc) != structure_key(a, ga)
    with pytest.raises(Exception, match="structure"):
        bind(pair[4].parametric, c, gc)


def test_switching_weights_follow_the_topology(tmp_path):
    sw = [
        {"time": 0.3, "follower": 4, "neighbour": 2, "weight": 0.0},
        {"time": 0.6, "follower": 4, "neighbour": 2, "weight": 1.0},
    ]
    ov = {"graph.switches": sw, "graph.link_fade": 0.0}  # raw switching (fades: test_link_fade)
    sc = api.load(PAPER, overrides=ov, variant="switch")
    gains, _ = api.ensure_gains(sc, tmp_path)
    cl = build_closed_loop(sc, gains)
    names = cl.outputs.name_out()
    C0 = np.asarray(sc.leader.C0)
    x = cl.x0 + np.random.default_rng(1).standard_normal(cl.x0.size)
    E = np.array([cl.layout.get(x, "eta", i) for i in range(sc.N)]).T
    psis = []
    for t in (0.1, 0.3 - 1e-9, 0.3, 0.45, 0.6, 0.9):
        o = dict(zip(names, cl.outputs(t, x), strict=True))
        LB, a0h = weights_at(sc.graph, t)  # numpy: the topology holding at t
        want = C0 @ E @ LB.T - np.outer(np.array(o["y0"]).ravel(), a0h)
        np.testing.assert_allclose(np.array(o["psi"]).T, want, rtol=1e-13, atol=1e-12)
        psis.append(np.array(o["psi"]))
    assert not np.allclose(psis[1], psis[2])  # the cut is felt from 0.3 s on
    np.testing.assert_allclose(psis[0], psis[4])  # restored at 0.6 s


def test_a_second_scenario_reuses_the_compiled_library(pair, tmp_path):
    """The whole loop's library takes p (method ``cvodes``; the per-agent engine of
    ``native`` compiles the gains and u0's numbers into its kernels)."""
    a, ga, b, gb, _ = pair
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path / "build"))
    first = api.build(a, ga, "cvodes", cg)
    second = api.build(b, gb, "cvodes", cg)
    assert second.library.path == first.library.path
    assert second.timings["codegen"] == second.timings["compile"] == 0.0
    ref = Reference(b, gb)
    rng = np.random.default_rng(5)
    for x in states(second.closed_loop, rng, 2):
        got = np.array(second.dyn(0.4, x, [], [], [])[0]).ravel()
        want = ref.rhs(0.4, x)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))
    tr = api.simulate(second, b, api.integrator_settings(b, "cvodes"))
    assert tr.complete


#: other graphs of the paper's N: a link lost and restored (raw switching); another graph
#: (a cycle 5 -> 1 and a second pinned follower) with the pinning of follower 2 lost and
#: restored through the fade
OTHER_GRAPHS = {
    "lost-restored": {
        "graph.switches": [
            {"time": 0.3, "follower": 4, "neighbour": 2, "weight": 0.0},
            {"time": 0.6, "follower": 4, "neighbour": 2, "weight": 1.0},
        ],
        "graph.link_fade": 0.0,
    },
    "cycle-faded": {
        "graph.adjacency": [
            [0.0, 0.0, 0.0, 0.0, 0.5],
            [1.0, 0.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0, 0.0],
        ],
        "graph.pinning": [1.0, 2.0, 0.0, 0.0, 0.0],
        "graph.switches": [
            {"time": 0.3, "follower": 2, "neighbour": 0, "weight": 0.0},
            {"time": 0.6, "follower": 2, "neighbour": 0, "weight": 2.0},
        ],
        "graph.link_fade": 0.2,
    },
}


@pytest.mark.parametrize("name", sorted(OTHER_GRAPHS))
def test_the_graph_as_data_is_the_graphs_own_loop(pair, name, tmp_path):
    # one structure serves every graph of N followers: the dense loop built for the paper's
    # graph, bound to another graph with switches, is that graph's own (sparse) loop, the
    # same numbers at every time (before, at, inside and after the switches) and state
    from generated.csource import expanded
    from verify.lyapunov import _derivative_p

    a, ga, *_ = pair
    b = api.load(PAPER, overrides=OTHER_GRAPHS[name], variant=name)
    gb, _ = api.ensure_gains(b, tmp_path)
    assert structure_key(b, gb) != structure_key(a, ga)
    assert structure_key(b, gb, dense=True) == structure_key(a, ga, dense=True)
    dense = bind(build_closed_loop(a, ga, dense=True).parametric, b, gb)
    own = build_closed_loop(b, gb)
    np.testing.assert_array_equal(dense.x0, own.x0)
    V = [
        _derivative_p(expanded(c.parametric.outputs), expanded(c.parametric.ode))
        for c in (dense, own)
    ]
    rng = np.random.default_rng(7)
    for t in (0.0, 0.3 - 1e-9, 0.3, 0.41, 0.6, 0.75, 2.0):
        for x in states(own, rng, k=2):
            for f, g in ((dense.ode, own.ode), (dense.outputs, own.outputs)):
                for u, v in zip(f.call([t, x]), g.call([t, x]), strict=True):
                    np.testing.assert_array_equal(np.array(u), np.array(v))
            for u, v in zip(V[0].call([t, x, dense.p0]), V[1].call([t, x, own.p0]), strict=True):
                np.testing.assert_array_equal(np.array(u), np.array(v))
