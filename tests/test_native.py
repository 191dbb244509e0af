"""The native integrator (generated/native.py, generated/sparse_lu.py, generated/native/driver.c).

Independent truths: numpy's dense solve and determinant for the generated sparse LU,
the matrix exponential and piecewise closed forms for the CVODE driver.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest
from scipy.linalg import expm

from core.errors import BuildError, IntegrationError
from generated import native
from generated.codegen import cache_key
from generated.schedule import output_grid
from generated.sparse_lu import sparse_lu
from generated.values import CodegenSettings, IntegratorSettings

E = ca.SX(0, 1)


def ode(name: str, t: ca.SX, x: ca.SX, rhs: ca.SX) -> ca.Function:
    return ca.Function(name, [t, x, E, E, E], [rhs, E, E, E], ca.dyn_in(), ca.dyn_out())


@pytest.fixture(scope="module")
def cg(tmp_path_factory):
    return CodegenSettings(optimization="-O0", build_root=str(tmp_path_factory.mktemp("nbuild")))


# --------------------------------------------------------------------------- sparse LU
def random_pattern(rng, n: int, density: float) -> tuple[ca.Sparsity, np.ndarray]:
    mask = rng.random((n, n)) < density
    np.fill_diagonal(mask, True)
    r, c = np.nonzero(mask)
    A = np.zeros((n, n))
    A[r, c] = rng.standard_normal(len(r))
    A += np.diag(np.abs(A).sum(axis=1) + 1.0)  # diagonally dominant: no pivoting needed
    return ca.Sparsity.triplet(n, n, r.tolist(), c.tolist()), A


@pytest.mark.parametrize(("n", "density"), [(1, 1.0), (6, 0.5), (25, 0.1), (40, 0.06)])
@pytest.mark.parametrize("reciprocal", [False, True])
def test_sparse_lu_solves_like_numpy_and_pivots_give_the_determinant(n, density, reciprocal):
    rng = np.random.default_rng(n)
    for _ in range(3):
        sp, A = random_pattern(rng, n, density)
        lu = sparse_lu(sp, reciprocal=reciprocal)
        LU, piv = lu.factor(ca.project(ca.DM(A), sp))
        # the stored diagonal: U's pivots, or their reciprocals
        diag = np.diag(np.array(ca.DM(LU)))
        p = np.array(piv).ravel()
        np.testing.assert_allclose(diag * p if reciprocal else diag / p, 1.0, rtol=1e-14)
        b = rng.standard_normal(n)
        x = np.array(lu.solve(LU, b)).ravel()
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-11, atol=1e-13)
        # U's diagonal: the product of the pivots is det(A) (no row exchanges)
        sign, logdet = np.linalg.slogdet(A)
        p = np.array(piv).ravel()
        assert np.prod(np.sign(p)) == sign
        assert np.sum(np.log(np.abs(p))) == pytest.approx(logdet, rel=1e-11, abs=1e-11)
        assert lu.fill == LU.nnz() - sp.nnz() >= 0


def test_sparse_lu_fill_is_zero_for_a_triangular_pattern():
    n = 8
    r, c = np.tril_indices(n)
    lu = sparse_lu(ca.Sparsity.triplet(n, n, r.tolist(), c.tolist()))
    assert lu.fill == 0


def test_sparse_lu_rejects_a_pattern_without_its_diagonal():
    sp = ca.Sparsity.triplet(2, 2, [0, 1], [1, 0])
    with pytest.raises(BuildError, match="diagonal"):
        sparse_lu(sp)
    with pytest.raises(BuildError, match="square"):
        sparse_lu(ca.Sparsity.dense(2, 3))


# --------------------------------------------------------------------------- driver
A_LIN = np.array([[0.0, 1.0, 0.0], [-2.0, -0.3, 0.5], [0.0, 0.0, -50.0]])  # stiff mode -50


def test_linear_ode_matches_matrix_exponential_across_breakpoints(cg):
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 3)
    lib = native.build(ode("lin", t, x, ca.mtimes(ca.DM(A_LIN), x)), cg)
    tg = output_grid(2.0, 0.01)
    x0 = np.array([1.0, 0.0, 1.0])
    s = IntegratorSettings(method="native", rtol=1e-10, atol=1e-12)
    tr = native.run(lib.path, x0, tg, s, breakpoints=[0.333, 1.0, 5.0])
    assert tr.complete and tr.message == "" and tr.method == "native"
    exact = np.array([expm(A_LIN * tt) @ x0 for tt in tg])
    np.testing.assert_allclose(tr.x, exact, atol=1e-7)
    st = tr.stats
    assert st["restarts"] == 2  # 5.0 lies beyond the horizon
    assert st["steps"] > 0 and st["rhs_evals"] >= st["steps"]
    assert 0 < st["jac_evals"] <= st["lu_factorizations"] and st["pivot_failures"] == 0
    assert st["newton_iters"] > 0 and st["last_step"] > 0
    # a state of the wrong size is refused by the driver, in one line
    with pytest.raises(IntegrationError, match="could not start: nx does not match"):
        native.run(lib.path, np.zeros(2), tg, s)


def test_a_run_returns_the_state_where_cvode_stood(cg):
    """A run that gives up hands back CVODE's last step (t_stop, x_stop), past the rows.

    Truth: the matrix exponential at t_stop. A complete run stands at the horizon.
    """
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 3)
    lib = native.build(ode("lin", t, x, ca.mtimes(ca.DM(A_LIN), x)), cg)
    tg, x0 = output_grid(2.0, 0.5), np.array([1.0, 0.0, 1.0])
    s = IntegratorSettings(method="native", rtol=1e-10, atol=1e-12, max_steps=40)
    tr = native.run(lib.path, x0, tg, s)
    assert not tr.complete
    assert tr.t_reached < tr.t_stop < tg[len(tr.t)]  # between the last row and the next
    np.testing.assert_allclose(tr.x_stop, expm(A_LIN * tr.t_stop) @ x0, rtol=1e-7, atol=1e-9)
    assert np.abs(tr.x_stop - tr.x[-1]).max() > 1e-3  # not the last output row
    done = native.run(lib.path, x0, tg, dataclasses.replace(s, max_steps=100_000))
    assert done.complete and done.t_stop == tg[-1]
    assert np.array_equal(done.x_stop, done.x[-1])


def test_discontinuity_at_a_breakpoint_is_resolved_exactly(cg):
    """ẋ = 1 before t = 0.505, −2 after (not an output time): x = t, then 0.505 − 2(t − 0.505)."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    lib = native.build(ode("jump", t, x, ca.if_else(t < 0.505, 1.0, -2.0)), cg)
    tg = output_grid(1.0, 0.01)
    s = IntegratorSettings(method="native", rtol=1e-10, atol=1e-12)
    tr = native.run(lib.path, np.zeros(1), tg, s, breakpoints=[0.505])
    exact = np.where(tg < 0.505, tg, 0.505 - 2.0 * (tg - 0.505))
    np.testing.assert_allclose(tr.x[:, 0], exact, atol=1e-9)
    assert tr.stats["restarts"] == 1


