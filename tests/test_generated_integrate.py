"""Integration methods over compiled code (generated/solvers/engine.py), against exact solutions."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.linalg import expm

from core.errors import IntegrationError
from generated.codegen import build_library
from generated.schedule import output_grid, schedule
from generated.solvers.engine import _chunks, integrate
from generated.values import CodegenSettings, IntegratorSettings

E = ca.SX(0, 1)


def ode(name: str, t: ca.SX, x: ca.SX, rhs: ca.SX) -> ca.Function:
    return ca.Function(name, [t, x, E, E, E], [rhs, E, E, E], ca.dyn_in(), ca.dyn_out())


@pytest.fixture(scope="module")
def cg(tmp_path_factory):
    return CodegenSettings(build_root=str(tmp_path_factory.mktemp("build")))


def compiled(f: ca.Function, cg: CodegenSettings) -> ca.Function:
    return build_library([f], cg, [f.name()]).function(f.name())


# --------------------------------------------------------------------------- linear, exact
A_LIN = np.array([[0.0, 1.0, 0.0], [-2.0, -0.3, 0.5], [0.0, 0.0, -50.0]])  # stiff mode -50


@pytest.fixture(scope="module")
def linear(cg):
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 3)
    return compiled(ode("lin", t, x, ca.mtimes(ca.DM(A_LIN), x)), cg)


def exact_linear(tg, x0):
    return np.array([expm(A_LIN * tt) @ x0 for tt in tg])


@pytest.mark.parametrize(("method", "tol"), [("cvodes", 1e-7), ("fixed", 2e-5)])
def test_linear_ode_matches_matrix_exponential(linear, method, tol):
    tg = output_grid(2.0, 0.01)
    x0 = np.array([1.0, 0.0, 1.0])
    s = IntegratorSettings(method=method, rtol=1e-10, atol=1e-12, fixed_step=1e-4)
    tr = integrate(linear, x0, tg, s, breakpoints=[0.333, 1.0])
    assert tr.complete and tr.message == ""
    assert tr.x.shape == (201, 3) and np.array_equal(tr.t, tg)
    ex = exact_linear(tg, x0)
    assert np.abs(tr.x - ex).max() < tol
    assert tr.stats["restarts"] == 2  # one chunk per segment (chunk = 1 s)
    assert tr.stats["steps"] > 0 and tr.stats["rhs_evals"] >= tr.stats["steps"]


def test_fixed_step_is_second_order(linear):
    """ROS2: halving the step quarters the error (smooth part, after the stiff transient)."""
    tg = output_grid(1.0, 0.05)
    x0 = np.array([1.0, 0.0, 0.0])  # no stiff transient
    ex = exact_linear(tg, x0)
    errs = []
    for h in (1e-2, 5e-3, 2.5e-3):
        tr = integrate(linear, x0, tg, IntegratorSettings(method="fixed", fixed_step=h))
        errs.append(np.abs(tr.x - ex).max())
    r1, r2 = errs[0] / errs[1], errs[1] / errs[2]
    assert 3.5 < r1 < 4.5 and 3.5 < r2 < 4.5


def test_fixed_step_is_stable_far_beyond_explicit_limit(cg):
    """λ = -1e5 with h = 1e-3 (hλ = -100): explicit RK4 would explode, ROS2 decays."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 2)
    f = compiled(ode("stiff", t, x, ca.vertcat(-1e5 * (x[0] - ca.cos(t)), -x[1])), cg)
    tg = output_grid(1.0, 0.1)
    tr = integrate(f, np.array([3.0, 1.0]), tg, IntegratorSettings(method="fixed", fixed_step=1e-3))
    assert tr.complete
    np.testing.assert_allclose(tr.x[1:, 0], np.cos(tg[1:]), atol=1e-4)
    np.testing.assert_allclose(tr.x[:, 1], np.exp(-tg), atol=1e-6)


# --------------------------------------------------------------------------- DAE with a mass matrix
M_DAE = np.array([[2.0, 0.5], [0.5, 1.0]])
C_DAE = np.array([[0.4, 0.0], [0.0, 0.2]])
K_DAE = np.array([[3.0, -1.0], [-1.0, 2.0]])


