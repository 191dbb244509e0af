"""One evaluation: a point of the box simulated and verified as a study sample is, and its
robustness per requirement (docs/search.md, 'Robustness').

The run takes the study's in-memory path (:func:`sweep.run.run_in_memory`: gains, the
shared compiled library, integration, outputs) and the bound table of
:func:`verify.pipeline.verify_run`, as ``make sweep`` does for each sample.
"""

from __future__ import annotations

import datetime as dt
import math
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from search import stl
from search.space import build_sample
from search.spec import SIGNALS, Requirement, SearchFile
from sweep.sampler import Sample

#: rows whose observed value is the fraction of output times at which a check holds
FRACTION = "fraction"
#: status of a run a requirement cannot score (robustness ±inf or NaN), :func:`unscored`
UNSCORED = "unscored"


def signals(sample: Sample, run: Any) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The logged signals a formula may name: per follower i ``deviation<i>`` (‖p_i − s_i‖,
    the formation slot of :func:`verify.operator_steps.slots`), ``et<i>`` (|e_ti|),
    ``eeta<i>`` (|ē_ηi|), ``u<i>`` (|u_i|), and their maxima over followers.

    Parameters
    ----------
    sample : Sample
        The evaluated sample.
    run : verify.pipeline.Run
        Its run (frame and gains).
    """
    from verify.operator_steps import deviation
    from verify.table import gauge

    sc, frame = sample.scenario, run.frame
    t = frame["t"].to_numpy(float)
    dev = deviation(sc, frame, gauge(sc, run.gains))
    out: dict[str, np.ndarray] = {}
    cols = list(frame.columns)
    for i in range(1, sc.N + 1):
        out[f"deviation{i}"] = dev[:, i - 1]
        for name in ("et", "eeta", "u"):
            mine = [c for c in cols if re.fullmatch(rf"{name}{i}_\d+", c)]
            out[f"{name}{i}"] = np.linalg.norm(frame[mine].to_numpy(float), axis=1)
    for name in SIGNALS:
        out[name] = np.max([out[f"{name}{i}"] for i in range(1, sc.N + 1)], axis=0)
    return t, out


def guaranteed_robustness(table: pd.DataFrame, claims: tuple[str, ...] = ()) -> tuple[float, str]:
    """The least margin of the table's ``guaranteed`` rows, and that row's label.

    A row ``observed <= bound`` has margin ``(bound - observed) / |bound|``; a row whose
    observed value is a fraction of output times (claim text names a fraction) has margin
    ``observed - bound`` when it fails and 1 when it holds. The sign follows the row's
    verdict (``holds``): a failing row's margin is negative even when its numbers tie.

    Parameters
    ----------
    table : DataFrame
        The bound table (bounds.csv's columns: claim, claim_id, agent, kind, bound,
        observed, holds).
    claims : tuple of str
        Only rows of these claim ids (empty: every guaranteed row).

    Returns
    -------
    (float, str)
        The margin (inf when there is no such row) and ``claim (follower i)``.
    """
    best, label = math.inf, ""
    for row in table.itertuples(index=False):
        if row.kind != "guaranteed" or (claims and row.claim_id not in claims):
            continue
        holds = row.holds is True or row.holds == True  # noqa: E712
        m = _margin(str(row.claim), float(row.bound), float(row.observed), holds)
        if m < best:
            best, label = m, _label(row)
    return best, label


def _margin(claim: str, bound: float, observed: float, holds: bool) -> float:
    if FRACTION in claim:
        return 1.0 if holds else min(observed - bound, -1e-12)
    if not (math.isfinite(bound) and math.isfinite(observed)):
        return 1.0 if holds else -1.0
    m = (bound - observed) / max(abs(bound), 1e-300)
    if holds:
        return max(m, 0.0)
    return min(m, -1e-12)


def _label(row: Any) -> str:
    try:
        return f"{row.claim} (follower {int(row.agent)})"
    except (TypeError, ValueError):
        return str(row.claim)


def robustness(
    reqs: tuple[Requirement, ...], sample: Sample, run: Any, table: pd.DataFrame
) -> dict[str, Any]:
    """``rob:<name>`` (scaled robustness) per requirement, ``worst_row:<name>`` for a
    guaranteed-rows requirement, and ``robustness``, the least of them.

    Parameters
    ----------
    reqs : tuple of Requirement
        The search file's requirements.
    sample, run, table
        The evaluated sample, its run and its bound table.
    """
    out: dict[str, Any] = {}
    t, values = signals(sample, run)
    for r in reqs:
        if r.guaranteed:
            rob, label = guaranteed_robustness(table, r.claims)
            out[f"worst_row:{r.name}"] = label
        else:
            rob = stl.robustness(r.node, t, values)
        out[f"rob:{r.name}"] = rob / r.scale
    out["robustness"] = min(out[f"rob:{r.name}"] for r in reqs)
    return out


def unscored(reqs: tuple[Requirement, ...], row: dict[str, Any]) -> str | None:
    """The status of a run some requirement cannot score, or None when all are finite.

    An ``always`` or ``eventually`` window that holds no sample of the run (it begins
    past the horizon) has robustness +inf or -inf, and a guaranteed-rows requirement
    whose claims have no guaranteed row in the table +inf: such a number ranks nothing,
    so the run is recorded as ``unscored: <requirement> ...`` (not told to CMA-ES, not
    the least robust run) and the report lists it.

    Parameters
    ----------
    reqs : tuple of Requirement
        The search file's requirements.
    row : dict
        The run's row with its ``rob:<name>`` columns (:func:`robustness`).
    """
    for r in reqs:
        v = float(row[f"rob:{r.name}"])
        if math.isfinite(v):
            continue
        if math.isnan(v):
            why = "is not a number (the run's signals hold NaN)"
        elif r.guaranteed:
            why = f"is {v:+g}: the bound table has no guaranteed row of its claims"
        else:
            why = f"is {v:+g}: a time window of its formula holds no sample (past the horizon)"
        return f"{UNSCORED}: {r.name} robustness {why}"
    return None


def verify_table(run: Any) -> pd.DataFrame:
    """The run's bound table (:func:`verify.pipeline.verify_run`).

    Parameters
    ----------
    run : verify.pipeline.Run
        A run in memory.
    """
    from verify import pipeline as P

    return P.verify_run(run).table


ARMS = ("search", "baseline", "minimise")


def row_id(arm: str, k: int) -> int:
    """The row's unique ``id`` in results.parquet: ``arm's index × 10**6 + k``.

    Parameters
    ----------
    arm : str
        One of :data:`ARMS`.
    k : int
        The evaluation's index within its arm.
    """
    return ARMS.index(arm) * 1_000_000 + int(k)


def evaluate(search: SearchFile, point: dict[str, Any], folder: str) -> dict[str, Any]:
    """Simulate, verify and score one point; never raises for the point's own fault.

    Parameters
    ----------
    search : SearchFile
        The search.
    point : dict
        ``arm``, ``eval`` (index), ``values`` (dimension -> value), ``dropped`` (groups)
        and ``u`` (the coordinates, or None for a minimisation step).
    folder : str
        The search's output folder.

    Returns
    -------
    dict
        One flat row: arm, eval, ``u:<k>``, ``param:<key>``, status, robustness columns.
    """
    from sweep.run import StudyPaths, one_line, param_columns, run_in_memory
    from sweep.worker import engine

    t0 = time.perf_counter()
    name = f"{search.name}-{point['arm']}-{point['eval']:04d}"
    sample = build_sample(
        search.study, point["values"], name, frozenset(point.get("dropped", ())), point["eval"]
    )
    row: dict[str, Any] = {
        "id": row_id(point["arm"], point["eval"]),
        "arm": point["arm"],
        "eval": point["eval"],
        "name": name,
        "target": point.get("target", ""),
    }
    for k, x in enumerate(point.get("u") or ()):
        row[f"u:{k}"] = float(x)
    row.update(param_columns(sample))
    if sample.scenario is None:
        row["status"] = f"refused: {sample.reason}"
    else:
        try:
            run = run_in_memory(sample, StudyPaths(Path(folder)), **engine(search.study))
            row.update(robustness(search.requirements, sample, run, verify_table(run)))
            row["library"] = run.meta.get("library", {}).get("key", "")
            row["status"] = unscored(search.requirements, row) or "ok"
        except Exception as exc:  # noqa: BLE001 - one point's failure is recorded
            row["status"] = f"failed: {one_line(exc)}"
    row["wall_s"] = time.perf_counter() - t0
    row["finished_utc"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    return row


def evaluate_many(search: SearchFile, points: list[dict], folder: str) -> list[dict[str, Any]]:
    """:func:`evaluate` for each point in turn (one Dask task).

    Parameters
    ----------
    search, folder
        As for :func:`evaluate`.
    points : list of dict
        The chunk's points.
    """
    return [evaluate(search, p, folder) for p in points]
