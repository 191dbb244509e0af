"""A console run written as files that replay it: u0 trace, scenario, logged states.

``<folder>/``
  ``u0.csv``          the operator's command, one row per change (t, u0_1..u0_p) and a last
                      row at the end time; held constant between rows (``leader.u0_hold``)
  ``<name>.toml``     the console's scenario with ``leader.u0_csv = "u0.csv"``, the health
                      changes as each follower's ``g`` table, each bias change as a
                      ``bias`` fault (its onset and the change as amplitude), the horizon
                      the run reached and the console's quantum as output step
  ``console.csv``     the states the console logged at every quantum (trajectory.csv's
                      state columns), to compare with the replay's trajectory.csv

and each link cut or restored as a ``[[graph.switches]]`` table. The scenario is loaded
back before the record is reported; one the loader refuses (a cut that leaves a
follower unreachable from the leader, which a scenario may not have) is removed and the
record says why, keeping ``u0.csv`` and ``console.csv``.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from console.engine import Change
from core.artifacts import atomic_write_text
from core.errors import ToolkitError
from core.scenario import load_scenario
from sweep.sampler import scenario_toml

TRACE_NAME, LOG_NAME = "u0.csv", "console.csv"


@dataclass(frozen=True)
class Record:
    """What was written.

    Attributes
    ----------
    folder : Path
    scenario : Path or None
        None when the run cannot be replayed by a scenario file (``reason`` says why).
    rows : int
        Logged states in ``console.csv``.
    t_end : float
        The replay's horizon.
    reason : str
        Empty, or why no scenario was written.
    """

    folder: Path
    scenario: Path | None
    rows: int
    t_end: float
    reason: str = ""

    def message(self) -> dict:
        """The reply a page gets."""
        return {
            "folder": str(self.folder),
            "scenario": str(self.scenario) if self.scenario else "",
            "rows": self.rows,
            "t_end": self.t_end,
            "reason": self.reason,
        }


def u0_rows(
    changes: Sequence[Change],
    u0_start: Sequence[float],
    t_end: float,
    restarts: Sequence[float] = (),
) -> list[list[float]]:
    """The held operator command as trace rows: (t, u0...) at 0, at each change, at ``t_end``.

    A row is also written at every time the console restarted its integrator without a
    change (``restarts``), with the command then held: a held trace's rows are the
    replay's breakpoints, so the replay restarts where the console did and takes the
    same steps.

    Parameters
    ----------
    changes : sequence of Change
        The run's changes in time order (others than ``u0`` are skipped).
    u0_start : sequence of float
        The command at t = 0 before any change.
    t_end : float
        The last logged time (> 0); changes at or after it are dropped.
    restarts : sequence of float
        Times the console's integrator restarted.
    """
    rows = {0.0: [float(v) for v in u0_start]}
    for c in changes:
        if c.kind == "u0" and c.t < t_end:
            rows[c.t] = list(c.values)
    knots = sorted(rows)
    for t in restarts:
        if 0.0 < t < t_end and t not in rows:
            j = int(np.searchsorted(knots, t, side="right")) - 1
            rows[t] = rows[knots[j]]
    rows.setdefault(t_end, rows[max(k for k in rows if k < t_end)] if t_end > 0 else rows[0.0])
    return [[t, *rows[t]] for t in sorted(rows)]


def replay_table(
    table: dict, changes: Sequence[Change], nominal_health: Sequence[float], t_end: float, h: float
) -> dict:
    """The console's scenario table turned into the replay of a run.

    Parameters
    ----------
    table : dict
        The console scenario as parsed TOML (u0 held, bias literal in every f).
    changes : sequence of Change
        The run's changes in time order (no ``link`` changes).
    nominal_health : sequence of float
        g_i at t = 0.
    t_end : float
        Horizon of the replay (the last logged time).
    h : float
        The console's quantum, the replay's output step.
    """
    data = copy.deepcopy(table)
    data["name"] = f"{table['name']}-replay"
    data["description"] = f"replay of a console run of {table['name']} to t = {t_end:g} s"
    leader = data["leader"]
    leader.pop("u0", None)
    leader["u0_csv"] = TRACE_NAME
    leader["u0_hold"] = True
    bias = {}
    for i, fo in enumerate(data["followers"]):
        g = [[0.0, float(nominal_health[i])]]
        for c in changes:
            if c.follower != i or c.t > t_end:
                continue
            if c.kind == "health":
                if c.t == g[-1][0]:
                    g[-1] = [c.t, c.values[0]]
                else:
                    g.append([c.t, c.values[0]])
            elif c.kind == "bias":
                old = bias.get(i, np.zeros(len(c.values)))
                new = np.array(c.values)
                fo.setdefault("faults", []).append(
                    {"type": "bias", "onset": c.t, "amplitude": (new - old).tolist()}
                )
                bias[i] = new
        fo["g"] = g if len(g) > 1 else g[0][1]
    data["graph"].pop("switches", None)  # the console's no-op switch (console.scenario)
    links = [c for c in changes if c.kind == "link" and c.t < t_end]
    if links:
        data["graph"]["switches"] = [
            {
                "time": c.t,
                "follower": c.follower + 1,
                "neighbour": c.neighbour + 1,
                "weight": c.values[0],
            }
            for c in links
        ]
    integ = data.setdefault("integration", {})
    integ["horizon"], integ["output_step"] = t_end, h
    return data


def write_record(
    folder: Path,
    table: dict,
    changes: Sequence[Change],
    u0_start: Sequence[float],
    nominal_health: Sequence[float],
    t_log: np.ndarray,
    x_log: np.ndarray,
    columns: Sequence[str],
    h: float,
    restarts: Sequence[float] = (),
) -> Record:
    """Write ``u0.csv``, ``console.csv`` and, when replayable, the scenario (atomically).

    Parameters
    ----------
    folder : Path
        Created if missing.
    table : dict
        The console scenario as parsed TOML.
    changes : sequence of Change
        The run's changes in time order.
    u0_start, nominal_health
        The command and the healths at t = 0.
    t_log : ndarray, shape (K,)
        Logged times from 0 (K >= 2 for a replayable run).
    x_log : ndarray, shape (K, len(columns))
        Logged values.
    columns : sequence of str
        Names of ``x_log``'s columns.
    h : float
        The console's quantum.
    restarts : sequence of float
        Times the console's integrator restarted (rows of the trace, see :func:`u0_rows`).
    """
    folder.mkdir(parents=True, exist_ok=True)
    t_end = float(t_log[-1])
    lines = ["t," + ",".join(columns)]
    lines += [",".join(repr(float(v)) for v in (t, *x)) for t, x in zip(t_log, x_log, strict=True)]
    atomic_write_text(folder / LOG_NAME, "\n".join(lines) + "\n")
    rows = u0_rows(changes, u0_start, t_end, restarts) if t_end > 0 else []
    p = len(u0_start)
    head = "t," + ",".join(f"u0_{k}" for k in range(1, p + 1))
    body = [",".join(repr(float(v)) for v in r) for r in rows]
    atomic_write_text(folder / TRACE_NAME, "\n".join([head, *body]) + "\n")
    used = [c for c in changes if c.t < t_end]
    if t_end <= 0:
        return Record(folder, None, len(t_log), t_end, "nothing to replay yet (t = 0)")
    data = replay_table(table, used, nominal_health, t_end, h)
    data["name"] = f"{table['name']}-{folder.name}"
    path = atomic_write_text(folder / f"{data['name']}.toml", scenario_toml(data))
    try:
        load_scenario(path)
    except ToolkitError as exc:
        path.unlink()
        return Record(folder, None, len(t_log), t_end, f"the replay is not a valid scenario: {exc}")
    return Record(folder, path, len(t_log), t_end)
