"""Breakpoints and output times (generated/schedule.py; every integrator uses it).

Independent truths: the properties a schedule must have (sorted, inside the horizon,
no two stops closer than the tolerance, every breakpoint a restart, every requested
output time kept), CVODE's own refusal criterion for an output time too close to the
current one (``|tout - t| < 2 eps max(|t|, |tout|)``, cvHin in cvode.c), the closed form
of a piecewise-constant right-hand side, and reaching the horizon: faults at 0.35, 0.57
and 0.7 s stopped the native integrator with TOO_CLOSE (the output grid's 0.7 is
0.7000000000000001, one rounding step after the restart at 0.7).
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from helpers import PAPER
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.errors import IntegrationError
from generated import api
from generated.built import Built
from generated.codegen import build_library
from generated.schedule import output_grid, schedule, time_tolerance
from generated.solvers.engine import integrate
from generated.values import CodegenSettings, IntegratorSettings

E = ca.SX(0, 1)
EPS = float(np.finfo(float).eps)
FAST = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------- strategies
@st.composite
def grids(draw, max_horizon: float = 50.0) -> np.ndarray:
    """An output grid as a user writes it: a decimal step dividing a decimal horizon."""
    step = draw(st.sampled_from([1e-3, 2e-3, 5e-3, 0.01, 0.02, 0.025, 0.05, 0.1, 0.125, 0.2]))
    n = draw(st.integers(1, min(2000, int(max_horizon / step))))
    return output_grid(round(n * step, 12), step)


@st.composite
def breakpoint_sets(draw, t_out: np.ndarray) -> list[float]:
    """Times that coincide with output times to rounding, cluster, or fall anywhere."""
    tf = float(t_out[-1])
    out = []
    for _ in range(draw(st.integers(0, 8))):
        kind = draw(st.sampled_from(["ulps", "decimal", "cluster", "any", "edge"]))
        tk = float(t_out[draw(st.integers(0, len(t_out) - 1))])
        if kind == "ulps":  # an output time moved by a few rounding steps
            b = tk
            for _ in range(abs(j := draw(st.integers(-4, 4)))):
                b = math.nextafter(b, math.inf if j > 0 else -math.inf)
        elif kind == "decimal":  # the same time written as a decimal literal
            b = float(f"{tk:.6g}")
        elif kind == "cluster":  # several within the tolerance of each other
            tol = time_tolerance(0.0, tf)
            b = tk + draw(st.floats(-3.0, 3.0)) * tol
            out.append(b + draw(st.floats(0.0, 1.0)) * tol)
        elif kind == "edge":  # at or just outside the ends of the run
            b = draw(st.sampled_from([0.0, tf, -1e-3, tf + 1e-3, 1e-15, tf * (1 - 1e-15)]))
        else:
            b = draw(st.floats(-0.1 * tf, 1.1 * tf, allow_nan=False))
        out.append(b)
    return out


@st.composite
def grid_and_breakpoints(draw, max_horizon: float = 50.0):
    t_out = draw(grids(max_horizon))
    return t_out, draw(breakpoint_sets(t_out))


# --------------------------------------------------------------------------- the schedule
@FAST
@given(grid_and_breakpoints())
def test_schedule_properties(case):
    t_out, bps = case
    s = schedule(t_out, bps)
    t0, tf, tol = float(t_out[0]), float(t_out[-1]), s.tol
    assert tol == 1000 * EPS * max(1.0, abs(t0), abs(tf))
    # rows keep exactly the requested times; each is integrated to within tol of it
    assert np.array_equal(s.t_out, t_out)
    assert s.targets[0] == t0 and s.targets[-1] == tf
    assert np.all(np.abs(s.targets - t_out) <= tol)
    # restarts: sorted, inside the run, each one of the given breakpoints
    br = s.breaks.tolist()
    assert br == sorted(br) and all(t0 + tol < b < tf - tol for b in br)
    assert set(br) <= set(bps)
    # every breakpoint inside the run is a restart, or within tol of a restart or an end
    for b in bps:
        if t0 < b < tf:
            assert min(abs(b - c) for c in [t0, tf, *br]) <= tol
    # a row's target is its time or a restart
    assert all(q == t or q in br for q, t in zip(s.targets, t_out, strict=True))
    # every stop of the run, in order: no two closer than tol, and CVODE would accept
    # each next time (cvHin: TOO_CLOSE when |tout - t| < 2 eps max(|t|, |tout|))
    stops = np.unique(np.concatenate([s.targets, s.breaks]))
    gaps = np.diff(stops)
    assert np.all(gaps > tol)
    assert np.all(gaps >= 2 * EPS * np.maximum(np.abs(stops[:-1]), np.abs(stops[1:])))
    # segments: every row once, in order, each in (start, end], ends = restarts + horizon
    segs = s.segments()
    assert [e for _, e, _ in segs] == [*br, tf]
    assert [k for _, _, rows in segs for k in rows] == list(range(1, len(t_out)))
    for start, end, rows in segs:
        assert all(start < s.targets[k] <= end for k in rows)


def test_schedule_merges_the_output_grid_with_a_fault_at_0_7():
    t_out = output_grid(2.0, 0.01)
    assert t_out[70] == 0.7000000000000001  # linspace's rounding: not the literal 0.7
    s = schedule(t_out, [0.7, 0.35, 0.57])
    assert s.breaks.tolist() == [0.35, 0.57, 0.7]
    assert s.targets[70] == 0.7 and s.t_out[70] == t_out[70]
    assert s.targets[35] == 0.35 and s.targets[57] == 0.57
    changed = np.flatnonzero(s.targets != t_out)
    assert set(changed) <= {35, 57, 70}


def test_schedule_refuses_output_times_below_the_resolution():
    with pytest.raises(IntegrationError, match="output_step") as ei:
        schedule(np.array([0.0, 1e-14, 1.0]))
    assert "\n" not in str(ei.value)


# --------------------------------------------------------------------------- closed form
def _jump_functions():
    """y' = 1 before b, -2 after; b is a state (b' = 0), so the jump time is a number of
    the run, not of the code: y = t, then b - 2 (t - b). DAE form: z = y'."""
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("z", 1)
    rate = ca.if_else(t < x[1], 1.0, -2.0)
    f_ode = ca.Function(
        "jump_ode", [t, x, E, E, E], [ca.vertcat(rate, 0.0), E, E, E], ca.dyn_in(), ca.dyn_out()
    )
    f_dae = ca.Function(
        "jump_dae",
        [t, x, z, E, E],
        [ca.vertcat(z, 0.0), z - rate, E, E],
        ca.dyn_in(),
        ca.dyn_out(),
    )
    return f_ode, f_dae