def test_dae_with_mass_matrix_matches_matrix_exponential(cg):
    """M a + C q + K p = 0 as a semi-explicit DAE (z = a) with IDAS; truth: expm."""
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 4), ca.SX.sym("z", 2)
    p, q = x[:2], x[2:]
    alg = ca.mtimes(ca.DM(M_DAE), z) + ca.mtimes(ca.DM(C_DAE), q) + ca.mtimes(ca.DM(K_DAE), p)
    f = ca.Function(
        "mdae", [t, x, z, E, E], [ca.vertcat(q, z), alg, E, E], ca.dyn_in(), ca.dyn_out()
    )
    dae = compiled(f, cg)
    Minv = np.linalg.inv(M_DAE)
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-Minv @ K_DAE, -Minv @ C_DAE]])
    x0 = np.array([1.0, -0.5, 0.0, 0.3])
    tg = output_grid(3.0, 0.05)
    tr = integrate(
        dae,
        x0,
        tg,
        IntegratorSettings(method="idas", rtol=1e-10, atol=1e-12),
        z0=np.zeros(2),
        breakpoints=[1.5],
    )
    assert tr.complete
    ex = np.array([expm(A * tt) @ x0 for tt in tg])
    assert np.abs(tr.x - ex).max() < 1e-7
    # the algebraic states are the accelerations
    acc = np.array([(A @ xx)[2:] for xx in ex])
    assert np.abs(tr.z - acc).max() < 1e-6


def test_methods_check_forms(linear):
    with pytest.raises(IntegrationError, match="x0"):
        integrate(linear, np.zeros(2), output_grid(1.0, 0.5), IntegratorSettings())
    with pytest.raises(IntegrationError, match="method"):
        IntegratorSettings(method="rk4")
    with pytest.raises(IntegrationError, match="rtol"):
        IntegratorSettings(rtol=-1.0)
    with pytest.raises(IntegrationError, match="divide"):
        output_grid(1.0, 0.3)


# --------------------------------------------------------------------------- tanh switching: all agree
def friction_ode_dae():
    """m v' = -k x - c v - F tanh(v/ε) + u(t), u a step at t = 0.75 (a breakpoint)."""
    mass, k, c, F, eps = 2.0, 4.0, 0.2, 1.5, 0.05
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("z", 1)
    u = ca.sin(2 * t) + 2.0 * (t >= 0.75)
    force = -k * x[0] - c * x[1] - F * ca.tanh(x[1] / eps) + u
    f_ode = ode("fric_ode", t, x, ca.vertcat(x[1], force / mass))
    f_dae = ca.Function(
        "fric_dae",
        [t, x, z, E, E],
        [ca.vertcat(x[1], z), mass * z - force, E, E],
        ca.dyn_in(),
        ca.dyn_out(),
    )
    return f_ode, f_dae


def test_cvodes_idas_fixed_agree_on_tanh_switching(cg):
    f_ode, f_dae = friction_ode_dae()
    e_ode, e_dae = compiled(f_ode, cg), compiled(f_dae, cg)
    tg = output_grid(1.5, 0.01)
    x0 = np.array([1.0, 0.0])
    res = {}
    for method, f in (("cvodes", e_ode), ("idas", e_dae), ("fixed", e_ode)):
        s = IntegratorSettings(method=method, rtol=1e-9, atol=1e-11, fixed_step=1e-4)
        tr = integrate(f, x0, tg, s, breakpoints=[0.75], z0=np.zeros(1))
        assert tr.complete, tr.message
        res[method] = tr.x
    # reference: scipy's Radau on the same equations (an independent integrator)
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        u = np.sin(2 * t) + 2.0 * (t >= 0.75)
        return [y[1], (-4 * y[0] - 0.2 * y[1] - 1.5 * np.tanh(y[1] / 0.05) + u) / 2.0]

    ref = np.vstack(
        [
            solve_ivp(
                rhs, (0, 0.75), x0, method="Radau", rtol=1e-11, atol=1e-13, t_eval=tg[tg <= 0.75]
            ).y.T,
        ]
    )
    y75 = ref[-1]
    ref2 = solve_ivp(
        rhs, (0.75, 1.5), y75, method="Radau", rtol=1e-11, atol=1e-13, t_eval=tg[tg > 0.75]
    ).y.T
    ref = np.vstack([ref, ref2])
    assert np.abs(res["cvodes"] - ref).max() < 1e-6
    assert np.abs(res["idas"] - ref).max() < 1e-6
    assert np.abs(res["fixed"] - ref).max() < 1e-4
    assert np.abs(res["cvodes"] - res["idas"]).max() < 1e-6


