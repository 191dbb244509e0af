"""One benchmark cell, run in its own subprocess: build, integrate ``runs`` times, record.

``python -m benchmarks.bench --worker N METHOD`` calls :func:`worker`; the parent
(:func:`benchmarks.bench.run_cell`) reads the record it writes.
"""

from __future__ import annotations

import dataclasses
import json
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.catalogue import (
    BENCH_METHODS,
    METHODS,
    OUTPUT_STEP,
    BenchError,
    BenchMethod,
    integration_method,
)
from benchmarks.scenarios import bench_gains, bench_scenario
from generated.values import Status


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _write(path: Path, rec: dict[str, Any]) -> None:
    from core.artifacts import atomic_write_text

    atomic_write_text(path, json.dumps(rec, default=_jsonable))


def _jsonable(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _time_casadi_rhs(f, x0: np.ndarray, nz: int = 0) -> float:
    """Seconds per evaluation of a CasADi integrator-form Function.

    Small states: ``f.map(K)`` evaluates K copies in one call, so Python's call overhead
    (≈ 10 µs) is not counted. Large states (nx ≥ 500): plain calls — the overhead is
    then negligible, and K copies of x would fall out of the cache (measured: the
    mapped timing overstates N = 2,000 by 3×).
    """
    import casadi as ca

    nx = x0.size
    if nx >= 500:
        args1 = [0.0, x0, np.zeros(nz), ca.DM(0, 1), ca.DM(0, 1)]
        f(*args1)
        reps, t0 = 0, time.perf_counter()
        while reps < 3 or time.perf_counter() - t0 < 0.3:
            f(*args1)
            reps += 1
        return (time.perf_counter() - t0) / reps
    K = 50
    fm = f.map(K, "serial")
    X = np.tile(x0.reshape(-1, 1), (1, K))
    args = [np.zeros((1, K)), X, np.zeros((nz, K)), ca.DM(0, K), ca.DM(0, K)]
    fm(*args)
    reps, t0 = 0, time.perf_counter()
    while reps < 3 or time.perf_counter() - t0 < 0.3:
        fm(*args)
        reps += 1
    return (time.perf_counter() - t0) / (reps * K)


def _time_py_rhs(rhs, x0: np.ndarray) -> float:
    rhs(0.0, x0)
    reps, t0 = 0, time.perf_counter()
    while reps < 3 or time.perf_counter() - t0 < 0.3:
        rhs(0.0, x0)
        reps += 1
    return (time.perf_counter() - t0) / reps


def _scipy_run(rhs, x0, t_out, method: str, sparsity, deadline: float) -> dict[str, Any]:
    """One scipy run, stepping by hand (counts steps; stops at the deadline)."""
    from scipy.integrate import BDF, RK45

    kw: dict[str, Any] = {"rtol": 1e-6, "atol": 1e-8}
    if method == "bdf":
        kw["jac_sparsity"] = sparsity
    cls = BDF if method == "bdf" else RK45
    t0 = time.perf_counter()
    solver = cls(rhs, float(t_out[0]), x0, float(t_out[-1]), **kw)
    steps, k, out = 0, 1, [x0]
    status, code = "ok", Status.OK
    while solver.status == "running":
        msg = solver.step()
        steps += 1
        if solver.status == "failed":
            status, code = f"failed at t = {solver.t:.4g} s: {msg}", Status.FAILED
            break
        if k < len(t_out) and solver.t >= t_out[k]:
            dense = solver.dense_output()
            while k < len(t_out) and t_out[k] <= solver.t:
                out.append(dense(t_out[k]))
                k += 1
        if time.perf_counter() > deadline:
            status = f"stopped at the time limit at t = {solver.t:.4g} s"
            code = Status.TIME_LIMIT
            break
    wall = time.perf_counter() - t0
    return {
        "wall": wall,
        "status": status,
        "status_code": code.name,
        "t_reached": float(solver.t),
        "steps": steps,
        "rhs_evals": int(solver.nfev),
        "jac_evals": int(getattr(solver, "njev", 0)),
        "x_final": out[-1],
    }


@dataclass
class Cell:
    """What every set-up of one (N, method) cell starts from.

    Attributes
    ----------
    N : int
    method : BenchMethod
    sc : Scenario
        The benchmark scenario with the common output grid.
    gains : Gains
    cl : ClosedLoop
    t_out : ndarray
        Output times.
    bps : list of float
        Breakpoints (scenario and closed loop).
    deadline : float
        ``time.perf_counter()`` after which no further run is started.
    """

    N: int
    method: BenchMethod
    sc: Any
    gains: Any
    cl: Any
    t_out: np.ndarray
    bps: list[float]
    deadline: float

    @property
    def x0(self) -> np.ndarray:
        """The closed loop's initial state."""
        return np.asarray(self.cl.x0, dtype=float)


def worker(N: int, method: str, runs: int, time_limit: float, horizon: float, out: Path) -> int:
    """Measure one (N, method) cell and write its record to ``out`` (JSON, rewritten as it goes).

    Parameters
    ----------
    N : int
        Number of followers.
    method : str
        One of :data:`METHODS`.
    runs : int
        Integration runs (0: build only).
    time_limit : float
        Wall seconds after which no further run is started.
    horizon : float
        Simulated seconds.
    out : Path
        The record (JSON); the final state goes next to it (``.npy``).

    Returns
    -------
    int
        Exit status 0.
    """
    if method not in BENCH_METHODS:
        raise BenchError(f"--worker: {method!r} unknown (expected one of {', '.join(METHODS)})")
    deadline = time.perf_counter() + time_limit
    rec: dict[str, Any] = {"N": N, "method": method, "status": "started", "runs": 0}
    cell = _cell(N, BENCH_METHODS[method], horizon, deadline, rec, out)
    run_once = _SETUP[cell.method.kind](cell, rec)
    _write(out, rec)
    if runs == 0:  # build-only cell
        rec.update(status="built", peak_rss_mb=_rss_mb(), done=True)
        _write(out, rec)
        return 0
    _measure(run_once, runs, time_limit, deadline, rec, out)
    return 0


def _cell(
    N: int, method: BenchMethod, horizon: float, deadline: float, rec: dict[str, Any], out: Path
) -> Cell:
    """The scenario, gains and closed loop of a cell (their times and sizes into ``rec``)."""
    from generated.schedule import output_grid
    from symbolic.closed_loop import build_closed_loop

    sc = bench_scenario(N, horizon=horizon)
    gains, rec["gains"] = bench_gains(sc)
    H = sc.integration.horizon
    step = H / max(1, round(H / OUTPUT_STEP))
    # every method stores the same grid; api.simulate reads it from the scenario
    sc = dataclasses.replace(sc, integration=dataclasses.replace(sc.integration, output_step=step))
    rec["base_rss_mb"] = _rss_mb()
    _write(out, rec)
    t0 = time.perf_counter()
    cl = build_closed_loop(sc, gains)
    rec["symbolic_s"] = time.perf_counter() - t0
    rec["nx"] = int(np.asarray(cl.x0).size)
    bps = sorted(set(sc.breakpoints()) | set(cl.breakpoints))
    _write(out, rec)
    return Cell(N, method, sc, gains, cl, output_grid(H, step), bps, deadline)


def _traj_result(tr: Any, jtimes: bool = False) -> dict[str, Any]:
    """One run's record entries from a :class:`~generated.values.Trajectory`."""
    st = tr.stats
    res = {
        "wall": st["wall_seconds"],
        "status": "ok" if tr.complete else tr.message,
        "status_code": tr.status.name,
        "t_reached": tr.t_reached,
        "steps": st["steps"],
        "rhs_evals": st["rhs_evals"],
        "jac_evals": st["jac_evals"],
        "x_final": tr.x[-1],
    }
    if jtimes:
        res["jtimes_evals"] = st.get("jtimes_evals")
    return res


def _setup_scipy(cell: Cell, rec: dict[str, Any]) -> Callable[[], dict[str, Any]]:
    """scipy's BDF/RK45 on the hand-written numpy right-hand side."""
    from verify.reference import Reference

    t0 = time.perf_counter()
    ref = Reference(cell.sc, cell.gains)
    rec["symbolic_s"] = time.perf_counter() - t0  # the hand-written RHS needs no build
    x0, kind = cell.x0, cell.method.name.split("-")[1]
    sparsity = None
    if kind == "bdf":
        import scipy.sparse as sps

        r, c = cell.cl.ode.sparsity_jac(1, 0).get_triplet()
        sparsity = sps.csc_matrix((np.ones(len(r)), (r, c)), shape=(x0.size, x0.size))
    rec["plan"] = "numpy RHS" + (", jac_sparsity" if sparsity is not None else "")
    rec["rhs_us"] = 1e6 * _time_py_rhs(ref.rhs, x0)
    return lambda: _scipy_run(ref.rhs, x0, cell.t_out, kind, sparsity, cell.deadline)


def _setup_exact(cell: Cell, rec: dict[str, Any]) -> Callable[[], dict[str, Any]]:
    """Our generated C with the exact sign function and the fixed-step method."""
    from generated.api import build_from_closed_loop, integrate_built
    from generated.values import IntegratorSettings
    from symbolic.closed_loop import build_closed_loop

    sc, meth = cell.sc, integration_method(cell.method.name)
    scx = dataclasses.replace(
        sc,
        options=dataclasses.replace(sc.options, sign="exact"),
        integration=dataclasses.replace(sc.integration, method=meth),
    )
    t0 = time.perf_counter()
    clx = build_closed_loop(scx, cell.gains)
    rec["symbolic_s"] = time.perf_counter() - t0
    built = build_from_closed_loop(clx, meth)
    h = sc.integration.fixed_step
    rec.update(
        codegen_s=built.timings["codegen"],
        compile_s=built.timings["compile"],
        c_bytes=built.library.source_bytes,
        plan=f"ROS2 h = {h:g} s, exact sign",
    )
    rec["rhs_us"] = 1e6 * _time_casadi_rhs(built.dyn, cell.x0)
    s = IntegratorSettings(method=meth, fixed_step=h, chunk=1e9)
    return lambda: _traj_result(integrate_built(built, cell.x0, cell.t_out, s, cell.bps))


def _setup_ours(cell: Cell, rec: dict[str, Any]) -> Callable[[], dict[str, Any]]:
    """Ours and its variants: the functions of ``make sim`` (generated.api) with the
    method's Jacobian strategy (c-idas: the one choose_plan picks for N); ``casadi-vm``
    integrates the symbolic closed loop with the same settings, no code generation."""
    from generated import solvers
    from generated.api import build_from_closed_loop, integrator_settings, simulate
    from generated.largescale import choose_plan
    from generated.solvers.engine import integrate
    from generated.values import CodegenSettings

    meth = integration_method(cell.method.name)
    cg = CodegenSettings(jacobian=cell.method.jacobian)
    label = solvers.get(meth).linear_algebra(cell.N, choose_plan(cell.N, cg.jacobian))
    s = integrator_settings(cell.sc, meth, cg)
    if cell.method.kind == "vm":
        dyn = cell.cl.ode_dyn
        rec.update(codegen_s=0.0, compile_s=0.0, c_bytes=0)
        rec["plan"] = f"CasADi VM, CasADi AD Jacobian, {label}"
    else:
        prepared = solvers.get(meth).prepare(cell.sc, cell.gains)
        built = build_from_closed_loop(cell.cl, meth, cg, prepared=prepared)
        dyn = built.dyn
        libs = built.agents[0] if built.agents else (built.library,)  # per-agent: its kernels
        rec.update(
            codegen_s=built.timings["codegen"],
            compile_s=built.timings["compile"],
            c_bytes=sum(lib.source_bytes for lib in libs),
            cache_hit=built.library.cache_hit,
            plan=label,
        )
    rec["rhs_us"] = 1e6 * _time_casadi_rhs(dyn, cell.x0, int(dyn.size1_in(2)))

    def run_once() -> dict[str, Any]:
        if cell.method.kind == "vm":
            tr = integrate(dyn, cell.x0, cell.t_out, s, breakpoints=cell.bps)
        else:
            tr = simulate(built, cell.sc, s)  # exactly what make sim integrates
        return _traj_result(tr, jtimes=True)

    return run_once


#: the set-up of each :attr:`BenchMethod.kind`
_SETUP = {"scipy": _setup_scipy, "exact": _setup_exact, "ours": _setup_ours, "vm": _setup_ours}


def _measure(
    run_once: Callable[[], dict[str, Any]],
    runs: int,
    time_limit: float,
    deadline: float,
    rec: dict[str, Any],
    out: Path,
) -> None:
    """Up to ``runs`` runs while they fit before the deadline; the record rewritten after each."""
    walls: list[float] = []
    for k in range(runs):
        res = run_once()
        walls.append(res.pop("wall"))
        xf = res.pop("x_final")
        rec.update(res)
        rec["runs"] = len(walls)
        rec["walls"] = walls
        if k == 0:
            np.save(out.with_suffix(".npy"), np.asarray(xf, dtype=float))
        _write(out, rec)
        if res["status_code"] != Status.OK.name:
            break
        left = deadline - time.perf_counter()
        if k + 1 < runs and walls[-1] > left:  # the next run would not fit
            rec["runs_note"] = f"{len(walls)} of {runs} runs (time limit {time_limit:g} s)"
            break
    rec["peak_rss_mb"] = _rss_mb()
    rec["done"] = True
    _write(out, rec)
