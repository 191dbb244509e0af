"""The search loop: CMA-ES asks for a batch, the batch runs on the Dask cluster, the
results are told; uniform random search runs in the same rounds with its own budget
(docs/search.md, 'Running a search').

Every evaluation is a row of ``out/<name>/results.parquet`` (``arm`` = ``search``,
``baseline`` or ``minimise``, ``eval`` = its index within the arm), committed atomically
after every round. A rerun reads the file and replays it: CMA-ES asks again from the same
seed, and a point whose row is committed (same arm and index, same coordinates) is told
its recorded robustness instead of being run, so the run continues where it stopped.
"""

from __future__ import annotations

import datetime as dt
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.provenance import current_commit, machine
from search.evaluate import evaluate_many
from search.space import dimensions, uniform_points, values_at
from search.spec import SearchFile, load_search
from sweep.run import commit_rows, read_results

RESULTS = "results.parquet"
#: robustness told to CMA-ES for a point that failed or was refused
PENALTY = 1e3
#: points per Dask task
CHUNK = 2

Executor = Callable[[SearchFile, list[dict], str], list[dict]]


def population(search: SearchFile, workers: int) -> int:
    """Each optimiser's points per generation: ``[search] batch``, else 4 per worker (at
    least 6).

    Parameters
    ----------
    search : SearchFile
        The search.
    workers : int
        Worker threads of the cluster.
    """
    return search.settings.batch or max(6, 4 * workers)


def dask_executor(client: Any) -> Executor:
    """Run a batch of points as Dask tasks of :data:`CHUNK` points each.

    Parameters
    ----------
    client : distributed.Client
        From :func:`sweep.run._client` (the study's cluster).
    """

    def run(search: SearchFile, points: list[dict], folder: str) -> list[dict]:
        chunks = [points[k : k + CHUNK] for k in range(0, len(points), CHUNK)]
        futs = client.map(
            evaluate_many, [search] * len(chunks), chunks, [folder] * len(chunks), pure=False
        )
        return [row for rows in client.gather(futs) for row in rows]

    return run


def local_executor(search: SearchFile, points: list[dict], folder: str) -> list[dict]:
    """Run a batch in this process (tests, and ``--workers 0``)."""
    return evaluate_many(search, points, folder)


def run_search(
    path: str | Path,
    out_root: str | Path = "out",
    workers: int | None = None,
    executor: Executor | None = None,
    command: str | None = None,
    progress: bool = True,
) -> Path:
    """Run (or continue) a search and write its report; return ``results.parquet``.

    Parameters
    ----------
    path : str or Path
        The search file.
    out_root : str or Path
        Results go to ``<out_root>/<name>/``.
    workers : int, optional
        Local Dask worker processes (default one per core; ``$DASK_SCHEDULER`` is used
        when set, as for studies).
    executor : callable, optional
        Runs a batch of points (default: the Dask cluster of :func:`sweep.run._client`).
    command : str, optional
        The command recorded with the results.
    progress : bool
        Print a progress line per round on stderr.
    """
    search = load_search(path)
    folder = Path(out_root) / search.name
    folder.mkdir(parents=True, exist_ok=True)
    results = folder / RESULTS
    info = {
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "command": command or " ".join(["python -m search", *sys.argv[1:]]),
        "search": str(path),
        "commit": current_commit(),
        "machine": machine(),
    }
    client = None
    if executor is None:
        from sweep.run import _client

        client = _client(None, workers)
        executor = dask_executor(client)
        threads = sum(client.nthreads().values())
    else:
        threads = workers or 1
    try:
        _loop(search, results, executor, info, population(search, threads), progress)
        from search.minimise import minimise

        minimise(search, results, executor, info)
    finally:
        if client is not None:
            cluster = client.cluster
            client.close()
            if cluster is not None:
                cluster.close()
    from search.report import write_report

    write_report(search, results)
    return results


def _key(row: Any) -> tuple[str, int]:
    return str(row["arm"]), int(row["eval"])


def _loop(
    search: SearchFile,
    results: Path,
    executor: Executor,
    info: dict[str, str],
    popsize: int,
    progress: bool,
) -> None:
    """Rounds of one CMA-ES generation per requirement plus a share of the baseline.

    Each requirement has its own optimiser, told that requirement's robustness: the least
    robustness over requirements is flat wherever another requirement is the smaller one,
    so one optimiser of the minimum follows whichever requirement happens to be least.
    """
    from cmaes import CMA

    s = search.settings
    dims = dimensions(search.study)
    n = len(dims)
    done = read_results(results)
    known = _known(done)
    reqs = search.requirements
    opts = [
        CMA(
            mean=np.full(n, 0.5),
            sigma=s.sigma,
            bounds=np.tile([0.0, 1.0], (n, 1)),
            seed=(s.seed + j) % (2**31),
            population_size=popsize,
        )
        for j in range(len(reqs))
    ]
    rounds = max(1, math.ceil(s.budget / (popsize * len(reqs))))
    per_round = math.ceil(s.baseline / rounds) if s.baseline else 0
    n_search = n_base = 0
    folder = str(results.parent.resolve())
    for r in range(rounds):
        asked = [[cma.ask() for _ in range(popsize)] for cma in opts]
        points = []
        for j, us in enumerate(asked):
            for k, u in enumerate(us):
                p = _point("search", n_search + j * popsize + k, u, dims)
                p["target"] = reqs[j].name
                points.append(p)
        m = max(min(per_round, s.baseline - n_base), 0)
        base_u = uniform_points(s.seed, n_base, m, n)
        points += [_point("baseline", n_base + k, u, dims) for k, u in enumerate(base_u)]
        rows = {_key(p): known[_key(p)] for p in points if _key(p) in known}
        todo = [p for p in points if _key(p) not in rows]
        if todo:
            new = executor(search, todo, folder)
            done = commit_rows(results, done, new, info)
            rows.update({_key(x): x for x in new})
        for j, (cma, us) in enumerate(zip(opts, asked, strict=True)):
            col = f"rob:{reqs[j].name}"
            got = [rows[("search", n_search + j * popsize + k)] for k in range(popsize)]
            cma.tell([(u, _told(row, col)) for u, row in zip(us, got, strict=True)])
        n_search += popsize * len(reqs)
        n_base += m
        if progress:
            _progress(r + 1, rounds, done)


def _known(done: pd.DataFrame) -> dict[tuple[str, int], dict]:
    """Committed rows that are final (not ``failed``), by (arm, eval)."""
    if not len(done) or "arm" not in done.columns:
        return {}
    out = {}
    for row in done.to_dict("records"):
        if not str(row.get("status", "")).startswith("failed"):
            out[_key(row)] = row
    return out


def _point(arm: str, k: int, u: np.ndarray, dims: tuple) -> dict:
    return {"arm": arm, "eval": k, "u": [float(x) for x in u], "values": values_at(dims, u)}


def _told(row: dict, column: str) -> float:
    rob = row.get(column)
    if row.get("status") != "ok" or rob is None or not math.isfinite(float(rob)):
        return PENALTY
    return float(rob)


def _progress(r: int, rounds: int, done: pd.DataFrame) -> None:
    ok = done[done["status"] == "ok"] if len(done) else done
    best = {
        arm: float(ok.loc[ok["arm"] == arm, "robustness"].min())
        for arm in ("search", "baseline")
        if len(ok) and (ok["arm"] == arm).any()
    }
    text = ", ".join(f"{a} min {v:.4g}" for a, v in best.items())
    print(f"search: round {r}/{rounds}, {len(done)} evaluations; {text}", file=sys.stderr)
