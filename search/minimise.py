"""The least robust run moved back toward the base scenario while it still violates
(docs/search.md, 'Minimised reproduction').

Group by group (the operator, each fault, each ``[params]`` key, in the box's order) the
group is first dropped (the base's value); if the run then no longer violates, each of
the group's numeric values is bisected between the base's (neutral) value and its own
for ``[search] minimise_steps`` steps, keeping the point closest to the base that still
violates. Every step is one evaluation (arm ``minimise``); the steps are deterministic, so
a rerun reuses their committed rows.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from core.artifacts import atomic_write_text
from core.faults import FAULT_TYPES
from search.space import Dimension, build_sample, dimensions, values_at
from search.spec import SearchFile
from sweep.run import commit_rows, read_results
from sweep.sampler import scenario_toml

WORST = "worst.toml"
MINIMISED = "minimised.toml"
STATE = "minimised.json"


@dataclass
class Minimised:
    """The outcome of minimisation.

    Attributes
    ----------
    source : dict
        The least robust row's arm, eval and robustness.
    requirement : str
        The violated requirement it keeps violating.
    values : dict
        The minimised point's values.
    dropped : list of str
        Groups reverted to the base scenario.
    robustness : float
        The minimised run's robustness of ``requirement``.
    changed : list of str
        Values that differ from the base.
    steps : int
        Evaluations spent.
    """

    source: dict
    requirement: str
    values: dict
    dropped: list[str] = field(default_factory=list)
    robustness: float = math.nan
    changed: list[str] = field(default_factory=list)
    steps: int = 0


def least_robust(table: pd.DataFrame) -> pd.Series | None:
    """The ``ok`` row of arm search or baseline with the least robustness, or None.

    Parameters
    ----------
    table : DataFrame
        results.parquet.
    """
    if not len(table) or "arm" not in table.columns:
        return None
    ok = table[(table["status"] == "ok") & table["arm"].isin(["search", "baseline"])]
    if not len(ok):
        return None
    return ok.loc[ok["robustness"].astype(float).idxmin()]


def point_of(row: pd.Series, dims: tuple[Dimension, ...]) -> dict[str, Any]:
    """A row's values, recomputed from its coordinates ``u:<k>``.

    Parameters
    ----------
    row : Series
        A search or baseline row.
    dims : tuple of Dimension
        The box.
    """
    return values_at(dims, [float(row[f"u:{k}"]) for k in range(len(dims))])


def minimise(
    search: SearchFile, results: Path, executor: Any, info: dict[str, str]
) -> Minimised | None:
    """Minimise the least robust run when it violates; write worst.toml, minimised.toml and
    minimised.json next to the results (removed when nothing violates).

    Parameters
    ----------
    search : SearchFile
        The search.
    results : Path
        results.parquet.
    executor : callable
        Runs a batch of points (:mod:`search.run`).
    info : dict
        Provenance stored with committed rows.
    """
    folder = results.parent
    done = read_results(results)
    worst = least_robust(done)
    for name in (WORST, MINIMISED, STATE):
        (folder / name).unlink(missing_ok=True)
    if worst is None:
        return None
    dims = dimensions(search.study)
    values = point_of(worst, dims)
    _write(search, folder / WORST, values, frozenset(), "least robust run")
    if float(worst["robustness"]) >= 0:
        return None
    req = min((r.name for r in search.requirements), key=lambda n: float(worst[f"rob:{n}"]))
    state = Minimised(
        {
            "arm": str(worst["arm"]),
            "eval": int(worst["eval"]),
            "robustness": float(worst["robustness"]),
        },
        req,
        dict(values),
        robustness=float(worst[f"rob:{req}"]),
    )
    known = {
        int(r["eval"]): r
        for r in done.to_dict("records")
        if r.get("arm") == "minimise" and r.get("status") == "ok"
    }
    folder_s = str(folder.resolve())

    def violates(vals: dict, dropped: list[str]) -> tuple[bool, float]:
        k = state.steps
        state.steps += 1
        row = known.get(k)
        key = _point_key(vals, dropped)
        if row is None or row.get("point") != key:  # a step of another minimisation
            point = {"arm": "minimise", "eval": k, "values": vals, "dropped": sorted(dropped)}
            row = executor(search, [point], folder_s)[0]
            row["dropped"] = json.dumps(sorted(dropped))
            row["point"] = key
            nonlocal done
            done = commit_rows(results, done, [row], info)
        rob = row.get(f"rob:{req}")
        ok = row.get("status") == "ok" and rob is not None and float(rob) < 0
        return ok, float(rob) if rob is not None else math.nan

    groups = list(dict.fromkeys(d.group for d in dims))
    for g in groups:
        hit, rob = violates(state.values, [*state.dropped, g])
        if hit:
            state.dropped.append(g)
            state.robustness = rob
            continue
        for d in (d for d in dims if d.group == g and d.neutral is not None):
            if _used(d, state.values):
                _bisect(state, d, search.settings.minimise_steps, violates)
    state.changed = [
        d.name
        for d in dims
        if d.group not in state.dropped
        and _used(d, state.values)
        and (d.neutral is None or state.values[d.name] != d.neutral)
    ]
    _write(
        search, folder / MINIMISED, state.values, frozenset(state.dropped), "minimised reproduction"
    )
    atomic_write_text(folder / STATE, json.dumps(asdict(state), indent=1, default=str))
    return state


def _used(d: Dimension, values: dict) -> bool:
    """Whether the point's scenario uses ``d``: a fault key only for the types that take it
    (an intermittent fault has no ``duration``), and a fault slot only within ``faults.count``."""
    m = re.fullmatch(r"faults\[(\d+)\]\.(\w+)(\[\d+\])?", d.name)
    if m is None:
        return True
    slot, key = int(m.group(1)), m.group(2)
    if slot > int(values.get("faults.count", slot)):
        return False
    if key in ("follower", "type"):
        return True
    return key in FAULT_TYPES[values[f"faults[{slot}].type"]][1:]


def _point_key(values: dict, dropped: list[str]) -> str:
    """The step's point as JSON: a committed step is reused only for the same point."""
    return json.dumps({"values": values, "dropped": sorted(dropped)}, sort_keys=True, default=str)


def _bisect(state: Minimised, d: Dimension, steps: int, violates: Any) -> None:
    """Move ``d``'s value toward its neutral value while the run still violates."""
    far = state.values[d.name]
    near = d.neutral
    if isinstance(far, int) and not isinstance(far, bool):
        return  # integers are left as found
    lo, hi = 0.0, 1.0  # fraction of the way from neutral to the found value
    for _ in range(steps):
        mid = (lo + hi) / 2
        trial = dict(state.values)
        trial[d.name] = near + mid * (far - near)
        hit, rob = violates(trial, state.dropped)
        if hit:
            hi = mid
            state.robustness = rob
        else:
            lo = mid
    state.values[d.name] = near + hi * (far - near)


def _write(search: SearchFile, path: Path, values: dict, dropped: frozenset, what: str) -> None:
    """A point's scenario file, for ``make sim`` / ``make verify``."""
    name = f"{search.name}-{path.stem}"
    sample = build_sample(search.study, values, name, dropped)
    data = dict(sample.scenario_data)
    data["description"] = f"{what} of search {search.name}"
    atomic_write_text(path, scenario_toml(data))