@pytest.fixture(scope="module")
def jump(tmp_path_factory):
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path_factory.mktemp("jump")))
    f_ode, f_dae = _jump_functions()
    return {
        "ode": build_library([f_ode], cg, [f_ode.name()]).function(f_ode.name()),
        "dae": build_library([f_dae], cg, [f_dae.name()]).function(f_dae.name()),
    }


def _run_jump(jump, method: str, t_out: np.ndarray, b: float, bps: list[float]):
    s = IntegratorSettings(method=method, rtol=1e-10, atol=1e-12, fixed_step=0.05)
    x0 = np.array([0.0, b])
    f = jump["dae" if method == "idas" else "ode"]
    return integrate(f, x0, t_out, s, breakpoints=bps, z0=np.ones(1))


@settings(max_examples=50, deadline=None)
@given(
    grids(max_horizon=3.0),
    st.data(),
    st.sampled_from(["cvodes", "idas", "fixed"]),
)
def test_jump_at_drawn_times_has_the_closed_form(jump, t_out, data, method):
    """A jump at an output time moved by a few ulps, or anywhere: every method reaches the
    horizon, every row at its requested time, with the closed form to 1e-8.

    The fixed step evaluates its first stage at a segment's start, so its jump is drawn
    among the restarts: one within tol after the start (or after another restart) is one
    instant with it, and a step that starts just before a jump is off by O(h·Δ).
    """
    bps = data.draw(breakpoint_sets(t_out))
    if method == "fixed":
        inside = schedule(t_out, bps).breaks.tolist()
    else:  # implicit methods: evaluated at the step's end, unaffected
        inside = [b for b in bps if 0.0 < b < t_out[-1]]
    b = data.draw(st.sampled_from(inside)) if inside else float(t_out[-1]) / 2
    tr = _run_jump(jump, method, t_out, b, [*bps, b])
    assert tr.complete, tr.message
    assert np.array_equal(tr.t, t_out)
    exact = np.where(t_out < b, t_out, b - 2.0 * (t_out - b))
    # a row merged with a restart holds the state there: off by <= 2 tol (|y'| <= 2); IDAS
    # at rtol 1e-10 drifts by 1e-9 over 2 s (measured); a step on the wrong side of the
    # jump is off by ~h·Δ (9.4e-4 for the fixed step before the schedule)
    np.testing.assert_allclose(tr.x[:, 0], exact, rtol=0, atol=1e-8)