def test_never_evaluates_beyond_the_horizon(cg):
    """ẋ = NaN for t > 1: a run to t = 1 must complete (the horizon is CVODE's stop time)."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    lib = native.build(ode("edge", t, x, ca.if_else(t <= 1.0, ca.cos(t), np.nan)), cg)
    tg = output_grid(1.0, 0.01)  # output times in between are interpolated, not stopped at
    tr = native.run(lib.path, np.zeros(1), tg, IntegratorSettings(rtol=1e-6, atol=1e-9))
    assert tr.complete and tr.stats["steps"] < len(tg) - 1  # fewer steps than outputs
    np.testing.assert_allclose(tr.x[:, 0], np.sin(tg), atol=1e-5)


def test_blow_up_gives_an_incomplete_trajectory_with_the_reason(cg):
    """ẋ = x², x(0) = 1: x = 1/(1 − t) leaves every bound before t = 1."""
    t, x = ca.SX.sym("t"), ca.SX.sym("x", 1)
    lib = native.build(ode("blow", t, x, x**2), cg)
    tg = output_grid(2.0, 0.1)
    s = IntegratorSettings(method="native", rtol=1e-6, atol=1e-8, max_steps=500)
    tr = native.run(lib.path, np.ones(1), tg, s)
    assert not tr.complete and 0.5 <= tr.t_reached < 1.0
    assert len(tr.t) == len(tr.x) and tr.t[-1] == tr.t_reached
    # the sensitivity dx(t)/dx(0) = x(t)² amplifies rtol = 1e-6 by 25 at t = 0.8, 100 at 0.9
    early = tr.t <= 0.8 + 1e-12
    np.testing.assert_allclose(tr.x[early, 0], 1.0 / (1.0 - tr.t[early]), rtol=1e-4)
    assert tr.message.startswith(f"native failed after t = {tr.t_reached:.6g} s")
    assert "\n" not in tr.message
    with pytest.raises(Exception, match="native failed"):
        tr.raise_if_incomplete()


def test_parameters_are_inputs_of_one_library(cg):
    # x' = -k x + c: x(t) = c/k + (x0 - c/k) exp(-k t), for every (k, c) with one library
    t, x, p = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("p", 2)
    f = ca.Function(
        "withp", [t, x, E, p, E], [-p[0] * x + p[1], E, E, E], ca.dyn_in(), ca.dyn_out()
    )
    lib = native.build(f, cg)
    t_out = output_grid(2.0, 0.25)
    s = IntegratorSettings(method="native", rtol=1e-10, atol=1e-12)
    x0 = np.array([1.0, -2.0])
    for k, c in ((0.5, 0.0), (3.0, 1.5)):
        tr = native.run(lib.path, x0, t_out, s, p=np.array([k, c]))
        exact = c / k + (x0[None, :] - c / k) * np.exp(-k * t_out[:, None])
        np.testing.assert_allclose(tr.x, exact, rtol=1e-7, atol=1e-9)
    assert native.build(f, cg).path == lib.path  # same code: the cached library
    with pytest.raises(IntegrationError, match="1 parameters given, the library takes 2"):
        native.run(lib.path, x0, t_out, s, p=np.array([1.0]))


def test_native_functions_need_an_ode():
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 2), ca.SX.sym("z")
    f = ca.Function("withz", [t, x, z, E, E], [x * z, z, E, E], ca.dyn_in(), ca.dyn_out())
    with pytest.raises(BuildError, match="algebraic states z"):
        native.native_functions(f)


def test_toolchain_key_covers_every_header_and_library():
    tc = native.toolchain()
    headers = {str(p.relative_to(native.INCLUDE_DIR)) for p in native.INCLUDE_DIR.rglob("*.h")}
    assert set(tc.key["headers"]) == headers and "sundials/sundials_config.h" in headers
    assert len(tc.key["libraries"]) == len(native.SUNDIALS_LIBRARIES) == len(tc.libraries)
    assert "hitl_native_run" in tc.appended_source
    # a changed header (or library) changes the cache key: the stale build is never used
    changed = dict(tc.key, headers=dict(tc.key["headers"], **{"sundials/x.h": "0"}))
    s = CodegenSettings()
    assert cache_key("int x;", s, tc.key) != cache_key("int x;", s, changed)


def test_missing_scikit_sundae_is_a_one_line_build_error(monkeypatch):
    native.toolchain.cache_clear()
    monkeypatch.setattr(native.importlib.util, "find_spec", lambda name: None)
    try:
        with pytest.raises(BuildError, match="scikit-sundae") as ei:
            native.toolchain()
        assert "\n" not in str(ei.value)
    finally:
        native.toolchain.cache_clear()


def test_settings_accept_native():
    s = IntegratorSettings(method="native")
    assert dataclasses.replace(s, rtol=1e-9).method == "native"
