"""Run a study's samples on Dask and stream one result row per sample to Parquet.

Each task runs a chunk of samples; for each it draws the sample, simulates it (the steps
of :func:`generated.api.run` in memory, or that function on the written scenario file
with ``--keep-runs``), verifies it (the bound-vs-actual table of
:func:`verify.pipeline.verify_run`, no figures) and returns one flat row. Rows are
committed to ``out/<study>/results.parquet`` in batches by an atomic replace of the
whole table, so an interrupted study resumes with only the missing sample ids.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
import re
import sys
import time
import traceback
import uuid
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.errors import UsageError
from core.provenance import current_commit, machine
from sweep.coverage import coverage_columns
from sweep.sampler import Sample, make_sample, write_scenario
from sweep.study import Study, load_study

RESULTS = "results.parquet"
#: columns every row has, in this order (then ``param:<key>`` and ``t2_entry:<i>``)
BASE_COLUMNS = [
    "id",
    "seed",
    "name",
    "status",
    "steps",
    "wall_s",
    "simulate_s",
    "checks_s",
    "library",
    "tail_max_et",
    "tail_switches",
    "last_switch_t",
    "formation_tail_max",
    "observer_tail_max",
    "t2_entry_source",
    "peak_u_max",
    "peak_u_late",
    "step_recovery_s",
    "step_pairs",
    "step_pairs_late",
    "step_pairs_undefined",
    "step_deviation_max",
    "step_peak_u",
    "guaranteed_held",
    "guaranteed_failed",
    "consistency_held",
    "n_guaranteed",
    "n_consistency",
    "finished_utc",
]


@dataclass(frozen=True)
class StudyPaths:
    """Where a study's outputs go: ``<out_root>/<study name>/``.

    Attributes
    ----------
    folder : Path
        The study's folder.
    """

    folder: Path

    @property
    def samples(self) -> Path:
        """Folder of the written sample scenarios."""
        return self.folder / "samples"

    @property
    def runs(self) -> Path:
        """Output root of the simulations (``runs/<sample name>/``)."""
        return self.folder / "runs"

    @property
    def results(self) -> Path:
        """The results table."""
        return self.folder / RESULTS


# --------------------------------------------------------------------------- one sample
@lru_cache(maxsize=4)
def _study(path: str) -> Study:
    """The study, loaded once per worker process."""
    return load_study(path)


def run_sample(study_path: str, sample_id: int, folder: str, keep: bool = False) -> dict[str, Any]:
    """Draw, simulate and verify one sample; never raises for a sample's own fault.

    Parameters
    ----------
    study_path : str
        The study file.
    sample_id : int
        0-based id.
    folder : str
        The study's output folder (:class:`StudyPaths`).
    keep : bool
        Also write the sample's scenario file (``samples/``) and its run (trajectory.csv,
        meta.json, gains.json under ``runs/``); default: the run stays in memory.

    Returns
    -------
    dict
        One flat row (:data:`BASE_COLUMNS`, ``param:<key>``, ``t2_entry:<i>``); ``status``
        is ``ok``, ``refused: <loader's reason>`` or ``failed: <one-line error>``.
    """
    t0 = time.perf_counter()
    paths = StudyPaths(Path(folder))
    sample = make_sample(_study(study_path), sample_id)
    row: dict[str, Any] = {"id": sample.id, "seed": str(sample.seed), **param_columns(sample)}
    row["name"] = sample.scenario_data.get("name", "")
    if sample.scenario is None:
        row["status"] = f"refused: {sample.reason}"
    else:
        try:
            row.update(_simulate_and_verify(sample, paths, keep))
            row["status"] = "ok"
        except Exception as exc:  # noqa: BLE001 - any failure of one sample is recorded
            row["status"] = f"failed: {one_line(exc)}"
    row["wall_s"] = time.perf_counter() - t0
    row["finished_utc"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    return row


def run_samples(
    study_path: str, sample_ids: list[int], folder: str, keep: bool = False
) -> list[dict[str, Any]]:
    """:func:`run_sample` for each id in turn: one Dask task runs a chunk of samples, so
    the scheduler's per-task cost is paid once per chunk (docs/studies.md, 'Execution').

    Parameters
    ----------
    study_path, folder, keep
        As for :func:`run_sample`.
    sample_ids : list of int
        The chunk's sample ids.

    Returns
    -------
    list of dict
        One row per id, in the order given.
    """
    return [run_sample(study_path, k, folder, keep) for k in sample_ids]


def one_line(exc: BaseException) -> str:
    """An exception as one line: its type and its text with whitespace collapsed, ≤ 500 chars.

    Parameters
    ----------
    exc : BaseException
        The exception of a failed sample.
    """
    text = " ".join(str(exc).split()) or "".join(traceback.format_exception_only(exc)).strip()
    return f"{type(exc).__name__}: {text}"[:500]


def param_columns(sample: Sample) -> dict[str, Any]:
    """The drawn values as ``param:<key>`` columns; a list becomes ``param:<key>[k]`` (1-based).

    Parameters
    ----------
    sample : Sample
        A drawn sample.
    """
    out: dict[str, Any] = {}
    for key, v in sample.params.items():
        if isinstance(v, list):
            out.update({f"param:{key}[{k + 1}]": _scalar(x) for k, x in enumerate(v)})
        else:
            out[f"param:{key}"] = _scalar(v)
    return out


def _scalar(v: Any) -> Any:
    """A Parquet-friendly value: numbers and strings stay, anything else becomes JSON."""
    if isinstance(v, bool | int | float | str):
        return v
    return json.dumps(v)


def _simulate_and_verify(sample: Sample, paths: StudyPaths, keep: bool) -> dict[str, Any]:
    """Run the sample (written to disk or in memory) and summarize its bounds table."""
    from verify import pipeline as P

    t0 = time.perf_counter()
    if keep:
        run = _run_written(sample, paths)
        t1 = time.perf_counter()
        v = P.verify_run(run, out_root=paths.runs)
    else:
        run = run_in_memory(sample, paths)
        t1 = time.perf_counter()
        v = P.verify_run(run)  # with the gains the run used (Run.gains): no file is read
    return {
        "simulate_s": t1 - t0,
        "checks_s": time.perf_counter() - t1,
        "steps": run.meta.get("steps"),
        "library": library_key(run.meta),
        **summarize_table(v.table),
        **coverage_columns(v.table),
        **theorem2_entry(v.table, sample.scenario, run.frame, v.config),
        "tail_max_et": tail_max_et(run.frame, v.config.tail_fraction),
        **topology_in_tail(sample.scenario, run.frame, v.config.tail_fraction),
        **step_recovery(sample.scenario, run),
    }


def step_recovery(sc: Any, run: Any) -> dict[str, Any]:
    """How the pinned followers came back to their slots after each operator step.

    Parameters
    ----------
    sc : Scenario
        The sample's scenario (its u0 gives the step times).
    run : verify.pipeline.Run
        The sample's run (its gains give the gauge).

    Returns
    -------
    dict
        ``step_recovery_s`` (seconds; NaN without operator steps), the counts of
        (step, pinned follower) pairs (:func:`verify.operator_steps.recovery_summary`) and
        ``step_peak_u``, the largest torque within 2 s of a step
        (:func:`verify.operator_steps.step_peak_u`).
    """
    from verify.operator_steps import recoveries, recovery_summary, step_peak_u
    from verify.table import gauge

    items = recoveries(sc, run.frame, gauge(sc, run.gains))
    return {**recovery_summary(items), "step_peak_u": step_peak_u(sc, run.frame)}


def _run_written(sample: Sample, paths: StudyPaths) -> Any:
    """``make sim`` of the written scenario file: samples/<name>.toml, runs/<name>/."""
    from generated import api
    from verify import pipeline as P

    scenario_file = write_scenario(sample, paths.samples)
    res = api.run(scenario_file, out_root=paths.runs, progress=False)
    return P.Run(sample.scenario, res.frame, res.trajectory.x, res.meta, res.csv_path.parent)


def run_in_memory(sample: Sample, paths: StudyPaths) -> Any:
    """The same steps as :func:`generated.api.run` (gains, build, integrate, outputs)
    writing nothing; the run's folder is where ``--keep-runs`` would write it.

    Parameters
    ----------
    sample : Sample
        The drawn sample (its scenario).
    paths : StudyPaths
        The study's folders.
    """
    from generated import api
    from verify import pipeline as P

    sc = sample.scenario
    gains = api.scenario_gains(sc, f"gains of sample {sample.id}")
    codegen = api.resolve_codegen(sc.N)
    built = api.build(sc, gains, sc.integration.method, codegen)
    traj = api.simulate(built, sc, api.integrator_settings(sc, sc.integration.method, codegen))
    traj.raise_if_incomplete()
    frame = api.trajectory_frame(built, sc, traj)
    meta = {"steps": traj.stats.get("steps"), "library": {"key": built.library.key}}
    folder = paths.runs / sc.name
    return P.Run(sc, frame, traj.x, meta, folder, gains=gains, closed_loop=built.closed_loop)


def library_key(meta: dict[str, Any]) -> str:
    """The key of the compiled library the run executed (meta.json ``library``): its
    content key when meta.json gives one, else the SHA-256 of the library file.

    Samples with equal keys ran the same compiled code (docs/studies.md).

    Parameters
    ----------
    meta : dict
        The run's meta.json content.
    """
    lib = meta.get("library")
    if isinstance(lib, str):
        return lib
    if isinstance(lib, dict) and isinstance(lib.get("key"), str):
        return lib["key"]
    libs = meta.get("libraries") or {}
    main = (lib or {}).get("path")
    if main in libs:
        return libs[main]
    return ",".join(sorted(libs.values()))


def tail_max_et(frame: pd.DataFrame, tail_fraction: float) -> float:
    """max_i sup over the tail window of the Euclidean norm |e_ti| (columns ``et<i>_<r>``).

    Parameters
    ----------
    frame : DataFrame
        The trajectory.
    tail_fraction : float
        The asymptotic window: the last fraction of the horizon.
    """
    from verify import signals as S

    frame = S.Columns.of(frame)  # one conversion, then columns by position
    t = S.column(frame, "t")
    tail = S.tail_mask(t, tail_fraction)
    best = -math.inf
    for i in range(1, S.dims(frame).N + 1):
        pattern = re.compile(rf"et{i}_\d+")
        cols = [c for c in frame.names if pattern.fullmatch(c)]
        e = np.linalg.norm(np.asfortranarray(S.take(frame, cols)[tail]), axis=1)
        best = max(best, float(e.max()))
    return best


def topology_in_tail(sc: Any, frame: pd.DataFrame, tail_fraction: float) -> dict[str, Any]:
    """Whether the tail window saw one fixed graph: ``tail_max_et`` is an asymptotic
    error only then; a link lost or recovered in the window puts its transient in it.

    Parameters
    ----------
    sc : Scenario
        Its ``graph.switches`` (link losses and recoveries).
    frame : DataFrame
        The trajectory (column ``t``).
    tail_fraction : float
        The tail window: the last fraction of the horizon (:func:`verify.signals.tail_start`).

    Returns
    -------
    dict
        ``tail_switches``: distinct topology switch times inside the tail window;
        ``last_switch_t``: the last switch time (NaN for a fixed graph).
    """
    from core.graph import switch_times
    from verify.signals import tail_start

    t = frame["t"].to_numpy(float)
    start, end = tail_start(t, tail_fraction), float(t[-1])
    times = switch_times(sc.graph.switches)
    return {
        "tail_switches": sum(1 for s in times if start <= s <= end),
        "last_switch_t": float(times[-1]) if times else math.nan,
    }


def summarize_table(table: pd.DataFrame) -> dict[str, Any]:
    """The row's numbers from a bounds table (:func:`verify.table.bounds_table`).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.

    Returns
    -------
    dict
        Formation and observer tails, peak |u_i|, Theorem 2 entry times and the verdicts.
    """
    from types import SimpleNamespace

    from verify import claims as CL

    # plain lists: a few comparisons per row cost less than pandas' methods
    claims, kinds = table["claim"].tolist(), table["kind"].tolist()
    ids = table["claim_id"].tolist()
    # an empty holds (a row that cannot be evaluated) is neither held nor failed
    holds = [h is True or h == True for h in table["holds"].fillna(False).tolist()]  # noqa: E712
    agents = table["agent"].tolist()
    observed = table["observed"].to_numpy(float)

    def max_observed(cid: str) -> float:
        hit = [c == cid for c in ids]
        vals = observed[np.asarray(hit, dtype=bool)]
        vals = vals[~np.isnan(vals)]  # NaN skipped, as pandas' max does
        return float(vals.max()) if vals.size else math.nan

    g = [k for k, kind in enumerate(kinds) if kind == "guaranteed"]
    c = [k for k, kind in enumerate(kinds) if kind == "consistency"]
    failed = [k for k in g if not bool(holds[k])]
    out: dict[str, Any] = {
        "formation_tail_max": max_observed(CL.FORMATION.id),
        "observer_tail_max": max_observed(CL.T1_TAIL.id),
        "peak_u_max": max_observed(CL.PEAK_U.id),
        "peak_u_late": max_observed(CL.PEAK_U_LATE.id),
        "guaranteed_held": all(holds[k] for k in g),
        "guaranteed_failed": "; ".join(
            _label(SimpleNamespace(claim=claims[k], agent=agents[k])) for k in failed
        ),
        "consistency_held": all(holds[k] for k in c),
        "n_guaranteed": len(g),
        "n_consistency": len(c),
    }
    return out


def _label(row: Any) -> str:
    """A table row's claim, with its follower when it has one."""
    agent = getattr(row, "agent", None)
    try:
        return f"{row.claim} (follower {int(agent)})"
    except (TypeError, ValueError):
        return str(row.claim)


def theorem2_entry(
    table: pd.DataFrame, scenario: Any, frame: pd.DataFrame, config: Any
) -> dict[str, Any]:
    """Each follower's Theorem 2 entry time: the comparison-lemma time t_c after which the
    provable variant's bound holds (:func:`verify.bounds.provable_entry_time`, the time
    the report's provable rows start from), else Lemma 1's observed reaching time.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table (for Lemma 1's observed reaching time).
    scenario : Scenario
    frame : DataFrame
        The trajectory.
    config : VerifyConfig
        The verification's settings.

    Returns
    -------
    dict
        ``t2_entry:<i>`` per follower (1-based) and ``t2_entry_source`` (``comparison lemma``,
        ``Lemma 1 observed`` or both, comma-separated).
    """
    from verify.bounds import provable_entry_time, theorem2_constants

    out: dict[str, Any] = {}
    sources: set[str] = set()
    lem = None
    for i in range(scenario.N):
        c = theorem2_constants(scenario, i, config)
        if c.provable:
            out[f"t2_entry:{i + 1}"] = provable_entry_time(c, frame, i, config.lemma1_delta)
            sources.add("comparison lemma")
        else:
            if lem is None:  # the table is searched only when some follower needs it
                from verify import claims as CL

                lem = table[table["claim_id"] == CL.LEMMA1_PAPER.id]
            obs = lem.loc[lem["agent"].astype(str) == str(i + 1), "observed"].astype(float)
            out[f"t2_entry:{i + 1}"] = float(obs.iloc[0]) if len(obs) else math.nan
            sources.add("Lemma 1 observed")
    out["t2_entry_source"] = ",".join(sorted(sources))
    return out


# --------------------------------------------------------------------------- results table
def read_results(path: Path) -> pd.DataFrame:
    """The committed rows (an empty table when the file does not exist).

    Parameters
    ----------
    path : Path
        ``results.parquet``.
    """
    if not path.is_file():
        return pd.DataFrame(columns=BASE_COLUMNS)
    return pd.read_parquet(path)


def commit_rows(
    path: Path, old: pd.DataFrame, rows: list[dict], info: dict[str, str]
) -> pd.DataFrame:
    """Write ``old`` plus ``rows`` as the whole table: a temporary file, then ``os.replace``.

    Parameters
    ----------
    path : Path
        ``results.parquet``.
    old : DataFrame
        The rows already committed.
    rows : list of dict
        New rows.
    info : dict
        Key-value metadata stored in the Parquet schema (date, command).

    Returns
    -------
    DataFrame
        The table written, sorted by id, one row per id (a new row replaces an old one
        of the same id: a retried sample).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    new = pd.DataFrame(rows)
    frames = [f for f in (old, new) if len(f)]
    table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=BASE_COLUMNS)
    table = table.drop_duplicates("id", keep="last").sort_values("id", ignore_index=True)
    table = _column_order(_uniform_types(table))
    arrow = pa.Table.from_pandas(table, preserve_index=False)
    meta = {**(arrow.schema.metadata or {}), **{k.encode(): v.encode() for k, v in info.items()}}
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(arrow.replace_schema_metadata(meta), tmp)
    os.replace(tmp, path)
    return table


def _uniform_types(table: pd.DataFrame) -> pd.DataFrame:
    """Object columns mixing types (e.g. a ``choice`` of numbers and strings) become text."""
    for c in table.columns:
        if table[c].dtype == object:
            kinds = {type(x) for x in table[c] if x is not None and x == x}
            if len(kinds) > 1:
                table[c] = [None if x is None or x != x else str(x) for x in table[c]]
    return table


def _column_order(table: pd.DataFrame) -> pd.DataFrame:
    for c in BASE_COLUMNS:
        if c not in table.columns:
            table[c] = None
    rest = sorted(c for c in table.columns if c not in BASE_COLUMNS)
    return table[BASE_COLUMNS + rest]


# --------------------------------------------------------------------------- the study
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
        Write each sample's scenario file and run (:func:`run_sample`).
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


#: Dask settings of the local cluster. Each process's event loop wakes up for these
#: timers, and on two cores a wake-up takes the core from a sample: no statistical
#: profiler sampling each task's stack every 10 ms, memory polled every second, the
#: loop's responsiveness tick every second (default 20 ms), the system monitor (CPU and
#: network counters for the dashboard, which a study does not start) every 5 s. The
#: workers' environment keeps Dask's one-thread caps but not its MALLOC_TRIM_THRESHOLD_:
#: with it glibc maps and unmaps every array above 128 KiB, about 5,000 page faults and
#: 11 ms of kernel time per sample of studies/faults.toml against 10 faults without
#: (docs/studies.md, 'Cost of a sample')
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.nanny.pre-spawn-environ": {
        "OMP_NUM_THREADS": 1,
        "MKL_NUM_THREADS": 1,
        "OPENBLAS_NUM_THREADS": 1,
    },
    # no HTTP pages: every Dask node opens an HTTP server; with no routes it serves none
    "distributed.scheduler.http.routes": [],
    "distributed.worker.http.routes": [],
}


def _client(scheduler: str | None, workers: int | None = None) -> Any:
    """A client of ``scheduler`` (or ``$DASK_SCHEDULER``), else of a new local cluster
    with ``workers`` single-threaded worker processes (default one per core)."""
    from distributed import Client

    address = scheduler or os.environ.get("DASK_SCHEDULER")
    if address:
        try:
            return Client(address)
        except OSError as exc:  # refused or timed out: name the address and the fix
            raise UsageError(
                f"Dask scheduler {address}: cannot connect ({' '.join(str(exc).split())[:200]}); "
                "start `dask scheduler` and `dask worker` there, or unset DASK_SCHEDULER"
            ) from exc
    return _local_client(workers)


def _local_client(workers: int | None) -> Any:
    """A client of a new local cluster on 127.0.0.1 that serves no HTTP.

    Dask's scheduler and workers each start an HTTP server whatever the dashboard
    settings (the scheduler on port 8787 when ``dashboard_address`` is None): here the
    scheduler's binds a free port of 127.0.0.1 instead, the servers have no routes
    (:data:`LOCAL_CLUSTER_CONFIG`), and both stop listening before the first task.

    Parameters
    ----------
    workers : int or None
        Single-threaded worker processes (default one per core).
    """
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set(LOCAL_CLUSTER_CONFIG):  # the nannies hand it to their workers
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            worker_dashboard_address=None,
            scheduler_kwargs={"dashboard": False},
        )
    from sweep.nohttp import NoHttp, stop_scheduler_http

    client = Client(cluster)
    client.run_on_scheduler(stop_scheduler_http)
    client.register_plugin(NoHttp())
    return client


def _close(client: Any, own_cluster: bool) -> None:
    cluster = client.cluster if own_cluster else None
    client.close()
    if cluster is not None:
        cluster.close()


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
) -> Path:
    """Run the study's samples not yet in ``results.parquet``, and again those recorded as
    ``failed`` (``refused`` is final); return the results path.

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

    Returns
    -------
    Path
        ``results.parquet``.
    """
    study = load_study(study_path)
    paths = StudyPaths(Path(out_root) / study.name)
    wanted = list(range(study.count)) if ids is None else sorted(set(ids))
    for k in wanted:
        if not 0 <= k < study.count:
            raise UsageError(
                f"--ids: sample id {k} outside 0..{study.count - 1}: give ids of the study"
            )
    paths.folder.mkdir(parents=True, exist_ok=True)
    done = read_results(paths.results)
    final = final_ids(done)
    todo = [k for k in wanted if k not in final]
    retried = len(set(todo) & set(int(x) for x in done["id"]))
    info = {
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "command": command or " ".join(["python -m sweep", *sys.argv[1:]]),
        "study": str(Path(study_path)),
        "retried": str(retried),
        "commit": current_commit(),
        "machine": machine(),
    }
    if todo or not paths.results.is_file():
        opts = RunOptions(scheduler, workers, batch, keep, chunk)
        _execute(str(Path(study_path).resolve()), todo, paths, done, info, opts)
    from sweep.report import write_report

    write_report(paths.results, retried=retried)
    return paths.results


def is_failed(status: Any) -> bool:
    """Whether a row's ``status`` is ``failed: ...`` (a fault of the run, retried by a rerun).

    Parameters
    ----------
    status : Any
        The row's ``status`` (``ok``, ``refused: ...``, ``failed: ...``).
    """
    return str(status).startswith("failed")


def final_ids(table: pd.DataFrame) -> set[int]:
    """Ids whose row is final: ``ok`` or ``refused`` (a rerun retries the ``failed`` ones).

    Parameters
    ----------
    table : DataFrame
        The committed results.
    """
    return {int(k) for k, s in zip(table["id"], table["status"], strict=True) if not is_failed(s)}


def faults_line(table: pd.DataFrame, study: str) -> str | None:
    """One line naming how many samples failed and the first reason; None when none did.

    Parameters
    ----------
    table : DataFrame
        The results.
    study : str
        The study file, for the rerun command.
    """
    failed = table[[is_failed(s) for s in table["status"]]].sort_values("id")
    if not len(failed):
        return None
    first = str(failed["status"].iloc[0]).removeprefix("failed").lstrip(": ")
    return (
        f"study faults: {len(failed)} of {len(table)} samples failed; first (id "
        f"{int(failed['id'].iloc[0])}): {first}; rerun `make sweep SWEEP={study}` retries them"
    )


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

    client = _client(opts.scheduler, opts.workers) if todo else None
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
            _close(client, opts.own_cluster)


def _results(
    client: Any,
    as_completed: Any,
    study_path: str,
    todo: list[int],
    paths: StudyPaths,
    opts: RunOptions,
):
    """Yield rows as tasks finish, keeping about two tasks per worker thread in flight.

    Each task runs a chunk of samples (:func:`run_samples`, :func:`chunk_size`). A task
    that dies with its worker (e.g. a crash inside the compiled library) is run again one
    sample per task, so only the sample that crashes gets a ``failed`` row; the study goes on.
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