@pytest.mark.parametrize("method", ["cvodes", "idas", "fixed"])
@pytest.mark.parametrize("b", [0.35, 0.57, 0.7])
def test_jump_at_a_grid_time_written_as_a_literal(jump, method, b):
    t_out = output_grid(1.0, 0.01)  # holds 0.35000000000000003, 0.5700000000000001, ...
    tr = _run_jump(jump, method, t_out, b, [b])
    assert tr.complete, tr.message
    exact = np.where(t_out < b, t_out, b - 2.0 * (t_out - b))
    np.testing.assert_allclose(tr.x[:, 0], exact, rtol=0, atol=1e-9)
    assert tr.stats["restarts"] == 1


# --------------------------------------------------------------------------- the paper, faulty
def _paper(horizon: float, faults: dict) -> object:
    return api.load(PAPER, {**faults, "integration.horizon": horizon}, variant="bp")


@pytest.fixture(scope="module")
def paper_env(tmp_path_factory):
    from synthesis import synthesize

    root = tmp_path_factory.mktemp("paper_bp")
    gains = synthesize(api.load(PAPER))  # the synthesis does not read the health g_i
    return gains, CodegenSettings(optimization="-O0", build_root=str(root / "build"))


@pytest.mark.parametrize("when", [0.35, 0.57, 0.7])
@pytest.mark.parametrize("form", ["table", "step"])
def test_paper_with_a_fault_reaches_the_horizon(paper_env, when, form):
    """The reported reproductions: follower 1 loses 10 % at 0.35, 0.57 or 0.7 s, written as
    a table or as a step expression; the default method reaches the horizon."""
    gains, cg = paper_env
    g = [[0.0, 1.0], [when, 0.9]] if form == "table" else f"1 - 0.1*step(t - {when})"
    sc = _paper(1.0, {"followers[1].g": g})
    assert sc.integration.method == "native" and sc.breakpoints() == (when,)
    built = api.build(sc, gains, settings=cg)
    tr = api.simulate(built, sc)
    assert tr.complete, tr.message
    assert tr.t[-1] == 1.0 and tr.stats["restarts"] == 1


#: several switches on follower 1 (a table) and one on follower 2 (a step expression)
FAULTS = {
    "followers[1].g": [[0.0, 1.0], [0.35, 0.9], [0.57, 0.85], [0.7, 0.95]],
    "followers[2].g": "1 - 0.1*step(t - 0.45)",
}


@pytest.fixture(scope="module")
def faulty(paper_env):
    gains, cg = paper_env
    sc = _paper(1.0, FAULTS)
    built: dict[str, Built] = {}

    def get(method: str) -> tuple:
        if method not in built:
            built[method] = api.build(sc, gains, method, cg)
        return sc, built[method]

    return get


@st.composite
def paper_schedules(draw):
    """A grid over at most 1 s and extra restart times that coincide with output times to
    rounding (or fall anywhere); the table's switches are restarts too."""
    t_out = draw(grids(max_horizon=1.0))
    return t_out, draw(breakpoint_sets(t_out))


