"""The per-agent driver (generated/agents.py) beside today's native path, in one run.

``python -m benchmarks.agents`` (run by ``make bench``) measures, on this machine:

* the paper scenario (N = 5): the whole-loop native driver against the per-agent
  driver, ``--runs`` integrations of each, alternating; their median times and the
  median of the per-pair ratios (``ratio_to_native``);
* N followers (default 2,000) of the benchmark scenario (:func:`benchmarks.scenarios.
  bench_scenario`) on its random acyclic graph and on the same graph with random extra
  links until the mean in-degree is 3 (cyclic), with 1 and 2 threads;
* the Newton solvers side by side (forward substitution, dense LU, GMRES) where each
  applies, and on the cyclic graph a sparse direct solver (SuperLU) projected onto the
  GMRES run's counters (:mod:`benchmarks.sparse_direct`): its linear algebra alone
  for the same steps, against the GMRES run's whole time.

Results: the table on stdout and ``out/bench/agents.csv``. Each integration reports
CVODE's counters; the wall time excludes the symbolic build, synthesis and gcc (listed
separately).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from core.artifacts import atomic_write_text
from core.cli_args import count, positive
from core.errors import CliParser, UsageError, run_cli

CYCLIC_SEED = 20260126
PAPER = "scenarios/paper.toml"


def cyclic_variant(sc: Any, mean_indegree: float = 3.0, seed: int = CYCLIC_SEED) -> Any:
    """``sc`` with random extra links (i hears j, i ≠ j) until the mean in-degree is reached.

    Parameters
    ----------
    sc : Scenario
    mean_indegree : float
    seed : int
    """
    from core.scenario import Graph

    rng = np.random.default_rng(seed)
    A = np.array(sc.graph.adjacency, dtype=float)
    N = A.shape[0]
    while (A != 0).sum() < mean_indegree * N:
        i, j = (int(v) for v in rng.integers(N, size=2))
        if i != j:
            A[i, j] = 1.0
    g = Graph(adjacency=A, pinning=np.array(sc.graph.pinning, dtype=float))
    return dataclasses.replace(sc, graph=g, name=f"{sc.name}-cyclic")


def _row(case: str, method: str, seconds: float, traj: Any, **extra: Any) -> dict[str, Any]:
    st = traj.stats
    keys = ("steps", "rhs_evals", "jac_evals", "lin_setups", "newton_iters", "krylov_iters")
    return {
        "case": case,
        "method": method,
        "seconds": round(seconds, 3),
        "complete": bool(traj.complete),
        **{k: int(st.get(k, 0)) for k in keys},
        **extra,
    }


def _timed(f: Any) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = f()
    return time.perf_counter() - t0, out


def _paired_runs(runs: int, f: Any, g: Any) -> tuple[float, float, float, Any, Any]:
    """f and g alternately ``runs`` times: their median times and the median of the
    per-pair ratios g/f (pairs are seconds apart, so the machine's drift cancels)."""
    tf, tg = [], []
    for _ in range(runs):
        a, out_f = _timed(f)
        b, out_g = _timed(g)
        tf.append(a)
        tg.append(b)
    ratio = float(np.median(np.array(tg) / np.array(tf)))
    return float(np.median(tf)), float(np.median(tg)), ratio, out_f, out_g


def paper_rows(runs: int, build_root: str | None) -> list[dict[str, Any]]:
    """The paper scenario: whole-loop native against the per-agent driver.

    Parameters
    ----------
    runs : int
        Timed repetitions of each integration.
    build_root : str, optional
        Where generated libraries are built (None: the default).
    """
    from core.scenario import load_scenario
    from generated import agents, api
    from generated.schedule import output_grid
    from generated.values import CodegenSettings

    sc = load_scenario(PAPER)
    gains = api.scenario_gains(sc, "paper")
    cg = CodegenSettings(build_root=build_root)
    built = api.build(sc, gains, "native", cg, runtime_parameters=True)  # whole loop: baseline
    settings = api.integrator_settings(sc, "native", cg)
    t_out = output_grid(sc.integration.horizon, sc.integration.output_step)
    x0, bps = built.closed_loop.x0, api.breakpoints(built, sc)
    libs, model = agents.build_models(sc, gains, cg)
    prob = agents.problem(sc, gains, model)
    paths = [lib.path for lib in libs]
    t_ref, t_ag, ratio, ref, tr = _paired_runs(
        runs,
        lambda: api.integrate_built(built, x0, t_out, settings, bps),
        lambda: agents.run(paths, prob, x0, t_out, settings, breakpoints=bps),
    )
    d = float((np.abs(tr.x - ref.x) / np.maximum(1.0, np.abs(ref.x))).max())
    return [
        _row("paper N=5", "native (whole loop)", t_ref, ref),
        _row("paper N=5", "agents", t_ag, tr, ratio_to_native=round(ratio, 2), rel_dx=d),
    ]


def large_rows(
    N: int, horizon: float, threads: list[int], solvers: list[str], build_root: str | None
) -> list[dict[str, Any]]:
    """N followers, acyclic and cyclic, per thread count and solver.

    Parameters
    ----------
    N : int
        Number of followers.
    horizon : float
        Integration horizon (s).
    threads : list of int
        Thread counts to run (more than 1 builds with OpenMP).
    solvers : list of str
        Linear solvers (``forward`` is skipped on a cyclic graph, ``dense`` on large ones).
    build_root : str, optional
        Where generated libraries are built (None: the default).
    """
    from benchmarks.scenarios import bench_gains, bench_scenario
    from generated import agents
    from generated.schedule import output_grid
    from generated.values import CodegenSettings, IntegratorSettings

    rows = []
    base = bench_scenario(N, horizon=horizon)
    for kind, sc in (("acyclic", base), ("cyclic", cyclic_variant(base))):
        t0 = time.perf_counter()
        gains = bench_gains(sc)[0]
        x0 = agents.initial_state(sc)
        t1 = time.perf_counter()
        cg = CodegenSettings(build_root=build_root)
        builds = {th: agents.build_models(sc, gains, cg, openmp=th > 1) for th in set(threads)}
        prob = agents.problem(sc, gains, builds[threads[0]][1])
        t2 = time.perf_counter()
        s = IntegratorSettings(method="native", rtol=1e-6, atol=1e-8, max_steps=1000000)
        t_out = output_grid(horizon, 0.1)
        indeg = float(np.mean(np.diff(prob.topologies[0].ptr)))
        for solver in solvers:
            if solver == "forward" and not prob.acyclic:
                continue
            if solver == "dense" and N * 3 * prob.n > 6000:
                continue
            for th in threads:
                ls = agents.LinearSettings(solver=solver, threads=th)
                t3 = time.perf_counter()
                tr = agents.run(
                    [lib.path for lib in builds[th][0]],
                    prob,
                    x0,
                    t_out,
                    s,
                    linear=ls,
                    breakpoints=sc.breakpoints(),
                )
                rows.append(
                    _row(
                        f"N={N} {kind} (in-degree {indeg:.2f})",
                        f"agents {solver}, {th} thread(s)",
                        time.perf_counter() - t3,
                        tr,
                        setup_s=round(t1 - t0, 1),
                        build_s=round(t2 - t1, 1),
                    )
                )
                print(rows[-1], flush=True)
                if not prob.acyclic and solver in ("auto", "gmres"):
                    rows.append(_direct_row(prob, rows[-1]))
                    print(rows[-1], flush=True)
    return rows


def _direct_row(prob: Any, gmres: dict[str, Any]) -> dict[str, Any]:
    """SuperLU on the jets system of ``prob``'s first topology, projected onto the
    counters of the GMRES run ``gmres`` (benchmarks/sparse_direct.py)."""
    from benchmarks.sparse_direct import jets_matrix, superlu_cost

    top = prob.topologies[0]
    cost = superlu_cost(jets_matrix(top.ptr, top.idx, top.w, 3 * prob.n))
    projected = cost.projected_s(gmres["lin_setups"], gmres["newton_iters"])
    return {
        "case": gmres["case"],
        "method": "sparse direct (SuperLU, projected on the run above)",
        "seconds": round(projected, 3),
        "factor_ms": round(cost.factor_s * 1e3, 3),
        "solve_ms": round(cost.solve_s * 1e3, 4),
        "fill": cost.fill,
        "two_cores": round(projected / 2, 3),
        "ratio_to_gmres": round(projected / gmres["seconds"], 2),
    }


def _table(rows: list[dict[str, Any]]) -> str:
    cols = list(dict.fromkeys(k for r in rows for k in r))
    lines = [",".join(cols)]
    lines += [",".join(str(r.get(c, "")) for c in cols) for r in rows]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks, print the rows and write ``agents.csv`` under ``--out``.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (None: ``sys.argv``).
    """
    ap = CliParser(prog="python -m benchmarks.agents", description=__doc__)
    ap.add_argument("--sizes", default="2000", help="comma-separated N of the large runs")
    ap.add_argument("--horizon", type=positive, default=20.0)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--solvers", default="auto")
    ap.add_argument("--runs", type=count, default=3)
    ap.add_argument("--out", default="out/bench")
    ap.add_argument("--build-root", default=None)
    a = ap.parse_args(argv)
    sizes, threads = _counts(a.sizes, "--sizes"), _counts(a.threads, "--threads")
    solvers = [v for v in a.solvers.split(",") if v]
    if not solvers:
        raise UsageError("--solvers: none given (e.g. --solvers auto)")
    rows = paper_rows(a.runs, a.build_root)
    for r in rows:
        print(r, flush=True)
    for N in sizes:
        rows += large_rows(N, a.horizon, threads, solvers, a.build_root)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "agents.csv", _table(rows))
    print(_table(rows))
    return 0


def _counts(text: str, flag: str) -> list[int]:
    """A comma-separated list of counts >= 1 (``--sizes``, ``--threads``)."""
    try:
        out = [count(v) for v in text.split(",") if v.strip()]
    except argparse.ArgumentTypeError as exc:
        raise UsageError(f"{flag}: {exc}") from None
    if not out:
        raise UsageError(f"{flag}: none given (comma-separated counts, e.g. 1,2)")
    return out


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
