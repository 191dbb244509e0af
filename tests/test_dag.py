"""The closed loop in graph order (symbolic/cascade.py, generated/dag.py, native/dag.c).

Independent truths: the whole closed loop built by symbolic/closed_loop.py (its
right-hand side, and its Jacobian by CasADi's AD with numpy's dense solve for the
Newton systems), the whole-loop native integrator, and the definition of a topological
order.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from benchmarks.scenarios import bench_gains, bench_scenario
from core.errors import IntegrationError, ScenarioError
from generated import api, dag
from generated.schedule import output_grid
from generated.values import CodegenSettings, IntegratorSettings
from symbolic.cascade import build_cascade, topological_order
from symbolic.closed_loop import build_closed_loop

N = 6  # random acyclic benchmark graph: depth 3, pinned and unpinned followers


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    sc = bench_scenario(N, horizon=0.3)
    gains = bench_gains(sc)[0]
    cl = build_closed_loop(sc, gains)
    cas = build_cascade(sc, gains)
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path_factory.mktemp("dag")))
    lib = dag.build(cas, cg)
    return sc, gains, cl, cas, cg, lib


def test_topological_order_and_cycles():
    A = np.zeros((5, 5))
    A[1, 0] = A[2, 1] = A[3, 0] = A[3, 2] = A[4, 3] = 1.0  # i hears j when A[i, j] != 0
    order = topological_order(A)
    pos = {int(i): k for k, i in enumerate(order)}
    for i, j in zip(*np.nonzero(A), strict=True):
        assert pos[int(j)] < pos[int(i)]  # every follower after the ones it hears
    assert sorted(order.tolist()) == list(range(5))
    A[0, 4] = 1.0  # 0 -> 1 -> 2 -> 3 -> 4 -> 0
    with pytest.raises(ScenarioError, match="graph.adjacency") as ei:
        topological_order(A, "s.toml")
    msg = str(ei.value)
    assert "\n" not in msg and "cycle" in msg and "'cvodes'" in msg and msg.startswith("s.toml")


def test_different_models_are_refused(setup):
    sc, gains, *_ = setup
    fo = sc.followers[1]
    other = dataclasses.replace(fo, params={**fo.params, next(iter(fo.params)): 9.0})
    sc2 = dataclasses.replace(sc, followers=(sc.followers[0], other, *sc.followers[2:]))
    with pytest.raises(ScenarioError, match="followers.model") as ei:
        build_cascade(sc2, gains)
    assert "\n" not in str(ei.value) and "'cvodes'" in str(ei.value)


@pytest.mark.parametrize("derivatives", ["oracle", "filtered"])
def test_blocks_in_order_are_the_whole_closed_loop(setup, derivatives):
    """Python: the blocks fed their neighbours' exact jets give the closed loop's RHS."""
    sc, gains, cl, cas, _, _ = setup
    if derivatives != sc.options.derivatives:
        sc = dataclasses.replace(
            sc, options=dataclasses.replace(sc.options, derivatives=derivatives)
        )
        cl, cas = build_closed_loop(sc, gains), build_cascade(sc, gains)
    lay = cas.layout
    m, na, n = lay.m, lay.agent_size, cas.n
    rng = np.random.default_rng(3)
    for t in (0.0, 0.7, 2.3):
        x = cl.x0 + rng.normal(scale=0.3, size=cl.x0.size)
        xd = np.array(cl.ode(t, x)).ravel()
        fv = np.array(cas.faults(t)).ravel()
        jets = {}
        for i in cas.order:
            nb = np.zeros(3 * n)
            for k in range(cas.upstream_ptr[i], cas.upstream_ptr[i + 1]):
                nb += cas.upstream_weight[k] * jets[cas.upstream_idx[k]]
            xb = np.concatenate([x[:m], x[m + i * na : m + (i + 1) * na]])
            out = cas.block(t, xb, nb, cas.coupling[i], cas.params[:, i], fv[cas.fault_index[i]])
            jets[i] = np.array(out[1]).ravel()
            ref = np.concatenate([xd[:m], xd[m + i * na : m + (i + 1) * na]])
            np.testing.assert_allclose(np.array(out[0]).ravel(), ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("gamma", [1e-4, 1e-2, 0.3])
def test_driver_rhs_and_newton_solve_against_the_whole_loop(setup, gamma):
    """C: one pass is cl.ode; block forward substitution solves (I − γJ) with J by AD."""
    _, _, cl, cas, _, lib = setup
    nx = cas.layout.nx
    rng = np.random.default_rng(int(1 / gamma))
    t = 0.45
    x = cl.x0 + rng.normal(scale=0.2, size=nx)
    b = rng.normal(size=nx)
    xdot, sol = dag.probe(lib.path, cas, t, x, gamma, b)
    ref = np.array(cl.ode(t, x)).ravel()
    np.testing.assert_allclose(xdot, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    tt, xx = ca.MX.sym("t"), ca.MX.sym("x", nx)
    J = np.array(ca.Function("J", [tt, xx], [ca.jacobian(cl.ode(tt, xx), xx)])(t, x))
    M = np.eye(nx) - gamma * J
    expected = np.linalg.solve(M, b)
    # the residual of the driver's solution in the dense system, relative to M's scale
    resid = np.abs(M @ sol - b).max() / (np.abs(M).max() * np.abs(sol).max())
    assert resid < 1e-12
    np.testing.assert_allclose(sol, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
    with pytest.raises(IntegrationError, match="entries"):
        dag.probe(lib.path, cas, t, x[:-1], gamma, b)


def test_run_converges_to_the_whole_loop_native_trajectory(setup):
    """Same integrator (CVODE BDF, exact Newton), another assembly: the same trajectory.

    The two differ by rounding, which the loop's start-up (|u| ~ 1e6 in the first 0.1 s)
    amplifies to the integrators' own error level; that difference must shrink with the
    tolerance (measured: 4.4e-4, 5.8e-5, 1.0e-6 at rtol 1e-7, 1e-9, 1e-11).
    """
    sc, gains, cl, cas, cg, lib = setup
    t_out = output_grid(0.3, 0.01)
    bps = sc.breakpoints()
    built = api.build(sc, gains, "native", cg, closed_loop=cl)  # N = 6: the whole loop
    assert built.dag is None
    diffs = []
    for rtol in (1e-9, 1e-11):
        s = IntegratorSettings(method="native", rtol=rtol, atol=rtol * 1e-2, max_steps=100000)
        tr = dag.run(lib.path, cas, cl.x0, t_out, s, breakpoints=bps)
        ref = api.integrate_built(built, cl.x0, t_out, s, bps)
        assert tr.complete and ref.complete and tr.method == "native"
        diffs.append((np.abs(tr.x - ref.x) / np.maximum(1.0, np.abs(ref.x))).max())
        # the same method takes about the same steps (they differ only by rounding)
        assert 0.8 < tr.stats["steps"] / ref.stats["steps"] < 1.25
        assert tr.stats["jac_evals"] < tr.stats["lin_setups"]  # CVODE reuses the Jacobian
        assert tr.stats["pivot_failures"] == 0
    assert diffs[1] < 1e-5 and diffs[1] < diffs[0] / 10


def test_native_above_20_needs_an_acyclic_graph(tmp_path):
    """N = 21 with a cycle: one line naming the fix, before any code is generated."""
    sc = bench_scenario(21, horizon=0.1)
    A = np.array(sc.graph.adjacency, dtype=float)
    A[0, 20] = 1.0  # follower 1 now hears follower 21, which hears back through the tree
    sc = dataclasses.replace(sc, graph=dataclasses.replace(sc.graph, adjacency=A))
    gains = bench_gains(sc)[0]
    cg = CodegenSettings(build_root=str(tmp_path / "b"))
    with pytest.raises(ScenarioError, match="cycle") as ei:
        api.build(sc, gains, "native", cg)
    assert "\n" not in str(ei.value) and "'cvodes'" in str(ei.value)
    assert not (tmp_path / "b").exists()


def test_breakpoints_faults_and_two_pinned_followers(tmp_path):
    """The two-follower test scenario (a fault switching at t = 0.3 s, both followers
    pinned, different fault expressions): graph order and whole loop converge together.

    Same integrator, another assembly: they differ by rounding, which the start-up
    transient amplifies to the integrators' own error level; that difference must shrink
    with the tolerance (measured 2026-12-01: 2.7e-5, 1.3e-4, 3.3e-6, 1.8e-7 at rtol 1e-8,
    1e-9, 1e-10, 1e-11 with atol = rtol/100).
    """
    from helpers import SMALL

    from synthesis import synthesize

    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    sc = api.load(path)
    assert sc.breakpoints() == (0.3,)
    gains = synthesize(sc)
    cl = build_closed_loop(sc, gains)
    cas = build_cascade(sc, gains)
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path / "b"))
    lib = dag.build(cas, cg)
    built = api.build(sc, gains, "native", cg, closed_loop=cl)
    t_out = output_grid(0.5, 0.01)
    diffs = []
    for rtol in (1e-9, 1e-11):
        s = IntegratorSettings(method="native", rtol=rtol, atol=rtol * 1e-2, max_steps=100000)
        tr = dag.run(lib.path, cas, cl.x0, t_out, s, breakpoints=sc.breakpoints())
        ref = api.integrate_built(built, cl.x0, t_out, s, sc.breakpoints())
        assert tr.complete and ref.complete
        assert tr.stats["restarts"] == ref.stats["restarts"] == 1
        diffs.append((np.abs(tr.x - ref.x) / np.maximum(1.0, np.abs(ref.x))).max())
    assert diffs[1] < 1e-6 and diffs[1] < diffs[0] / 10, diffs