def _paper_run(faulty, method: str, case) -> None:
    t_out, extra = case
    sc, built = faulty(method)
    s = api.integrator_settings(sc, method)
    bps = [*api.breakpoints(built, sc), *extra]
    tr = api.integrate_built(built, np.asarray(built.closed_loop.x0), t_out, s, bps)
    assert tr.complete, tr.message
    assert np.array_equal(tr.t, t_out) and np.all(np.isfinite(tr.x))


@FAST
@given(paper_schedules())
def test_paper_default_method_reaches_the_horizon_on_drawn_schedules(faulty, case):
    """50 drawn output grids and restart sets on the paper with switching faults: the
    default method (native: the per-agent engine) reaches every horizon."""
    _paper_run(faulty, "native", case)


@pytest.mark.parametrize(("method", "examples"), [("cvodes", 12), ("idas", 8)])
def test_paper_other_methods_reach_the_horizon_on_drawn_schedules(faulty, method, examples):
    @settings(max_examples=examples, deadline=None, database=None)
    @given(paper_schedules())
    def check(case):
        _paper_run(faulty, method, case)

    check()


@st.composite
def fault_healths(draw):
    """A health g_i(t) with switches at drawn times: a table of 1-4 entries or a step."""
    times = draw(
        st.lists(
            st.one_of(
                st.integers(1, 99).map(lambda k: k / 100),  # decimal literals: grid times
                st.floats(0.001, 0.999),
            ),
            min_size=1,
            max_size=3,
            unique=True,
        )
    )
    values = draw(st.lists(st.floats(0.6, 1.0), min_size=len(times), max_size=len(times)))
    if draw(st.booleans()):
        return [[0.0, 1.0], *([t, v] for t, v in zip(sorted(times), values, strict=True))]
    drop = round(1.0 - values[0], 3)
    return f"1 - {drop}*step(t - {times[0]!r})"


@settings(max_examples=20, deadline=None, database=None)
@given(fault_healths(), fault_healths(), paper_schedules())
def test_per_agent_driver_with_drawn_faults(paper_env, faulty, g1, g4, case):
    """Fault onsets and switch times drawn into the code itself: the per-agent native
    driver (one follower model's kernels, compiled in seconds) reaches the horizon."""
    from generated import agents

    gains, cg = paper_env
    t_out, extra = case
    sc = _paper(1.0, {"followers[1].g": g1, "followers[4].g": g4})
    libs, model = agents.build_models(sc, gains, dataclasses.replace(cg, kernel_optimization="-O0"))
    s = api.integrator_settings(sc)
    x0 = np.asarray(faulty("native")[1].closed_loop.x0)  # the health g_i is not a state
    paths = [lib.path for lib in libs]
    prob = agents.problem(sc, gains, model)
    tr = agents.run(paths, prob, x0, t_out, s, breakpoints=[*sc.breakpoints(), *extra])
    assert tr.complete, tr.message
    assert np.array_equal(tr.t, t_out)


def test_per_agent_driver_at_25_followers_with_a_fault(tmp_path):
    """N = 25 (the default method runs the per-agent engine) with a fault at 0.7 s."""
    from benchmarks.scenarios import bench_gains, bench_scenario

    sc = bench_scenario(25, horizon=1.0)
    fault = api.load(PAPER, {"followers[1].g": [[0.0, 1.0], [0.7, 0.9]]}).followers[0].g
    fo = (dataclasses.replace(sc.followers[0], g=fault), *sc.followers[1:])
    sc = dataclasses.replace(sc, followers=fo)
    assert sc.breakpoints() == (0.7,) and sc.integration.method == "native"
    gains = bench_gains(sc)[0]
    cg = CodegenSettings(optimization="-O0", build_root=str(tmp_path))
    built = api.build(sc, gains, settings=dataclasses.replace(cg, kernel_optimization="-O0"))
    assert built.agents is not None
    tr = api.simulate(built, sc)
    assert tr.complete, tr.message
    assert tr.t[-1] == 1.0 and tr.stats["restarts"] == 1
