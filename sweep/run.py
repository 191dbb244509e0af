"""Run a study's samples on Dask and stream one result row per sample to Parquet.

Each task runs a chunk of samples (:func:`sweep.worker.run_samples`: draw, simulate and
verify each, one flat row per sample) on the client of :func:`sweep.cluster.dask_client`,
with a bounded window of tasks in flight. Rows are committed to
``out/<study>/results.parquet`` in batches by an atomic replace of the whole table
(:mod:`sweep.results`), so an interrupted study resumes with only the missing sample ids
(:mod:`sweep.resume`).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import shutil
import sys
import uuid
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from core.errors import UsageError
from core.provenance import current_commit, machine
from sweep.cluster import (  # noqa: F401
    LOCAL_CLUSTER_CONFIG,
    close_client,
    dask_client,
    scheduler_address,
)
from sweep.identity import IDENTITY, check_identity
from sweep.lock import LOCK, study_lock
from sweep.measures import summarize_table, tail_max_et, theorem2_entry  # noqa: F401
from sweep.results import RESULTS, StudyPaths, commit_rows, read_results
from sweep.resume import pending_ids
from sweep.study import Study, load_study
from sweep.worker import one_line, param_columns, run_in_memory, run_samples  # noqa: F401

# The names above marked F401 are re-exported: search/ and docs/studies.md,
# docs/verification.md, docs/search.md reach them as sweep.run.<name>.


@dataclass(frozen=True)
class RunOptions:
    """How a study runs.

    Attributes
    ----------
    scheduler : str or None
        A Dask scheduler address; None: ``$DASK_SCHEDULER``, else a local cluster.
    workers : int or None
        Worker processes of the local cluster (default: one per core).
    batch : int
        Rows per atomic commit.
    keep : bool
        Write each sample's scenario file and run (:func:`sweep.worker.run_sample`).
    chunk : int or None
        Samples per Dask task; None: :func:`chunk_size`.
    """

    scheduler: str | None = None
    workers: int | None = None
    batch: int = 10
    keep: bool = False
    chunk: int | None = None

    @property
    def own_cluster(self) -> bool:
        """Whether the run starts (and closes) its own local cluster."""
        return not (self.scheduler or os.environ.get("DASK_SCHEDULER"))


#: the most samples one task runs: a chunk costs about this many sample times at the end
#: of a study, when the other workers may already be idle
MAX_CHUNK = 8


def chunk_size(n_samples: int, n_threads: int) -> int:
    """Samples per task: at least four tasks per worker thread, at most :data:`MAX_CHUNK`.

    A task costs the scheduler a round trip (a few milliseconds, and the client's
    process shares the machine's cores with the workers); chunks pay it once for
    several samples while keeping enough tasks to balance the workers.

    Parameters
    ----------
    n_samples : int
        Samples to run.
    n_threads : int
        Worker threads of the cluster.
    """
    return max(1, min(MAX_CHUNK, n_samples // max(1, 4 * n_threads)))


def run_study(
    study_path: str | Path,
    out_root: str | Path = "out",
    scheduler: str | None = None,
    batch: int = 10,
    ids: Iterable[int] | None = None,
    command: str | None = None,
    workers: int | None = None,
    keep: bool = False,
    chunk: int | None = None,
    restart: bool = False,
) -> Path:
    """Run the study's samples not yet in ``results.parquet``, and again those recorded as
    ``failed`` (``refused`` is final); return the results path.

    The study's folder is locked while it runs (:func:`sweep.lock.study_lock`: a second
    run is refused), and its results are added to only when the folder's recorded
    identity is this study's (:func:`sweep.identity.check_identity`).

    Parameters
    ----------
    study_path : str or Path
        The study file.
    out_root : str or Path
        Results go to ``<out_root>/<study name>/``.
    scheduler : str, optional
        A Dask scheduler address (``tcp://host:port``); default ``$DASK_SCHEDULER``, else a
        local cluster of one single-threaded worker process per core.
    batch : int
        Rows are committed (atomically) every ``batch`` finished samples, and at the end.
    ids : iterable of int, optional
        Which samples (default all); those already ``ok`` or ``refused`` in the results
        are skipped.
    command : str, optional
        The command recorded with the results (default ``sys.argv``).
    workers : int, optional
        Worker processes of the local cluster (default one per core; not used with a
        scheduler).
    keep : bool
        Write each sample's scenario file and run files (default: in memory, only the
        results and the report are written).
    chunk : int, optional
        Samples per Dask task (default :func:`chunk_size`).
    restart : bool
        Discard the folder's results (and its report, runs and sample files) first.

    Returns
    -------
    Path
        ``results.parquet``.
    """
    study = load_study(study_path)
    paths = StudyPaths(Path(out_root) / study.name)
    wanted = list(range(study.count)) if ids is None else sorted(set(ids))
    _check_options(study, wanted, batch, workers, chunk, keep)
    scheduler = scheduler_address(scheduler)
    created = [d for d in (paths.folder, *paths.folder.parents) if not d.exists()]
    paths.folder.mkdir(parents=True, exist_ok=True)
    with study_lock(paths.folder):
        try:
            return _run_locked(
                study,
                study_path,
                paths,
                wanted,
                command,
                restart,
                RunOptions(scheduler, workers, batch, keep, chunk),
            )
        except BaseException:
            if created and not paths.results.exists():
                _remove_new_folders(paths, created)
            raise


def _check_options(
    study: Study, wanted: list[int], batch: int, workers: int | None, chunk: int | None, keep: bool
) -> None:
    """Refuse, in one line before any folder, options :func:`run_study` cannot honour."""
    for k in wanted:
        if not 0 <= k < study.count:
            raise UsageError(
                f"--ids: sample id {k} outside 0..{study.count - 1}: give ids of the study"
            )
    for flag, value in (("--batch", batch), ("--workers", workers), ("--chunk", chunk)):
        if value is not None and value < 1:
            raise UsageError(f"{flag}: {value}: give an integer >= 1")
    losses = study.graph.losses if study.graph is not None else None
    if keep and losses is not None and losses.theorem1 == "measured":
        raise UsageError(
            f"--keep-runs: study {study.name} certifies its samples' gains on their base "
            'graphs ([graph.losses] theorem1 = "measured"), which make sim does not: run '
            "it without --keep-runs"
        )


def _remove_new_folders(paths: StudyPaths, created: list[Path]) -> None:
    """Remove the folders this run created, with its identity and lock file (the lock
    still held: :func:`sweep.lock.study_lock` retries on an unlinked lock file)."""
    for name in (IDENTITY, LOCK):
        (paths.folder / name).unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        for d in created:  # the deepest first; stops at one that is not empty
            d.rmdir()


def discard(paths: StudyPaths) -> None:
    """Remove a study folder's results, identity, report, figures, runs and samples
    (``--restart``); the folder and its lock stay.

    Parameters
    ----------
    paths : StudyPaths
        The study's folder.
    """
    for name in (RESULTS, IDENTITY, "report.md"):
        (paths.folder / name).unlink(missing_ok=True)
    for sub in (paths.folder / "figures", paths.runs, paths.samples):
        if sub.is_dir() and not sub.is_symlink():
            shutil.rmtree(sub)


def _run_locked(
    study: Any,
    study_path: str | Path,
    paths: StudyPaths,
    wanted: list[int],
    command: str | None,
    restart: bool,
    opts: RunOptions,
) -> Path:
    """:func:`run_study` with the folder's lock held."""
    if restart:
        discard(paths)
    done = read_results(paths.results)
    check_identity(paths.folder, study, paths.results.exists())
    todo, retried = pending_ids(wanted, done)
    info = {
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "command": command or " ".join(["python -m sweep", *sys.argv[1:]]),
        "study": str(Path(study_path)),
        "retried": str(retried),
        "commit": current_commit(),
        "machine": machine(),
    }
    if todo or not paths.results.is_file():
        _execute(str(Path(study_path).resolve()), todo, paths, done, info, opts)
    from sweep.report import write_report

    write_report(paths.results, retried=retried)
    return paths.results


