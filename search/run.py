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
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.provenance import current_commit, machine
from search.evaluate import evaluate_many
from search.space import dimensions, sobol_points, uniform_points, values_at
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
        From :func:`sweep.cluster.dask_client` (the study's cluster).
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
    overrides: dict[str, int] | None = None,
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
        Runs a batch of points (default: the Dask cluster of
        :func:`sweep.cluster.dask_client`).
    command : str, optional
        The command recorded with the results.
    progress : bool
        Show a progress bar over the evaluations on stderr (each arm's least robustness).
    overrides : dict, optional
        ``[search]`` values replacing the file's (``seed``, ``budget``, ``baseline``),
        checked as the file's are.
    """
    search = load_search(path, overrides)
    folder = Path(out_root) / search.name
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
        from sweep.cluster import dask_client

        client = dask_client(None, workers)
        executor = dask_executor(client)
        threads = sum(client.nthreads().values())
    else:
        threads = workers or 1
    try:
        folder.mkdir(parents=True, exist_ok=True)  # once the cluster is there: no empty folder
        _loop(search, results, executor, info, population(search, threads), progress)
        from search.minimise import minimise

        minimise(search, results, executor, info)
    finally:
        if client is not None:
            from sweep.cluster import close_client

            close_client(client, own_cluster=True)
    from search.report import write_report

    write_report(search, results)
    return results


def _key(row: Any) -> tuple[str, int]:
    return str(row["arm"]), int(row["eval"])


@dataclass
class _Rounds:
    """One search's rounds: what is committed, what runs, and the baseline's pace."""

    search: SearchFile
    results: Path
    executor: Executor
    info: dict[str, str]
    dims: tuple
    done: pd.DataFrame = field(default_factory=pd.DataFrame)
    known: dict[tuple[str, int], dict] = field(default_factory=dict)
    n_search: int = 0
    n_base: int = 0
    bar: Any = None  # a tqdm bar over the evaluations, when progress is shown

    def run(self, points: list[dict], last: bool = False) -> dict[tuple[str, int], dict]:
        """Run ``points`` (search arm) with the baseline's share; the rows by (arm, eval).

        The baseline keeps pace with the search (``baseline / budget`` points per search
        point); the last round adds whatever of it is left.
        """
        s = self.search.settings
        self.n_search += len(points)
        due = s.baseline if last else math.ceil(self.n_search * s.baseline / s.budget)
        m = max(min(due, s.baseline) - self.n_base, 0)
        base_u = uniform_points(s.seed, self.n_base, m, len(self.dims))
        points = points + [
            _point("baseline", self.n_base + k, u, self.dims) for k, u in enumerate(base_u)
        ]
        self.n_base += m
        rows = {_key(p): self.known[_key(p)] for p in points if _recorded(self.known, p)}
        todo = [p for p in points if _key(p) not in rows]
        if todo:
            new = self.executor(self.search, todo, str(self.results.parent.resolve()))
            self.done = commit_rows(self.results, self.done, new, self.info)
            rows.update({_key(x): x for x in new})
        if self.bar is not None:
            self.bar.update(len(points))
            self.bar.set_postfix_str(_least_text(self.done), refresh=False)
        return rows


def _loop(
    search: SearchFile,
    results: Path,
    executor: Executor,
    info: dict[str, str],
    popsize: int,
    progress: bool,
) -> None:
    """Exploration, then one local CMA-ES per requirement, with the baseline alongside.

    The first ``explore`` share of the budget is a scrambled Sobol' sequence, shared by all
    requirements (every run scores every requirement). Each requirement then has its own
    CMA-ES, started at its least robust explored point and told that requirement's
    robustness: the least robustness over requirements is flat wherever another
    requirement is the smaller one, so one optimiser of the minimum would follow whichever
    requirement happens to be least. An optimiser that stops is restarted at the least
    robust point found for its requirement.
    """
    s = search.settings
    dims = dimensions(search.study)
    done = read_results(results)
    r = _Rounds(search, results, executor, info, dims, done, _known(done))
    if progress:
        from tqdm import tqdm

        r.bar = tqdm(total=s.budget + s.baseline, desc="search", unit="eval", file=sys.stderr)
    n_explore = min(int(round(s.explore * s.budget)), s.budget)
    explored: dict[tuple[str, int], dict] = {}
    try:
        for k0 in range(0, n_explore, popsize * len(search.requirements)):
            k1 = min(k0 + popsize * len(search.requirements), n_explore)
            us = sobol_points(s.seed, k0, k1 - k0, len(dims))
            pts = [
                _point("search", k0 + k, u, dims) | {"target": "explore"} for k, u in enumerate(us)
            ]
            explored.update(r.run(pts, last=k1 == s.budget))
        _local(r, popsize, n_explore, explored)
    finally:
        if r.bar is not None:
            r.bar.close()


def _local(r: _Rounds, popsize: int, start: int, explored: dict) -> None:
    """Generations of one CMA-ES per requirement until the budget is spent."""
    s, reqs, n = r.search.settings, r.search.requirements, len(r.dims)
    cols = [f"rob:{q.name}" for q in reqs]
    best = [_least(explored.values(), c) for c in cols]
    opts = [_cma(b, n, s.sigma, s.seed + j, popsize) for j, b in enumerate(best)]
    k = start
    while k < s.budget:
        # the budget's last generation may be partial (at least 2 points per optimiser)
        per = max(min(popsize, math.ceil((s.budget - k) / len(reqs))), 2)
        asked = [[cma.ask() for _ in range(per)] for cma in opts]
        pts = [
            _point("search", k + j * per + i, u, r.dims) | {"target": reqs[j].name}
            for j, us in enumerate(asked)
            for i, u in enumerate(us)
        ]
        rows = r.run(pts, last=k + len(pts) >= s.budget)
        for j, us in enumerate(asked):
            got = [rows[("search", k + j * per + i)] for i in range(per)]
            best[j] = _least([*got, *([best[j]] if best[j] else [])], cols[j])
            if per == popsize:  # a partial generation is not told: nothing follows it
                opts[j].tell([(u, _told(row, cols[j])) for u, row in zip(us, got, strict=True)])
            if opts[j].should_stop():  # restart at the least robust point so far
                opts[j] = _cma(best[j], n, s.sigma, s.seed + j + 7919 * (k + 1), popsize)
        k += len(pts)


def _cma(best: dict | None, n: int, sigma: float, seed: int, popsize: int) -> Any:
    """A CMA-ES in the unit box, centred on ``best``'s coordinates (else the centre)."""
    from cmaes import CMA

    mean = np.clip(_coords(best), 1e-9, 1 - 1e-9) if best else np.full(n, 0.5)
    return CMA(
        mean=mean,
        sigma=sigma,
        bounds=np.tile([0.0, 1.0], (n, 1)),
        seed=seed % (2**31),
        population_size=popsize,
    )


def _coords(row: dict) -> np.ndarray:
    keys = sorted((c for c in row if c.startswith("u:")), key=lambda c: int(c[2:]))
    return np.array([float(row[c]) for c in keys])


def _least(rows: Iterable[dict], column: str) -> dict | None:
    """The ``ok`` row with the least ``column`` (ties: the first), or None."""
    best = None
    for row in rows:
        if _told(row, column) < PENALTY and (
            best is None or _told(row, column) < _told(best, column)
        ):
            best = row
    return best


def _known(done: pd.DataFrame) -> dict[tuple[str, int], dict]:
    """Committed rows that are final (not ``failed``), by (arm, eval)."""
    if not len(done) or "arm" not in done.columns:
        return {}
    out = {}
    for row in done.to_dict("records"):
        if not str(row.get("status", "")).startswith("failed"):
            out[_key(row)] = row
    return out


def _recorded(known: dict[tuple[str, int], dict], p: dict) -> bool:
    """Whether ``p`` has a committed row of the same arm, index and coordinates (a row of
    another seed or space, under the same name, is run again and replaced)."""
    row = known.get(_key(p))
    return row is not None and np.array_equal(_coords(row), np.asarray(p["u"], dtype=float))


def _point(arm: str, k: int, u: np.ndarray, dims: tuple) -> dict:
    return {"arm": arm, "eval": k, "u": [float(x) for x in u], "values": values_at(dims, u)}


def _told(row: dict, column: str) -> float:
    rob = row.get(column)
    if row.get("status") != "ok" or rob is None or not math.isfinite(float(rob)):
        return PENALTY
    return float(rob)


def _least_text(done: pd.DataFrame) -> str:
    """Each arm's least robustness so far, for the progress bar."""
    ok = done[done["status"] == "ok"] if len(done) else done
    best = {
        arm: float(ok.loc[ok["arm"] == arm, "robustness"].min())
        for arm in ("search", "baseline")
        if len(ok) and (ok["arm"] == arm).any()
    }
    return ", ".join(f"{a} min {v:.4g}" for a, v in best.items())
