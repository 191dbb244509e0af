"""A topology study on one library per follower model (``studies/topologies.toml``).

``python -m sweep.topologies [STUDY]`` draws the study's samples with the study
machinery (:func:`sweep.sampler.samples`: random digraphs with a spanning tree from the
leader, N and link losses as the file says; the loader refuses a sample whose topology
breaks Assumption 1) and integrates each with the per-agent driver
(:mod:`generated.agents`): the kernels are compiled once, for the first sample, and
every later sample — any graph, any N, any switching — runs the same library with its
graph as data.

Gains: the study's gains are those of the base scenario with its settings (the leader's
LMIs, the UIO and λ1, λ2 do not depend on the graph and are what the kernels compile
in); per sample only the graph's own quantities change: H = I (the study's graphs are
cooperative) and L̄ = L + B. The sample's Theorem 1 condition λ1 > λ̄1 / w is evaluated
on every topology with Lemma 3's w for the paper's z = (L̄ᵀ)⁻¹1 (column ``theorem1``;
the synthesis stage may find a larger w with its best diagonal Z, so ``False`` here is
"not shown by the paper's z", not a proof of failure).

Per sample: N, links, whether a topology has a cycle, link losses, w_min, theorem1,
CVODE's status and counters (an incomplete run: the time it reached and CVODE's
message, also listed in the report), where CVODE stood when it returned (``t_stop``)
with the largest state there (``stop_state``, ``stop_abs``) against the largest of the
output rows (``rows_abs``) — a state that ran away, or an integrator stalled on a tame
one — and the last topology switch before it (``switch_before_stop``), the integration time, the library key(s) and whether they were compiled for this
sample, and the observer's tail error max |η_i − η0| over the last quarter of the
horizon. Output: ``out/topologies/results.csv`` and
``report.md`` (counts, timing, the libraries used).
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import time
from pathlib import Path
from typing import Any

import numpy as np

from core.artifacts import atomic_write_text
from core.errors import CliParser, UsageError, run_cli
from core.memo import MEMO
from core.provenance import provenance_line

STUDY = "studies/topologies.toml"
#: the study, its base gains and codegen settings, set once per process (core/memo.py)
_STATE = MEMO.namespace("topologies-state", 3)


def sample_gains(base: Any, sc: Any) -> tuple[Any, float, bool]:
    """The base gains with ``sc``'s graph quantities, its w_min and Theorem 1's verdict.

    Parameters
    ----------
    base : Gains
        Gains of the study's first sample (synthesised).
    sc : Scenario
        A sample on a cooperative graph.

    Returns
    -------
    (Gains, float, bool)
    """
    from core.graph import pinned_laplacian
    from synthesis.lemma3 import lemma3_z, w_of

    L_bar = pinned_laplacian(sc.graph.adjacency, sc.graph.pinning).toarray()
    ws = []
    for top in sc.graph.topologies():
        Lk = pinned_laplacian(top.adjacency, top.pinning)
        ws.append(float(w_of(Lk.toarray(), lemma3_z(Lk))))
    w = min(ws)
    g = dataclasses.replace(base, L_bar=L_bar, H=np.eye(sc.N), w=w)
    return g, w, bool(base.lambda1 > base.lambda_bar1 / w)


def _run_one(sample: Any) -> dict[str, Any]:
    from core.graph import switch_times
    from generated import agents, api

    row: dict[str, Any] = {"sample": sample.id}
    sc = sample.scenario
    if sc is None:
        return {**row, "status": "refused", "reason": sample.reason}
    base, cg = _STATE["gains"], _STATE["codegen"]
    gains, w, thm = sample_gains(base, sc)
    tops = sc.graph.topologies()
    t0 = time.perf_counter()
    libs, model = agents.build_models(sc, gains, cg)
    prob = agents.problem(sc, gains, model)
    x0 = agents.initial_state(sc)
    t1 = time.perf_counter()
    s = api.integrator_settings(sc, "native", cg)
    from generated.schedule import output_grid

    H = sc.integration.horizon
    t_out = output_grid(H, sc.integration.output_step)
    tr = agents.run([lib.path for lib in libs], prob, x0, t_out, s, breakpoints=sc.breakpoints())
    t2 = time.perf_counter()
    lay = agents.make_layout(sc.m, sc.n, sc.N, False)
    tail = tr.t >= 0.75 * H  # the times reached: an incomplete run has fewer rows
    X = tr.x[tail & np.isfinite(tr.x).all(axis=1)]
    eta0 = X[:, : sc.m]
    err = (
        max(np.abs(X[:, lay.slices[("eta", i)]] - eta0).max() for i in range(sc.N))
        if len(X)
        else np.nan
    )
    k_stop = tr.largest_at_stop()
    before = [t for t in switch_times(sc.graph.switches) if t <= tr.t_stop]
    return {
        **row,
        "N": sc.N,
        "links": int((np.asarray(sc.graph.adjacency) != 0).sum()),
        "cyclic": not prob.acyclic,
        "losses": len(tops) - 1,
        "w_min": w,
        "theorem1": thm,
        "status": "complete" if tr.complete else "incomplete",
        "t_reached": float(tr.t_reached),
        "message": "" if tr.complete else tr.message,
        "t_stop": float(tr.t_stop),
        "stop_state": lay.name_of(k_stop),
        "stop_abs": float(abs(tr.x_stop[k_stop])),
        "rows_abs": float(np.nanmax(np.abs(tr.x))),
        "switch_before_stop": before[-1] if before else np.nan,
        "steps": int(tr.stats["steps"]),
        "prepare_s": round(t1 - t0, 4),
        "simulate_s": round(t2 - t1, 4),
        "library": ";".join(lib.key[:12] for lib in libs),
        "compiled": any(not lib.cache_hit for lib in libs),
        "tail_obs_err": float(err),
    }


def _init_worker(study: Any) -> None:
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _STATE["study"] = study


def _run_id(sample_id: int) -> dict[str, Any]:
    from sweep.sampler import make_sample

    return _run_one(make_sample(_STATE["study"], sample_id))


def run_study(path: str, count: int | None, workers: int, build_root: str | None) -> list[dict]:
    """All samples of the study (or the first ``count``); the first one compiles.

    Parameters
    ----------
    path : str
    count : int, optional
    workers : int
        Processes (forked after the first sample: they inherit its libraries). Each
        draws its own samples, one at a time, so a long sample holds up no other.
    build_root : str, optional
    """
    from generated import api
    from generated.values import CodegenSettings
    from sweep.sampler import make_sample
    from sweep.study import load_study

    study = load_study(path)
    n = study.count if count is None else min(count, study.count)
    rows, k = [], 0
    while k < n:  # the first sample the loader accepts compiles the kernels
        first = make_sample(study, k)
        k += 1
        if first.scenario is None:
            rows.append(_run_one(first))
            continue
        _STATE["codegen"] = CodegenSettings(build_root=build_root)
        _STATE["gains"] = api.scenario_gains(first.scenario, f"gains of sample {first.id}")
        rows.append(_run_one(first))
        break
    rest = range(k, n)
    if workers > 1:
        ctx = mp.get_context("fork")
        with ctx.Pool(workers, initializer=_init_worker, initargs=(study,)) as pool:
            rows += pool.imap_unordered(_run_id, rest, chunksize=1)
    else:
        _STATE["study"] = study
        rows += [_run_id(k) for k in rest]
    return sorted(rows, key=lambda r: r["sample"])


def report(rows: list[dict], wall: float, path: str) -> str:
    """The study's summary (Markdown).

    Parameters
    ----------
    rows : list of dict
        One per sample, from :func:`run_study`.
    wall : float
        Wall time of the whole study (s).
    path : str
        The study file, named in the title.
    """
    ran = [r for r in rows if r["status"] != "refused"]
    comp = [r for r in ran if r["status"] == "complete"]
    cyc = [r for r in ran if r["cyclic"]]
    libs = sorted({r["library"] for r in ran})
    compiled = [r["sample"] for r in ran if r["compiled"]]
    sim = np.array([r["simulate_s"] for r in ran]) if ran else np.zeros(1)
    thm = [r for r in ran if r["theorem1"]]
    err = np.array([r["tail_obs_err"] for r in comp])
    tail = f"median {np.median(err):.2e}, max {err.max():.2e}" if comp else "no complete run"
    lines = [
        f"# Topology study ({path})",
        "",
        f"{provenance_line()}; `python -m sweep.topologies {path}`.",
        "",
        f"- samples: {len(rows)}; refused by the loader (Assumption 1 on a topology): "
        f"{len(rows) - len(ran)}; integrated: {len(ran)}, complete: {len(comp)}",
        f"- cyclic: {len(cyc)}, acyclic: {len(ran) - len(cyc)}; with link losses: "
        f"{sum(1 for r in ran if r['losses'] > 0)}",
        f"- N from {min(r['N'] for r in ran)} to {max(r['N'] for r in ran)}",
        f"- wall time: {wall:.1f} s; integration per sample: median {np.median(sim):.2f} s, "
        f"max {sim.max():.2f} s",
        f"- libraries: {len(libs)} ({', '.join(libs)}); compiled for sample(s) "
        f"{compiled or 'none (all from the cache)'}",
        f"- Theorem 1 shown with the paper's z: {len(thm)} of {len(ran)}",
        f"- observer tail error max |η_i − η0| (complete runs): {tail}",
    ]
    lines += [
        f"- incomplete: sample {r['sample']} (N = {r['N']}) stopped at t = "
        f"{r['t_reached']:.4g} s: {r['message']}" + _stop_text(r)
        for r in ran
        if r["status"] != "complete"
    ]
    return "\n".join(lines) + "\n"


def _stop_text(r: dict) -> str:
    """Where CVODE stood when it gave up, against the largest state of the rows before."""
    from generated.values import stop_note

    note = stop_note(r["t_stop"], r["stop_state"], r["stop_abs"])
    switch = r["switch_before_stop"]
    last = (
        "no topology switch before"
        if np.isnan(switch)
        else f"{(r['t_stop'] - switch) * 1e3:.3g} ms after the last topology switch"
    )
    return f"{note} (at most {r['rows_abs']:.3g} in the output rows before; {last})"


def _csv(rows: list[dict]) -> str:
    cols = list(dict.fromkeys(k for r in rows for k in r))
    out = [",".join(cols)]
    for r in rows:
        out.append(",".join(str(r.get(c, "")).replace(",", ";") for c in cols))
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the study, write ``results.csv`` and ``report.md`` under ``--out`` and print the report.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (None: ``sys.argv``).
    """
    ap = CliParser(prog="python -m sweep.topologies", description=__doc__)
    ap.add_argument("study", nargs="?", default=STUDY)
    ap.add_argument("--count", type=int, default=None, help="only the first COUNT samples")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="out/topologies")
    ap.add_argument("--build-root", default=None)
    a = ap.parse_args(argv)
    if a.count is not None and a.count < 1:
        raise UsageError(f"--count: {a.count} samples: give an integer >= 1 (or no --count)")
    if a.workers < 1:
        raise UsageError(f"--workers: {a.workers} processes: give an integer >= 1")
    for flag, value in (("--out", a.out), ("--build-root", a.build_root)):
        if value is not None and not value.strip():
            raise UsageError(f"{flag}: an empty path: give a folder")
    t0 = time.perf_counter()
    rows = run_study(a.study, a.count, a.workers, a.build_root)
    wall = time.perf_counter() - t0
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "results.csv", _csv(rows))
    text = report(rows, wall, a.study)
    atomic_write_text(out / "report.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