# --------------------------------------------------------------------------- breakpoints
def test_run_restarts_at_breakpoints(cg):
    """x' = step(t - 0.5): exact answer max(0, t - 0.5); with the restart, to 1e-12."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    f = compiled(ode("ramp", t, x, ca.if_else(t >= 0.5, 1.0, 0.0)), cg)
    tg = output_grid(1.0, 0.1)
    tr = integrate(
        f, np.zeros(1), tg, IntegratorSettings(rtol=1e-10, atol=1e-12), breakpoints=[0.5]
    )
    np.testing.assert_allclose(tr.x[:, 0], np.maximum(0.0, tg - 0.5), atol=1e-12)
    tr2 = integrate(
        f, np.zeros(1), tg, IntegratorSettings(method="fixed", fixed_step=0.01), breakpoints=[0.5]
    )
    np.testing.assert_allclose(tr2.x[:, 0], np.maximum(0.0, tg - 0.5), atol=1e-12)


def test_plan_splits_at_breakpoints_and_chunks():
    tg = output_grid(3.0, 0.25)
    chunks = _chunks(schedule(tg, [0.6, 2.0, 5.0]), chunk=1.0)
    targets = [c for ch in chunks for c in ch]
    # every output time once, in order, plus the breakpoint 0.6 as a non-output target
    assert [c[1] for c in targets if c[1] >= 0] == list(range(1, len(tg)))
    assert [c[0] for c in targets if c[1] < 0] == [0.6]
    assert all(
        b > a
        for a, b in zip([0.0] + [c[0] for c in targets], [c[0] for c in targets], strict=False)
    )
    # no chunk crosses a breakpoint, none is longer than the chunk length
    start = 0.0
    for ch in chunks:
        for b in (0.6, 2.0):
            assert not (start < b < ch[-1][0])
        assert ch[-1][0] - start <= 1.0 + 1e-12
        start = ch[-1][0]


# --------------------------------------------------------------------------- failures
@pytest.fixture(scope="module")
def blowup(cg):
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    return compiled(ode("blowup", t, x, x**2), cg)  # x(t) = 1/(1 - t), blows up at t = 1


@pytest.mark.parametrize("method", ["cvodes"])
def test_failure_keeps_trajectory_up_to_time_reached(blowup, method):
    tg = output_grid(2.0, 0.05)
    s = IntegratorSettings(method=method, max_steps=2000, fixed_step=1e-3)
    tr = integrate(blowup, np.ones(1), tg, s)
    assert not tr.complete
    assert method in tr.message and "failed after t =" in tr.message
    assert 0.8 <= tr.t_reached < 1.0
    assert len(tr.t) == len(tr.x) and tr.t[-1] == tr.t_reached
    assert np.all(np.isfinite(tr.x))
    # what was kept is right: the exact solution 1/(1 - t)
    ok = tr.t < 0.9
    np.testing.assert_allclose(tr.x[ok, 0], 1 / (1 - tr.t[ok]), rtol=1e-3)
    with pytest.raises(IntegrationError) as ei:
        tr.raise_if_incomplete()
    assert ei.value.t_reached == tr.t_reached


def test_nan_is_a_failure(cg):
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    f = compiled(ode("nanrhs", t, x, ca.if_else(t > 0.5, ca.sqrt(-1 - x**2), -x)), cg)
    for method in ("cvodes", "fixed"):
        tr = integrate(
            f, np.ones(1), output_grid(1.0, 0.1), IntegratorSettings(method=method, max_steps=500)
        )
        assert not tr.complete and tr.t_reached == pytest.approx(0.5)
        np.testing.assert_allclose(tr.x[:, 0], np.exp(-tr.t), rtol=1e-4)


def test_progress_is_reported(linear):
    seen = []
    integrate(
        linear,
        np.ones(3),
        output_grid(3.0, 0.5),
        IntegratorSettings(chunk=1.0),
        progress=seen.append,
    )
    assert seen == pytest.approx([1.0, 2.0, 3.0])


def test_gmres_with_extra_options_matches_direct(cg, linear):
    """The matrix-free Newton–Krylov path (extra SUNDIALS options) solves the same problem."""
    from dataclasses import replace

    t, x = ca.SX.sym("t"), ca.SX.sym("x", 3)
    f = ode("lin_jvp", t, x, ca.mtimes(ca.DM(A_LIN), x))
    lib = build_library([f], replace(cg, jacobian="jvp"), ["lin_jvp"])
    tg = output_grid(1.0, 0.1)
    x0 = np.array([1.0, 0.0, 1.0])
    s = IntegratorSettings(
        rtol=1e-10,
        atol=1e-12,
        newton_scheme="gmres",
        extra_options=(("use_preconditioner", False), ("max_krylov", 3)),
    )
    tr = integrate(lib.function("lin_jvp"), x0, tg, s)
    assert tr.complete
    assert np.abs(tr.x - exact_linear(tg, x0)).max() < 1e-7


def test_idas_failure_keeps_trajectory(cg):
    """x' = z, 0 = z − x² (blow-up at t = 1) in the DAE form."""
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 1), ca.SX.sym("z", 1)
    f = ca.Function("blowdae", [t, x, z, E, E], [z, z - x**2, E, E], ca.dyn_in(), ca.dyn_out())
    dae = compiled(f, cg)
    tr = integrate(
        dae,
        np.ones(1),
        output_grid(2.0, 0.05),
        IntegratorSettings(method="idas", max_steps=2000),
        z0=np.ones(1),
    )
    assert not tr.complete and "idas failed after t =" in tr.message
    assert 0.8 <= tr.t_reached < 1.0 and np.all(np.isfinite(tr.x)) and np.all(np.isfinite(tr.z))
    ok = tr.t < 0.9
    np.testing.assert_allclose(tr.x[ok, 0], 1 / (1 - tr.t[ok]), rtol=1e-3)
    np.testing.assert_allclose(tr.z[ok, 0], tr.x[ok, 0] ** 2, rtol=1e-3)


