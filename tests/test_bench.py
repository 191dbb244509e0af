"""Sanity tests of the benchmark and of the large-N plan (no timing assertions)."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import scipy.linalg as sla

from generated.bench import BenchError, bench_scenario, main, random_graph
from generated.largescale import choose_plan, integrate_plan, plan_functions
from symbolic.errors import ToolkitError

ROOT = Path(__file__).resolve().parent.parent


# ----------------------------------------------------------------------------- graphs
@pytest.mark.parametrize("N", [1, 2, 7, 300])
def test_random_graph_is_a_sparse_dag_reachable_from_the_leader(N: int) -> None:
    A, pin = random_graph(N, seed=3)
    assert A.shape == (N, N) and pin.shape == (N,)
    assert np.all(np.triu(A) == 0)  # i hears only j < i: acyclic, no self-loops
    indeg = A.sum(1)
    assert np.all(indeg[1:] >= 1) and indeg.max() <= 3
    assert pin[0] > 0 and np.count_nonzero(pin) == max(1, N // 100)
    # every follower reachable from the leader: L + B is a nonsingular M-matrix
    LB = np.diag(A.sum(1) + pin) - A
    assert np.all(np.linalg.eigvals(LB).real > 0)
    A2, pin2 = random_graph(N, seed=3)
    assert np.array_equal(A, A2) and np.array_equal(pin, pin2)


def test_random_graph_rejects_empty() -> None:
    with pytest.raises(ToolkitError):
        random_graph(0)


def test_bench_scenario_shapes_and_offsets() -> None:
    sc = bench_scenario(12, horizon=3.0)
    assert sc.N == 12 and len(sc.followers) == 12
    assert sc.integration.horizon == 3.0
    b0 = np.array([f.b0 for f in sc.followers])
    assert np.allclose(np.linalg.norm(b0, axis=1), 4.0)  # offsets on a circle
    assert sc.controller.Lambda.shape == (12, sc.n)
    assert sc.initial.eta.shape == (12, sc.m)
    assert sc.observer.phi0.shape == (12,)
    paper = bench_scenario(5)
    assert paper.name == "paper"  # N = 5 is the paper's own scenario


# ----------------------------------------------------------------------------- plans
def test_choose_plan() -> None:
    assert choose_plan(5).strategy == "direct"
    big = choose_plan(2000)
    assert big.strategy == "gmres" and not big.expand and big.derivatives == ("fwd1",)
    assert big.integrator_options["newton_scheme"] == "gmres"
    assert big.integrator_options["use_preconditioner"] is False
    assert choose_plan(2000, "direct").derivatives == ("jac",)
    for bad in ({"strategy": "lu"}, {"max_krylov": 0}):
        with pytest.raises(ToolkitError):
            choose_plan(10, **bad)


def _linear_dyn(A: np.ndarray) -> ca.Function:
    """ẋ = A x in integrator form, built from a mapped per-block function like the closed loop."""
    nx = A.shape[0]
    t, x = ca.MX.sym("t"), ca.MX.sym("x", nx)
    e = ca.MX(0, 1)
    return ca.Function("lin", [t, x, e, e, e], [ca.mtimes(ca.sparsify(ca.DM(A)), x), e, e, e],
                       ca.dyn_in(), ca.dyn_out())  # fmt: skip


def test_gmres_companion_is_the_jacobian_vector_product() -> None:
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6))
    f = _linear_dyn(A)
    fwd = plan_functions(f, choose_plan(100))[1]
    assert fwd.name() == "fwd1_lin"
    v = rng.normal(size=6)
    x = rng.normal(size=6)
    outs = f(0.0, x, [], [], [])
    jv = fwd(0.0, x, [], [], [], *outs, 0.0, v, [], [], [])[0]
    np.testing.assert_allclose(np.array(jv).ravel(), A @ v, rtol=1e-12)


@pytest.mark.parametrize("strategy", ["direct", "gmres"])
def test_integrate_plan_matches_matrix_exponential(strategy: str) -> None:
    # stiff linear test problem (eigenvalues -1 ... -1e4) with the exact solution expm(At) x0
    rng = np.random.default_rng(1)
    V = np.linalg.qr(rng.normal(size=(8, 8)))[0]
    A = V @ np.diag(-np.logspace(0, 4, 8)) @ V.T
    x0 = rng.normal(size=8)
    t_out = np.linspace(0.0, 2.0, 5)
    res = integrate_plan(
        _linear_dyn(A), x0, t_out, choose_plan(8, strategy), rtol=1e-8, atol=1e-10,
        breakpoints=[0.7],
    )  # fmt: skip
    assert res.complete, res.message
    assert np.allclose(res.t, t_out)
    exact = np.array([sla.expm(A * t) @ x0 for t in t_out])
    np.testing.assert_allclose(res.x, exact, atol=1e-6)
    assert res.stats["steps"] > 0 and res.stats["rhs_evals"] > 0
    if strategy == "gmres":
        assert res.stats["jac_evals"] == 0  # matrix-free: no Jacobian is ever formed


def test_integrate_plan_reports_failure_instead_of_raising() -> None:
    A = np.array([[-1.0]])
    res = integrate_plan(_linear_dyn(A), np.ones(1), np.linspace(0, 1, 3), choose_plan(1),
                         max_steps=1)  # fmt: skip
    assert not res.complete and "failed" in res.message
    assert res.x.shape[0] == len(res.t) >= 1


# ----------------------------------------------------------------------------- command line
def test_cli_bad_method_is_one_line_exit_2() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "generated.bench", "--methods", "nope"],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "--methods" in proc.stderr


def test_bad_sizes_raise_bench_error() -> None:
    with pytest.raises(BenchError):
        main(["--sizes", "5,x"])


def test_quick_smoke_run(tmp_path: Path) -> None:
    """``--quick`` end to end on a short horizon: two methods, table, CSV and plot."""
    proc = subprocess.run(
        [sys.executable, "-m", "generated.bench", "--quick", "--horizon", "0.02",
         "--methods", "c-cvodes-direct,scipy-rk45", "--out", str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "c-cvodes-direct*" in proc.stdout
    rows = list(csv.DictReader((tmp_path / "bench.csv").open()))
    assert [r["method"] for r in rows] == ["c-cvodes-direct", "scipy-rk45"]
    ours, rk = rows
    assert ours["status"] == "ok" and float(ours["ratio_to_ours"]) == 1.0
    assert int(ours["steps"]) > 0 and int(ours["rhs_evals"]) >= int(ours["steps"])
    assert float(ours["c_bytes"]) > 0 and float(ours["peak_rss_mb"]) > 0
    if rk["status"] == "ok":
        # same scenario, same tolerances: the final states agree (relative to max(1, |x|))
        assert float(rk["rel_dx_final_vs_ours"]) < 1e-2
    assert (tmp_path / "scaling.png").stat().st_size > 1000


def test_finish_ratios_and_table_from_synthetic_records() -> None:
    from generated.bench import finish, table

    x = np.array([1.0, 100.0])
    recs = [
        {"N": 5, "method": "c-cvodes-direct", "status": "ok", "int_median_s": 0.5,
         "int_min_s": 0.4, "int_max_s": 0.6, "_x_final": x},
        {"N": 5, "method": "scipy-bdf", "status": "ok", "int_median_s": 30.0,
         "int_min_s": 30.0, "int_max_s": 30.0, "_x_final": x + np.array([0.01, 1.0])},
        {"N": 5, "method": "scipy-rk45", "status": "stopped at the time limit at t = 1 s"},
    ]  # fmt: skip
    out = finish(recs)
    assert out[0]["ours"] and out[0]["ratio_to_ours"] == 1.0
    assert out[1]["ratio_to_ours"] == pytest.approx(60.0)
    assert out[1]["rel_dx_final_vs_ours"] == pytest.approx(0.01)  # max(0.01/1, 1/100)
    assert "ratio_to_ours" not in out[2]  # no ratio for a run that did not finish
    txt = table(out)
    assert "c-cvodes-direct*" in txt and "stopped at the time limit" in txt


def test_gmres_build_carries_the_jacobian_sparsity(tmp_path: Path) -> None:
    """The compiled matrix-free RHS reports A's pattern, not a dense Jacobian."""
    from generated.codegen import CodegenSettings
    from generated.largescale import build_plan

    A = np.diag(-np.arange(1.0, 7.0)) + np.diag(np.ones(5), -1)  # bidiagonal
    plan = choose_plan(100)
    b = build_plan(_linear_dyn(A), plan, "lin_cl", CodegenSettings(build_root=str(tmp_path)))
    assert set(b.library.names) == {"lin_cl", "fwd1_lin_cl"}  # no jac_ generated
    sp = b.dyn.sparsity_jac(1, 0)
    assert sp.nnz() == np.count_nonzero(A)
    x0 = np.ones(6)
    res = integrate_plan(b.dyn, x0, np.array([0.0, 0.5]), plan, rtol=1e-9, atol=1e-12)
    assert res.complete
    np.testing.assert_allclose(res.x[-1], sla.expm(0.5 * A) @ x0, rtol=1e-6)
    again = build_plan(_linear_dyn(A), plan, "lin_cl", CodegenSettings(build_root=str(tmp_path)))
    assert again.library.cache_hit and again.library.key == b.library.key