def _execute(
    study_path: str,
    todo: list[int],
    paths: StudyPaths,
    done: pd.DataFrame,
    info: dict[str, str],
    opts: RunOptions,
) -> None:
    """Submit ``todo`` (a bounded window in flight) and commit rows as they finish."""
    from distributed import as_completed
    from tqdm import tqdm

    client = dask_client(opts.scheduler, opts.workers) if todo else None
    pending: list[dict] = []
    failures = 0
    try:
        with tqdm(total=len(todo), desc="samples", unit="sample", file=sys.stderr) as bar:
            for row in _results(client, as_completed, study_path, todo, paths, opts):
                pending.append(row)
                failures += row["status"] != "ok"
                bar.update(1)
                bar.set_postfix(not_ok=failures)
                if len(pending) >= max(1, opts.batch):
                    done = commit_rows(paths.results, done, pending, info)
                    pending = []
    finally:
        commit_rows(paths.results, done, pending, info)
        if client is not None:
            close_client(client, opts.own_cluster)


def _results(
    client: Any,
    as_completed: Any,
    study_path: str,
    todo: list[int],
    paths: StudyPaths,
    opts: RunOptions,
):
    """Yield rows as tasks finish, keeping about two tasks per worker thread in flight.

    Each task runs a chunk of samples (:func:`sweep.worker.run_samples`,
    :func:`chunk_size`). A task that dies with its worker (e.g. a crash inside the compiled
    library) is run again one sample per task, so only the sample that crashes gets a
    ``failed`` row; the study goes on.
    """
    if not todo:
        return
    threads = sum(client.nthreads().values())
    size = opts.chunk or chunk_size(len(todo), threads)
    chunks = deque(todo[k : k + size] for k in range(0, len(todo), size))
    window = max(2, 2 * threads)
    folder = str(paths.folder.resolve())
    tag = uuid.uuid4().hex[:8]
    ids: dict[str, list[int]] = {}

    def submit(chunk: list[int]) -> Any:
        key = f"samples-{chunk[0]}x{len(chunk)}-{tag}"
        fut = client.submit(run_samples, study_path, chunk, folder, opts.keep, key=key, pure=False)
        ids[fut.key] = chunk
        return fut

    stream = as_completed([submit(chunks.popleft()) for _ in range(min(window, len(chunks)))])
    for fut in stream:
        chunk = ids.pop(fut.key)
        try:
            rows = fut.result()
        except Exception as exc:  # noqa: BLE001 - the worker died or the task was lost
            if len(chunk) > 1:  # find the sample that fails: each on its own
                chunks.extendleft([k] for k in reversed(chunk))
                rows = []
            else:
                rows = [_failed_row(chunk[0], exc)]
        yield from rows
        while chunks and stream.count() < window:
            stream.add(submit(chunks.popleft()))


def _failed_row(sample_id: int, exc: BaseException) -> dict[str, Any]:
    """The row of a sample whose task raised (its worker died, or the task was lost)."""
    return {
        "id": sample_id,
        "status": f"failed: {one_line(exc)}",
        "finished_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }
