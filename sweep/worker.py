"""One sample on a Dask worker: draw it, simulate it, verify it, return its result row.

The run stays in memory (the steps of :func:`generated.api.run`, writing nothing) or, with
``--keep-runs``, is that function on the written scenario file; the checks are the
bound-vs-actual table of :func:`verify.pipeline.verify_run` (no figures). A sample's own
fault (a refused draw, an exception) is its row's ``status``, never an error of the task.
"""

from __future__ import annotations

import datetime as dt
import json
import time
import traceback
from pathlib import Path
from typing import Any

from core.memo import MEMO
from sweep.coverage import GIVEN, coverage_columns
from sweep.measures import (
    library_key,
    link_recovery,
    step_recovery,
    stop_columns,
    summarize_table,
    tail_max_et,
    theorem2_entry,
    topology_in_tail,
)
from sweep.results import StudyPaths
from sweep.sampler import Sample, make_sample, write_scenario
from sweep.study import Study, load_study
from sweep.switched_gains import topology_columns


class TwinFailed(Exception):
    """The no-loss twin of a sample whose own run completed failed (the row says so)."""


@MEMO.memoize("worker-studies", 4)
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
        One flat row (:data:`sweep.results.BASE_COLUMNS`, ``param:<key>``,
        ``t2_entry:<i>``); ``status`` is ``ok``, ``refused: <loader's reason>`` or
        ``failed: <one-line error>``. A run that stopped early (``failed:
        IntegrationError: ...``) has where it stopped (:func:`sweep.measures.stop_columns`).
    """
    t0 = time.perf_counter()
    paths = StudyPaths(Path(folder))
    sample = make_sample(_study(study_path), sample_id)
    row: dict[str, Any] = {"id": sample.id, "seed": str(sample.seed), **param_columns(sample)}
    row["name"] = sample.scenario_data.get("name", "")
    if sample.scenario is None:
        row["status"] = f"refused: {sample.reason}"
    else:
        study = _study(study_path)
        try:
            row.update(_simulate_and_verify(sample, paths, keep, study, row))
            if _baseline(study):
                try:
                    row.update(link_baseline(sample, paths, **engine(study)))
                except Exception as exc:  # noqa: BLE001 - named: the sample's own run completed
                    raise TwinFailed(f"no-loss twin: {one_line(exc)}") from exc
            row["status"] = "ok"
        except TwinFailed as exc:
            row["status"] = f"failed: {exc}"
        except Exception as exc:  # noqa: BLE001 - any failure of one sample is recorded
            row["status"] = f"failed: {one_line(exc)}"
        if _study(study_path).compare_gains:
            row.update(given_gains(_study(study_path), sample, paths))
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


def _simulate_and_verify(
    sample: Sample, paths: StudyPaths, keep: bool, study: Study, row: dict[str, Any]
) -> dict[str, Any]:
    """Run the sample (written to disk or in memory) and summarize its bounds table; the
    columns of a run that stopped early go into ``row`` before its error is raised."""
    from verify import pipeline as P

    t0 = time.perf_counter()
    extra: dict[str, Any] = {}
    if keep:
        run, traj = _run_written(sample, paths)
        row.update(stop_columns(sample.scenario, traj, None))  # complete: no layout read
        t1 = time.perf_counter()
        v = P.verify_run(run, out_root=paths.runs)
    else:
        run, traj = simulate_in_memory(sample, paths, **engine(study))
        row.update(stop_columns(sample.scenario, traj, run.closed_loop.layout))
        traj.raise_if_incomplete()
        t1 = time.perf_counter()
        v = P.verify_run(run)  # with the gains the run used (Run.gains): no file is read
        if _measured(study):
            extra = topology_columns(sample.scenario, run.gains)
    return {
        "simulate_s": t1 - t0,
        "checks_s": time.perf_counter() - t1,
        "steps": run.meta.get("steps"),
        "library": library_key(run.meta),
        **{k: run.meta[k] for k in ("cyclic", "compiled") if k in run.meta},
        **extra,
        **summarize_table(v.table),
        **coverage_columns(v.table),
        **theorem2_entry(v.table, sample.scenario, run.frame, v.config),
        "tail_max_et": tail_max_et(run.frame, v.config.tail_fraction),
        **topology_in_tail(sample.scenario, run.frame, v.config.tail_fraction),
        **step_recovery(sample.scenario, run),
        **link_recovery(sample.scenario, run),
    }


def engine(study: Study) -> dict[str, bool]:
    """How the study's samples run: the keywords of :func:`simulate_in_memory`.

    Parameters
    ----------
    study : Study
    """
    return {"measured": _measured(study), "dense": study.graph is not None}


def _measured(study: Study) -> bool:
    """Whether the study measures Theorem 1 on its samples' switched topologies."""
    g = study.graph
    return g is not None and g.losses is not None and g.losses.theorem1 == "measured"


def _baseline(study: Study) -> bool:
    """Whether the study asks for each sample's run without its losses."""
    g = study.graph
    return g is not None and g.losses is not None and g.losses.baseline


#: the no-loss twin's columns (``<column>_nolosses``): its pairs not back in time, and why
NOLOSS_COLUMNS = (
    "switch_pairs_late",
    "switch_pairs_undefined",
    "switch_out_within",
    "switch_out_observer",
)


def link_baseline(
    sample: Sample, paths: StudyPaths, measured: bool = False, dense: bool = False
) -> dict[str, Any]:
    """The sample once more with its graph switches made no-ops (each sets the base
    graph's weight): the same structure, so the same compiled library, and the run the
    losses are compared with (``peak_u_late_nolosses``; NaN without switches). It keeps
    the sample's λ1 (synthesized over the topologies with the losses), so the two runs
    differ in the switches only.

    Parameters
    ----------
    sample : Sample
        The drawn sample.
    paths : StudyPaths
        The study's folders.
    measured, dense : bool
        As for :func:`simulate_in_memory`.
    """
    import dataclasses

    from core.graph import Switch
    from verify.link_recovery import peak_u_late, switch_recoveries, switch_summary
    from verify.table import gauge

    sc = sample.scenario
    if sc is None or not sc.graph.switches:
        return {"peak_u_late_nolosses": float("nan")}
    A, b = sc.graph.adjacency, sc.graph.pinning

    def same(s: Switch) -> Switch:
        w = b[s.follower] if s.neighbour is None else A[s.follower, s.neighbour]
        return dataclasses.replace(s, weight=float(w))

    graph = dataclasses.replace(sc.graph, switches=tuple(same(s) for s in sc.graph.switches))
    lambda1 = _gains(sc, f"gains of sample {sample.id}", measured).lambda1
    obs = dataclasses.replace(sc.observer, lambda1=float(lambda1))
    twin = dataclasses.replace(sample, scenario=dataclasses.replace(sc, graph=graph, observer=obs))
    run = run_in_memory(twin, paths, measured=measured, dense=dense)
    # the same (switch time, follower) pairs without the losses: what the formation's own
    # error leaves of the promise "back within 0.05 within 2 s"
    back = switch_summary(switch_recoveries(sc, run.frame, gauge(sc, run.gains)))
    return {
        "peak_u_late_nolosses": peak_u_late(run.frame, sc.N, sc.n),
        **{f"{k}_nolosses": back[k] for k in NOLOSS_COLUMNS},
    }


def given_gains(study: Study, sample: Sample, paths: StudyPaths) -> dict[str, Any]:
    """The sample once more with the base scenario's own gains (:meth:`Study.given`: the
    same draws without the design's keys), in memory; its columns prefixed ``given:``
    (``given:status`` as ``status``; docs/studies.md, 'Designed gains beside the base's').

    Parameters
    ----------
    study : Study
        A study with ``compare_gains``.
    sample : Sample
        The drawn sample (with the designed gains).
    paths : StudyPaths
        The study's folders.
    """
    twin = make_sample(study.given(), sample.id)
    out: dict[str, Any] = {}
    if twin.params != sample.params:  # the draws must not depend on the gains
        out["status"] = "failed: the draws differ without the design's keys"
    elif twin.scenario is None:
        out["status"] = f"refused: {twin.reason}"
    else:
        try:
            out.update(_simulate_and_verify(twin, paths, False, study, out))
            if _baseline(study):  # the given gains' own run without the losses
                out.update(link_baseline(twin, paths, **engine(study)))
            out["status"] = "ok"
        except Exception as exc:  # noqa: BLE001 - recorded like the sample's own run
            out["status"] = f"failed: {one_line(exc)}"
    return {f"{GIVEN}{k}": v for k, v in out.items()}


def _run_written(sample: Sample, paths: StudyPaths) -> tuple[Any, Any]:
    """``make sim`` of the written scenario file: samples/<name>.toml, runs/<name>/; the
    run and its (complete: ``api.run`` raises otherwise) trajectory."""
    from generated import api
    from verify import pipeline as P

    scenario_file = write_scenario(sample, paths.samples)
    res = api.run(scenario_file, out_root=paths.runs, progress=False)
    run = P.Run(sample.scenario, res.frame, res.trajectory.x, res.meta, res.csv_path.parent)
    return run, res.trajectory


def run_in_memory(
    sample: Sample, paths: StudyPaths, measured: bool = False, dense: bool = False
) -> Any:
    """The same steps as :func:`generated.api.run` (gains, build, integrate, outputs)
    writing nothing; the run's folder is where ``--keep-runs`` would write it.

    Parameters
    ----------
    sample : Sample
        The drawn sample (its scenario).
    paths : StudyPaths
        The study's folders.
    measured, dense : bool
        As for :func:`simulate_in_memory`.

    Raises
    ------
    IntegrationError
        The run stopped early.
    """
    run, traj = simulate_in_memory(sample, paths, measured=measured, dense=dense)
    traj.raise_if_incomplete()
    return run


def _gains(sc: Any, where: str, measured: bool) -> Any:
    """The run's gains: certified on the base graph (``measured``) or as ``make sim``'s."""
    from generated import api
    from sweep.switched_gains import base_graph_gains

    return base_graph_gains(sc, where) if measured else api.scenario_gains(sc, where)


def _frame(built: Any, sc: Any, traj: Any) -> Any:
    """The run's trajectory frame; its outputs through the verification's compiled Functions
    of the structure when there are (the same SX outputs as C: the same numbers,
    ``tests/test_parameters.py``), else the closed loop's."""
    import dataclasses

    from generated import api
    from verify.lyapunov import fast_functions, run_digest

    cl = built.closed_loop
    if cl.parametric is not None and cl.parametric.layout.dense:
        fast = fast_functions(cl, run_digest(cl.p0, traj.t, traj.x))
        if fast.compiled:
            built = dataclasses.replace(built, outputs_p=fast.functions["outputs"])
    return api.trajectory_frame(built, sc, traj)


def simulate_in_memory(
    sample: Sample, paths: StudyPaths, measured: bool = False, dense: bool = False
) -> tuple[Any, Any]:
    """:func:`run_in_memory` without raising for a run that stopped early.

    Parameters
    ----------
    sample : Sample
        The drawn sample (its scenario).
    paths : StudyPaths
        The study's folders.
    measured : bool
        Gains certified on the sample's base graph
        (:func:`sweep.switched_gains.base_graph_gains`).
    dense : bool
        The closed loop with the graph as data (``api.build``'s ``dense_graph``: one per
        N for a study that draws its graphs; method ``native`` only).

    Returns
    -------
    (Run, Trajectory)
        The run (its frame empty when the trajectory is incomplete) and the trajectory.
    """
    import pandas as pd

    from generated import api
    from verify import pipeline as P

    sc = sample.scenario
    gains = _gains(sc, f"gains of sample {sample.id}", measured)
    codegen = api.resolve_codegen(sc.N)
    method = sc.integration.method
    built = api.build(sc, gains, method, codegen, dense_graph=dense)
    traj = api.simulate(built, sc, api.integrator_settings(sc, method, codegen))
    frame = _frame(built, sc, traj) if traj.complete else pd.DataFrame()
    libs = built.agents[0] if built.agents is not None else (built.library,)
    meta = {"steps": traj.stats.get("steps"), "library": {"key": ";".join(x.key for x in libs)}}
    if built.agents is not None:  # the per-agent engine: the graph's cycles, a new library
        meta.update(cyclic=not built.agents[1].acyclic, compiled=not built.library.cache_hit)
    folder = paths.runs / sc.name
    run = P.Run(sc, frame, traj.x, meta, folder, gains=gains, closed_loop=built.closed_loop)
    return run, traj