# --------------------------------------------------------------------------- ill-conditioned z (IDAS)
def noisy_friction_dae() -> ca.Function:
    """The friction DAE plus big·(tan x cos x − sin x): zero exactly, rounding ~1e-4 in z.

    Mimics the paper scenario, where a 1-ulp change of x moves the accelerations z by
    up to 1.6e-3 (5 000 × rtol |z|): z cannot be converged to rtol in floating point.
    """
    mass, k, c, F, eps, big = 2.0, 4.0, 0.2, 1.5, 0.05, 1e12
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("z", 1)
    noise = big * (ca.tan(x[0]) * ca.cos(x[0]) - ca.sin(x[0]))  # |x0| <= 1 < π/2
    force = -k * x[0] - c * x[1] - F * ca.tanh(x[1] / eps) + ca.sin(2 * t) + noise
    return ca.Function(
        "noisy_dae",
        [t, x, z, E, E],
        [ca.vertcat(x[1], z), mass * z - force, E, E],
        ca.dyn_in(),
        ca.dyn_out(),
    )


def test_idas_leaves_algebraic_states_out_of_newton_test(cg):
    """z is out of IDAS's Newton test (algebraic_atol): x stays accurate, Newton converges.

    With z in the test (``algebraic_atol = atol``, the former behaviour) the same run
    fails the Newton iteration thousands of times (measured: 5 330 steps, 2 500
    failures, against 352 and 59). Truth: scipy's Radau on the noise-free ODE.
    """
    from scipy.integrate import solve_ivp

    dae = compiled(noisy_friction_dae(), cg)
    tg = output_grid(1.5, 0.01)
    x0 = np.array([1.0, 0.0])

    def rhs(t, y):
        return [y[1], (-4 * y[0] - 0.2 * y[1] - 1.5 * np.tanh(y[1] / 0.05) + np.sin(2 * t)) / 2]

    ref = solve_ivp(rhs, (0, 1.5), x0, method="Radau", rtol=1e-12, atol=1e-14, t_eval=tg).y.T
    s = IntegratorSettings(method="idas", rtol=1e-6, atol=1e-8)
    tr = integrate(dae, x0, tg, s, z0=np.zeros(1))
    assert tr.complete, tr.message
    assert np.abs(tr.x - ref).max() < 1e-5
    assert tr.stats["newton_fails"] < 0.25 * tr.stats["steps"]
    # z(0) solves alg = 0 for x0 (IDACalcIC, which uses the same weights, would stop early)
    assert abs(float(dae(0.0, x0, tr.z[0], [], [])[1])) < 1e-10
    old = integrate(
        dae,
        x0,
        tg,
        IntegratorSettings(method="idas", rtol=1e-6, atol=1e-8, algebraic_atol=1e-8),
        z0=np.zeros(1),
    )
    assert old.stats["newton_fails"] > 10 * max(tr.stats["newton_fails"], 1)


def test_fixed_step_refines_where_a_step_meets_nan():
    """ROS2 over one coarse output interval: a step that leaves the RHS's domain (sqrt
    of a negative number) puts NaN into the next step's Jacobian, and the sparse linear
    solve raises; that interval is refined like a failed error test instead of ending
    the run (before the fix: "Nonzero 0 is not-a-number" at t = 0). The result matches
    scipy's Radau (independent implementation)."""
    from scipy.integrate import solve_ivp

    t, x = ca.SX.sym("t"), ca.SX.sym("x", 2)
    rhs = ca.vertcat(1 - 50 * ca.sqrt(x[0]) + 0.1 * x[1], x[0] - x[1])
    f = ode("sqrt_decay", t, x, rhs)
    s = IntegratorSettings(method="fixed", fixed_step=0.1, fixed_rtol=1e-4, fixed_atol=1e-6)
    tr = integrate(f, np.array([1.0, 0.0]), np.array([0.0, 1.0]), s)
    assert tr.complete, tr.message
    assert tr.stats["refined_intervals"] > 0

    def g(_t, y):
        return [1 - 50 * np.sqrt(max(y[0], 0.0)) + 0.1 * y[1], y[0] - y[1]]

    ref = solve_ivp(g, (0, 1), [1.0, 0.0], method="Radau", rtol=1e-10, atol=1e-12)
    assert np.allclose(tr.x[-1], ref.y[:, -1], rtol=1e-3, atol=1e-5)
