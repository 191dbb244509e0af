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
    (method ``native``): the per-agent engine, one kernel library per follower model,
    the graph as runtime data (:mod:`generated.agents`).
``c-cvodes-direct``, ``c-cvodes-gmres``
    Our generated C + CVODES through CasADi's interface with the two plans of
    :mod:`generated.largescale` (``jacobian="sparse"``: sparse direct Jacobian /
    ``"jvp"``: matrix-free GMRES).

All of ours are built and integrated by the functions of ``make sim``
(:func:`generated.api.build_from_closed_loop`, :func:`generated.api.integrator_settings`,
:func:`generated.api.simulate`). "Ours" — the denominator of the ratio column — is
:func:`benchmarks.catalogue.ours_method`: ``c-cvode-native`` at every N (the shipped scenarios' method).
``c-idas``
    Our generated C (DAE form) + IDAS, same plan as ours, same functions.
``fixed``
    The fixed-step ROS2 method of :mod:`generated.solvers.fixed` with the exact sign
    function (its purpose), step ``integration.fixed_step``.

Compile cache: unless ``--warm-cache``, the cells build into a fresh cache
``<out>/build`` (emptied at the start), so every ``codegen_s``/``compile_s`` is a real
build, never a cache hit from an earlier ``make sim``; cells of one run share it (the
runs of a cell, and methods with the same library, reuse it within the run).

Scenarios: N = 5 is ``scenarios/paper.toml``; larger N are built by
:func:`benchmarks.scenarios.bench_scenario` from it: the paper's follower model and faults (cycled), offsets
on a circle of radius 4, p_i(0) = b_i0 + noise, and a random acyclic sparse graph in
which every follower hears its spanning-tree parent and up to two more earlier
followers (fixed seed), with one follower in a hundred pinned to the leader.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.catalogue import (
    CHEAP_BUILDS,
    METHODS,
    SIZES,
    BenchError,
    ours_method,
)
from benchmarks.tables import (
    finish,
    markdown,
    plot,
    short_number,
    status_short,
    table,
    write_csv,
)
from benchmarks.worker import worker
from core.cli_args import count, positive
from core.errors import CliParser, run_cli
from generated.values import Status


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


def _parser() -> argparse.ArgumentParser:
    """The command line of :func:`main`."""
    ap = CliParser(prog="python -m benchmarks.bench", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="N = 5 only, one run per method")
    ap.add_argument("--sizes", default=None, help="comma-separated N (default 5,50,500,2000)")
    ap.add_argument("--methods", default=None, help=f"comma-separated, from {','.join(METHODS)}")
    ap.add_argument("--runs", type=count, default=None, help="runs per cell (default 5; quick 1)")
    ap.add_argument(
        "--time-limit", type=positive, default=None, help="seconds per cell (default 120; quick 60)"
    )
    ap.add_argument(
        "--ours-time-limit",
        type=positive,
        default=None,
        help="seconds per cell for ours (default 1500, at least 4x --time-limit: "
        "ours completes N = 2,000 in about 700 s here)",
    )
    ap.add_argument("--horizon", type=positive, default=20.0, help="simulated seconds (default 20)")
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
            median = short_number(r.get("int_median_s"))
            print(f"  N={N:<5d} {meth:<16s} {median:>8s} s  {status_short(r)}", flush=True)
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
