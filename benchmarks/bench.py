"""``make bench``: our generated C against what users would use instead, from 5 to 2,000 agents.

::

    python -m benchmarks.bench                 # N = 5, 50, 500, 2000; all methods
    python -m benchmarks.bench --quick         # N = 5, one run each (smoke test)
    python -m benchmarks.bench --sizes 5,50 --methods c-cvode-native,scipy-bdf --runs 3

Every (N, method) cell runs in its own subprocess (its own peak RSS, a hard wall-clock
limit); the parent prints the table and writes ``out/bench/bench.csv`` and
``out/bench/scaling.png``. Methods (same scenario, rtol 1e-6, atol 1e-8, tanh sign for
the variable-step methods, the same output grid):

``scipy-bdf``, ``scipy-rk45``
    :func:`scipy.integrate.BDF`/``RK45`` on the plain numpy right-hand side of
    :class:`verify.reference.Reference` (what a user writes by hand). BDF gets the
    Jacobian's sparsity pattern (``jac_sparsity``): without it scipy differences a
    dense nx×nx Jacobian (6 GB at N = 2,000).
``casadi-vm``
    The symbolic closed loop (``ClosedLoop.ode_dyn``) evaluated by CasADi's virtual
    machine, no code generation, CVODES with CasADi's own Jacobian.
``c-cvode-native``
    Our generated C + SUNDIALS CVODE driven from C, one call from Python per run
    (method ``native``): up to N = 20 the whole loop's right-hand side, Jacobian and
    sparse LU (:mod:`generated.native`); above, one follower's block evaluated along
    the acyclic graph, Newton systems solved by block forward substitution
    (:mod:`generated.dag`).
``c-cvodes-direct``, ``c-cvodes-gmres``
    Our generated C + CVODES through CasADi's interface with the two plans of
    :mod:`generated.largescale` (``jacobian="sparse"``: sparse direct Jacobian /
    ``"jvp"``: matrix-free GMRES).

All of ours are built and integrated by the functions of ``make sim``
(:func:`generated.api.build_from_closed_loop`, :func:`generated.api.integrator_settings`,
:func:`generated.api.simulate`). "Ours" — the denominator of the ratio column — is
:func:`ours_method`: ``c-cvode-native`` at every N (the shipped scenarios' method).
``c-idas``
    Our generated C (DAE form) + IDAS, same plan as ours, same functions.
``fixed``
    The fixed-step ROS2 method of :mod:`generated.integrate` with the exact sign
    function (its purpose), step ``integration.fixed_step``.

Compile cache: unless ``--warm-cache``, the cells build into a fresh cache
``<out>/build`` (emptied at the start), so every ``codegen_s``/``compile_s`` is a real
build, never a cache hit from an earlier ``make sim``; cells of one run share it (the
runs of a cell, and methods with the same library, reuse it within the run).

Scenarios: N = 5 is ``scenarios/paper.toml``; larger N are built by
:func:`bench_scenario` from it: the paper's follower model and faults (cycled), offsets
on a circle of radius 4, p_i(0) = b_i0 + noise, and a random acyclic sparse graph in
which every follower hears its spanning-tree parent and up to two more earlier
followers (fixed seed), with one follower in a hundred pinned to the leader.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import ToolkitError, run_cli
from generated.solvers import Status

SIZES = (5, 50, 500, 2000)


@dataclass(frozen=True)
class BenchMethod:
    """A benchmark method: what it runs and how.

    Attributes
    ----------
    name : str
        The benchmark's name (``c-cvode-native``).
    kind : str
        How the worker sets it up: ``scipy`` (hand-written numpy RHS), ``vm`` (CasADi's
        virtual machine, no code generation), ``ours`` (the functions of ``make sim``) or
        ``exact`` (``ours`` with the exact sign function).
    solver : str or None
        The registered integration method it runs (:func:`generated.solvers.get`).
    jacobian : str or None
        ``CodegenSettings.jacobian`` (``auto``: the plan of ``make sim``).
    cheap_build : bool
        Its build is cheap at any N: after it hits the time limit, larger N still get a
        build-only cell (build times, C size, RHS time) instead of nothing.
    """

    name: str
    kind: str
    solver: str | None = None
    jacobian: str | None = None
    cheap_build: bool = True


#: the benchmark's methods, in table order
BENCH_METHODS = {
    m.name: m
    for m in (
        BenchMethod("scipy-bdf", "scipy"),
        BenchMethod("scipy-rk45", "scipy"),
        BenchMethod("casadi-vm", "vm", "cvodes", "sparse"),
        BenchMethod("c-cvode-native", "ours", "native", "auto"),
        BenchMethod("c-cvodes-direct", "ours", "cvodes", "sparse", cheap_build=False),
        BenchMethod("c-cvodes-gmres", "ours", "cvodes", "jvp"),
        BenchMethod("c-idas", "ours", "idas", "auto"),
        BenchMethod("fixed", "exact", "fixed", cheap_build=False),
    )
}
METHODS = tuple(BENCH_METHODS)
BENCH_SEED = 20260121
PAPER = Path(__file__).resolve().parent.parent / "scenarios" / "paper.toml"
OUTPUT_STEP = 0.1  # output grid of every method (states stored there)
#: methods whose build is cheap at any N (:attr:`BenchMethod.cheap_build`)
CHEAP_BUILDS = tuple(m.name for m in BENCH_METHODS.values() if m.cheap_build)


def integration_method(method: str) -> str:
    """The registered integration method a benchmark method runs.

    Parameters
    ----------
    method : str
        One of the CasADi/generated-C methods of :data:`METHODS`.

    Raises
    ------
    BenchError
        For a benchmark method without one (the scipy methods) or an unknown name.
    """
    m = BENCH_METHODS.get(method)
    if m is None or m.solver is None:
        raise BenchError(f"{method!r} runs no registered integration method")
    from generated import solvers

    return solvers.get(m.solver).name


def ours_method(N: int) -> str:
    """The benchmark method that is ours at N: what ``make sim`` runs for N followers.

    ``c-cvode-native`` (method ``native``) at every N: the whole-loop build up to
    N = 20, the graph-ordered blocks above (:mod:`generated.dag`; the benchmark's graphs
    are acyclic and its followers share one model).

    Parameters
    ----------
    N : int
        Number of followers.
    """
    if int(N) < 1:
        raise BenchError(f"N: {N} must be >= 1")
    return "c-cvode-native"


class BenchError(ToolkitError):
    """Bad benchmark arguments."""


# ----------------------------------------------------------------------------- scenarios
def random_graph(N: int, seed: int = BENCH_SEED) -> tuple[np.ndarray, np.ndarray]:
    """A random sparse acyclic graph with a spanning tree rooted at the leader.

    Follower 0 is pinned; follower i ≥ 1 hears a random parent j < i (the spanning
    tree) and up to two more random earlier followers (about 3 neighbours each);
    ``max(1, N // 100)`` followers are pinned (follower 0 among them). Acyclic, so L + B is triangular with
    eigenvalues ≥ 1 (the observer network is stable for any N).

    Parameters
    ----------
    N : int
        Number of followers (>= 1).
    seed : int
        Random seed.

    Returns
    -------
    (adjacency, pinning)
        ``adjacency[i, j] = 1`` when follower i hears follower j.
    """
    if N < 1:
        raise BenchError(f"N: {N} must be >= 1")
    rng = np.random.default_rng(seed)
    A = np.zeros((N, N))
    pin = np.zeros(N)
    pin[0] = 1.0
    for i in range(1, N):
        A[i, int(rng.integers(0, i))] = 1.0
        extra = rng.choice(i, size=min(2, i), replace=False)
        A[i, extra] = 1.0
    k = max(1, N // 100)
    if k > 1:  # more pinned followers besides follower 0
        pin[1 + rng.choice(N - 1, k - 1, replace=False)] = 1.0
    return A, pin


def bench_scenario(N: int, seed: int = BENCH_SEED, horizon: float | None = None):
    """The benchmark scenario with N followers (N = 5: the paper's own scenario).

    Parameters
    ----------
    N : int
    seed : int
        Graph and initial-position seed.
    horizon : float, optional
        Override of ``integration.horizon`` (default: the paper's 20 s).

    Returns
    -------
    Scenario
        With ``integration.method`` that of :func:`ours_method` (``native``).
    """
    from core.scenario import Graph, load_scenario

    base = load_scenario(PAPER)
    if N == base.N:
        sc = base
    else:
        A, pin = random_graph(N, seed)
        rng = np.random.default_rng(seed + 1)
        followers = []
        for i in range(N):
            src = base.followers[i % base.N]
            ang = 2.0 * math.pi * i / N
            b0 = np.array([4.0 * math.cos(ang), 4.0 * math.sin(ang)])
            p0 = b0 + rng.normal(scale=0.5, size=2)
            followers.append(dataclasses.replace(src, b0=_frozen(b0), p0=_frozen(p0)))

        def rep(a: Any) -> np.ndarray:  # first agent's value for every agent
            return _frozen(np.repeat(np.asarray(a)[:1], N, axis=0))

        o, c, ini = base.observer, base.controller, base.initial
        sc = dataclasses.replace(
            base,
            name=f"bench-N{N}",
            path=f"{PAPER} (benchmarks.bench: N = {N}, seed {seed})",
            sha256=f"bench-N{N}-seed{seed}-{base.sha256}",
            description=f"benchmark: {N} followers on a random acyclic graph (seed {seed})",
            graph=Graph(adjacency=_frozen(A), pinning=_frozen(pin)),
            followers=tuple(followers),
            observer=dataclasses.replace(
                o, alpha1=rep(o.alpha1), alpha1_bar=rep(o.alpha1_bar), phi0=rep(o.phi0)
            ),
            controller=dataclasses.replace(
                c,
                **{
                    k: rep(getattr(c, k))
                    for k in ("Lambda", "k1", "k2", "gamma", "sigma", "ghat_ref")
                },
            ),
            initial=dataclasses.replace(
                ini,
                eta=rep(ini.eta),
                mu=rep(ini.mu),
                theta_hat=rep(ini.theta_hat),
                ghat=rep(ini.ghat),
            ),
        )
    # the method make sim would use at this N
    ig = dataclasses.replace(sc.integration, method=integration_method(ours_method(N)))
    if horizon is not None:
        ig = dataclasses.replace(ig, horizon=float(horizon))
    return dataclasses.replace(sc, integration=ig)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def bench_gains(sc):
    """Gains for the benchmark: :func:`synthesis.synthesize` (uncertified warnings allowed).

    Parameters
    ----------
    sc : Scenario
        A :func:`bench_scenario`.

    Returns
    -------
    (Gains, str)
        The gains and where they came from.
    """
    from synthesis import synthesize

    g = synthesize(sc)
    cert = g.certificate or {}
    tag = "synthesize" + ("" if cert.get("passed", True) else " (certificate warnings)")
    return g, tag


# ----------------------------------------------------------------------------- worker
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
    from generated.integrate import output_grid
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
    """One run's record entries from a :class:`~generated.integrate.Trajectory`."""
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
    from generated.integrate import IntegratorSettings
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
    from generated.codegen import CodegenSettings
    from generated.integrate import integrate
    from generated.largescale import choose_plan

    meth = integration_method(cell.method.name)
    cg = CodegenSettings(jacobian=cell.method.jacobian)
    label = solvers.get(meth).linear_algebra(cell.N, choose_plan(cell.N, cg.jacobian))
    s = integrator_settings(cell.sc, meth, cg)
    if cell.method.kind == "vm":
        dyn = cell.cl.ode_dyn
        rec.update(codegen_s=0.0, compile_s=0.0, c_bytes=0)
        rec["plan"] = f"CasADi VM, CasADi AD Jacobian, {label}"
    else:
        cascade = solvers.get(meth).prepare(cell.sc, cell.gains)
        built = build_from_closed_loop(cell.cl, meth, cg, cascade=cascade)
        dyn = built.dyn
        dag_bytes = built.dag[0].source_bytes if built.dag else 0  # second library
        rec.update(
            codegen_s=built.timings["codegen"],
            compile_s=built.timings["compile"],
            c_bytes=built.library.source_bytes + dag_bytes,
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


# ----------------------------------------------------------------------------- parent
def run_cell(
    N: int, method: str, runs: int, time_limit: float, horizon: float, folder: Path
) -> dict[str, Any]:
    """Run one cell in a subprocess with a hard wall-clock limit; return its record.

    Parameters
    ----------
    N : int
        Number of followers.
    method : str
        One of :data:`METHODS`.
    runs : int
        Integration runs (0: build only).
    time_limit : float
        Seconds per cell (the subprocess is killed 60 s after it).
    horizon : float
        Simulated seconds.
    folder : Path
        Output folder (records under ``cells/``).
    """
    rec_path = folder / "cells" / f"N{N}-{method}.json"
    rec_path.parent.mkdir(parents=True, exist_ok=True)
    for p in (rec_path, rec_path.with_suffix(".npy")):
        p.unlink(missing_ok=True)
    cmd = [sys.executable, "-m", "benchmarks.bench", "--worker", str(N), method]
    cmd += ["--runs", str(runs), "--time-limit", str(time_limit), "--horizon", str(horizon)]
    cmd += ["--record", str(rec_path)]
    t0 = time.perf_counter()
    hard = time_limit + 60.0  # grace for interpreter start, synthesis and builds
    status, code = None, Status.FAILED
    # own session: on the time limit the whole group (the worker and its gcc) is killed
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        _, err = proc.communicate(timeout=hard)
        if proc.returncode != 0:
            lines = [ln for ln in err.splitlines() if ln.strip()]
            status = "error: " + (lines[-1] if lines else f"exit {proc.returncode}")
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        status = f"stopped at the time limit ({hard:.0f} s wall incl. build)"
        code = Status.TIME_LIMIT
    rec: dict[str, Any] = {"N": N, "method": method}
    if rec_path.is_file():
        try:
            rec = json.loads(rec_path.read_text())
        except json.JSONDecodeError:
            pass
    if status is not None:
        rec["status"] = status if not rec.get("runs") else f"{rec.get('status')}; {status}"
        rec["status_code"] = code.name
    elif not rec.get("done"):
        rec["status"] = "error: worker ended without a result"
        rec["status_code"] = Status.FAILED.name
    rec["cell_wall_s"] = time.perf_counter() - t0
    walls = rec.get("walls") or []
    if walls:
        rec["int_median_s"] = statistics.median(walls)
        rec["int_min_s"] = min(walls)
        rec["int_max_s"] = max(walls)
        if rec.get("rhs_evals"):
            rec["int_per_eval_us"] = 1e6 * walls[0] / rec["rhs_evals"]
    npy = rec_path.with_suffix(".npy")
    if npy.is_file():
        rec["_x_final"] = np.load(npy)
    return rec


COLUMNS = [
    "N",
    "nx",
    "method",
    "plan",
    "status",
    "runs",
    "int_median_s",
    "int_min_s",
    "int_max_s",
    "ratio_to_ours",
    "symbolic_s",
    "codegen_s",
    "compile_s",
    "cache_hit",
    "c_bytes",
    "steps",
    "rhs_evals",
    "jac_evals",
    "jtimes_evals",
    "rhs_us",
    "peak_rss_mb",
    "base_rss_mb",
    "t_reached",
    "rel_dx_final_vs_ours",
    "gains",
]


def finish(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Add the ratio to ours and the final-state difference to ours, per N.

    Parameters
    ----------
    records : list of dict
        Cell records (changed in place and returned).
    """
    for N in sorted({r["N"] for r in records}):
        ours_name = ours_method(N)
        ours = next((r for r in records if r["N"] == N and r["method"] == ours_name), None)
        for r in records:
            if r["N"] != N:
                continue
            r["ours"] = r["method"] == ours_name
            ok = r.get("status") == "ok"
            if ours and ours.get("status") == "ok" and ours.get("int_median_s") and ok:
                r["ratio_to_ours"] = r["int_median_s"] / ours["int_median_s"]
            xa, xb = r.get("_x_final"), (ours or {}).get("_x_final")
            complete = ok and (ours or {}).get("status") == "ok"
            if complete and xa is not None and xb is not None and xa.shape == xb.shape:
                r["rel_dx_final_vs_ours"] = float(
                    np.max(np.abs(xa - xb) / np.maximum(1.0, np.abs(xb)))
                )
    return records


def write_csv(records: list[dict[str, Any]], path: Path) -> Path:
    """``bench.csv`` (atomically).

    Parameters
    ----------
    records : list of dict
        Cell records.
    path : Path
        The CSV file.
    """
    import csv
    import io

    from core.artifacts import atomic_write_text

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(COLUMNS)
    for r in records:
        w.writerow([_fmt_csv(r.get(c)) for c in COLUMNS])
    return atomic_write_text(path, buf.getvalue())


def _fmt_csv(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def table(records: list[dict[str, Any]]) -> str:
    """The printed table.

    Parameters
    ----------
    records : list of dict
        Cell records after :func:`finish`.
    """
    head = (
        "N",
        "method",
        "int med [s]",
        "min–max [s]",
        "×ours",
        "steps",
        "RHS ev",
        "µs/RHS",
        "sym [s]",
        "cg+cc [s]",
        "C [kB]",
        "RSS [MB]",
        "status",
    )
    rows = [head]
    for r in records:
        med = r.get("int_median_s")
        mm = f"{r['int_min_s']:.3g}–{r['int_max_s']:.3g}" if med is not None else ""
        cgcc = (r.get("codegen_s") or 0.0) + (r.get("compile_s") or 0.0)
        star = "*" if r.get("ours") else ""
        rows.append(
            (
                str(r["N"]),
                r["method"] + star,
                _g(med),
                mm,
                _g(r.get("ratio_to_ours")),
                _g(r.get("steps")),
                _g(r.get("rhs_evals")),
                _g(r.get("rhs_us")),
                _g(r.get("symbolic_s")),
                _g(cgcc) if "codegen_s" in r else "",
                _g((r.get("c_bytes") or 0) / 1000) if r.get("c_bytes") else "",
                _g(r.get("peak_rss_mb")),
                _status_short(r),
            )
        )
    widths = [max(len(row[k]) for row in rows) for k in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines) + "\n(* = ours: what make sim runs for N, benchmarks.bench.ours_method)"


def markdown(records: list[dict[str, Any]]) -> str:
    """The results as a Markdown table (``out/bench/bench.md``, for the README).

    Parameters
    ----------
    records : list of dict
        Cell records after :func:`finish`.
    """
    head = [
        "N",
        "method",
        "integration [s] median (min–max)",
        "× ours",
        "steps",
        "RHS evals",
        "µs / RHS",
        "symbolic [s]",
        "codegen + gcc [s]",
        "C [kB]",
        "peak RSS [MB]",
        "status",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in records:
        med = r.get("int_median_s")
        t = f"{med:.3g} ({r['int_min_s']:.3g}–{r['int_max_s']:.3g})" if med is not None else ""
        cgcc = (r.get("codegen_s") or 0.0) + (r.get("compile_s") or 0.0)
        cells = [
            str(r["N"]),
            r["method"] + (" *" if r.get("ours") else ""),
            t,
            _g(r.get("ratio_to_ours")),
            _g(r.get("steps")),
            _g(r.get("rhs_evals")),
            _g(r.get("rhs_us")),
            _g(r.get("symbolic_s")),
            _g(cgcc) if "codegen_s" in r else "",
            _g(r["c_bytes"] / 1000) if r.get("c_bytes") else "",
            _g(r.get("peak_rss_mb")),
            _status_short(r).replace("|", "/"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _status_short(r: dict[str, Any]) -> str:
    s = str(r.get("status", ""))
    note = r.get("runs_note")
    return f"{s} [{note}]" if note else s


def _g(v: Any) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, int):
        return str(v)
    return f"{v:.3g}"


def plot(records: list[dict[str, Any]], path: Path) -> Path | None:
    """``scaling.png``: integration time against N (log-log), one line per method.

    Parameters
    ----------
    records : list of dict
        Cell records after :func:`finish`.
    path : Path
        The PNG file.
    """
    import matplotlib

    matplotlib.use("Agg")
    import io

    import matplotlib.pyplot as plt

    from core.artifacts import atomic_write_bytes

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for meth in METHODS:
        mine = [r for r in records if r["method"] == meth]
        pts = [
            (r["N"], r["int_median_s"])
            for r in mine
            if r.get("status") == "ok" and r.get("int_median_s")
        ]
        # stopped or failed cells that ran (not the "not run" ones), at their wall time
        bad = [
            (r["N"], r["cell_wall_s"])
            for r in mine
            if r.get("status") != "ok"
            and r.get("cell_wall_s")
            and not str(r.get("status", "")).startswith(("not run", "build only"))
        ]
        if not pts and not bad:
            continue
        xy = list(zip(*sorted(pts), strict=True)) if pts else [[], []]
        (line,) = ax.loglog(*xy, "o-", label=meth)
        if bad:
            ax.loglog(*zip(*sorted(bad), strict=True), "x", color=line.get_color(), ms=8)
    Ns = sorted({r["N"] for r in records})
    if len(Ns) > 1:
        ax.loglog(Ns, [0.05 * n / Ns[0] for n in Ns], "k:", lw=0.8, label="∝ N")
    ax.set_xlabel("followers N")
    ax.set_ylabel("integration wall time, 20 s horizon [s]")
    ax.set_title("x: stopped at the time limit or failed (at the cell's wall time)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue())


def _parser() -> argparse.ArgumentParser:
    """The command line of :func:`main`."""
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.bench", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--quick", action="store_true", help="N = 5 only, one run per method")
    ap.add_argument("--sizes", default=None, help="comma-separated N (default 5,50,500,2000)")
    ap.add_argument("--methods", default=None, help=f"comma-separated, from {','.join(METHODS)}")
    ap.add_argument("--runs", type=int, default=None, help="runs per cell (default 5; quick 1)")
    ap.add_argument(
        "--time-limit", type=float, default=None, help="seconds per cell (default 120; quick 60)"
    )
    ap.add_argument(
        "--ours-time-limit",
        type=float,
        default=None,
        help="seconds per cell for ours (default 1500, at least 4x --time-limit: "
        "ours completes N = 2,000 in about 700 s here)",
    )
    ap.add_argument("--horizon", type=float, default=20.0, help="simulated seconds (default 20)")
    ap.add_argument("--out", default=None, help="output folder (default out/bench)")
    ap.add_argument(
        "--warm-cache",
        action="store_true",
        help="reuse compiled libraries from the build cache (default: a fresh cache "
        "in <out>/build, so codegen and gcc times are measured, not cache hits)",
    )
    ap.add_argument("--worker", nargs=2, metavar=("N", "METHOD"), help=argparse.SUPPRESS)
    ap.add_argument("--record", default=None, help=argparse.SUPPRESS)
    return ap


def main(argv: list[str]) -> int:
    """Command line of ``python -m benchmarks.bench`` (see the module docstring).

    Parameters
    ----------
    argv : list of str
        Arguments without the program name.
    """
    a = _parser().parse_args(argv)
    runs = a.runs if a.runs is not None else (1 if a.quick else 5)
    limit = a.time_limit if a.time_limit is not None else (60.0 if a.quick else 120.0)
    if runs < 1 and not a.worker:
        raise BenchError(f"--runs: {runs} must be >= 1")
    if not (limit > 0 and a.horizon > 0):
        raise BenchError("--time-limit and --horizon must be > 0")
    if a.worker:
        N, meth = int(a.worker[0]), a.worker[1]
        return worker(N, meth, runs, limit, a.horizon, Path(a.record))
    sizes = (5,) if a.quick and a.sizes is None else _ints(a.sizes, SIZES, "--sizes")
    methods = tuple(a.methods.split(",")) if a.methods else METHODS
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise BenchError(
            f"--methods: {', '.join(bad)} unknown (expected some of {', '.join(METHODS)})"
        )
    folder = _bench_folder(a.out, a.warm_cache)
    print(
        f"bench: N = {', '.join(map(str, sizes))}; {len(methods)} methods; {runs} run(s); "
        f"limit {limit:g} s per cell; horizon {a.horizon:g} s; {os.cpu_count()} CPUs",
        flush=True,
    )
    ours_limit = a.ours_time_limit if a.ours_time_limit is not None else max(1500.0, 4.0 * limit)
    limits = (limit, ours_limit)
    records = finish(_run_cells(sizes, methods, runs, limits, a.horizon, folder))
    _report(records, folder)
    return 0


def _bench_folder(out: str | None, warm_cache: bool) -> Path:
    """The output folder; unless ``warm_cache``, an emptied build cache in it for the cells."""
    from core.artifacts import OUT_ROOT

    folder = Path(out) if out else OUT_ROOT / "bench"
    folder.mkdir(parents=True, exist_ok=True)
    if not warm_cache:  # the cells (subprocesses) inherit the empty cache
        shutil.rmtree(folder / "build", ignore_errors=True)
        os.environ["HITL_BUILD_DIR"] = str((folder / "build").resolve())
    return folder


def _run_cells(
    sizes: tuple[int, ...],
    methods: tuple[str, ...],
    runs: int,
    limits: tuple[float, float],
    horizon: float,
    folder: Path,
) -> list[dict[str, Any]]:
    """Every (N, method) cell in order; a method that hit the time limit at some N gets a
    build-only cell (cheap builds) or a 'not run' record at larger N.

    ``limits``: seconds per cell for the others and for ours.
    """
    records = []
    stopped: dict[str, int] = {}  # method -> first N where it hit the time limit
    for N in sizes:
        ours_name = ours_method(N)
        for meth in methods:
            why = f"stopped at the time limit at N = {stopped.get(meth)}"
            if meth in stopped and meth in CHEAP_BUILDS:  # still measure the build and RHS
                r = run_cell(N, meth, 0, limits[0], horizon, folder)
                if r.get("status") == "built":
                    r["status"] = f"build only: not integrated ({why})"
            elif meth in stopped:  # reported, not silently skipped
                r = {"N": N, "method": meth, "status": f"not run: {why}"}
            else:
                lim = limits[1] if meth == ours_name else limits[0]
                r = run_cell(N, meth, runs, lim, horizon, folder)
                if r.get("status_code") == Status.TIME_LIMIT.name:
                    stopped[meth] = N
            records.append(r)
            median = _g(r.get("int_median_s"))
            print(f"  N={N:<5d} {meth:<16s} {median:>8s} s  {_status_short(r)}", flush=True)
    return records


def _report(records: list[dict[str, Any]], folder: Path) -> None:
    """bench.csv, bench.md and scaling.png in ``folder``; the table on stdout."""
    from core.artifacts import atomic_write_text
    from core.provenance import provenance, provenance_line, write_provenance

    csv_path = write_csv(records, folder / "bench.csv")
    png = plot(records, folder / "scaling.png")
    p = provenance()
    write_provenance(folder, p)
    atomic_write_text(folder / "bench.md", f"{provenance_line(p)}\n\n{markdown(records)}")
    print(table(records))
    print(f"wrote {csv_path}, {folder / 'bench.md'} and {png}")


def _ints(text: str | None, default: tuple[int, ...], what: str) -> tuple[int, ...]:
    if text is None:
        return default
    try:
        vals = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise BenchError(f"{what}: {text!r} is not a comma-separated list of integers") from None
    if not vals or min(vals) < 1:
        raise BenchError(f"{what}: {text!r} needs integers >= 1")
    return vals


if __name__ == "__main__":
    sys.exit(run_cli(main))
