"""A console run written as files that replay it: u0 trace, scenario, logged states.

``<folder>/`` (``record-<date>-<time>-<microseconds>``, created exclusively: a record
never replaces another)
  ``u0.csv``          the operator's command, one row per change (t, u0_1..u0_p) and a last
                      row at the end time; each change a smoothstep ramp from its row on
                      (``leader.u0_hold`` with ``leader.u0_rise``, core/hold.py)
  ``events.csv``      what the integrator did: failures, restarts, holds (t, kind, text)
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

:class:`Recorder` writes from the server's record worker thread, not the loop's: each
logged row is formatted once into the run's :class:`LogSpool` (later saves append only
the rows logged since) and copied to each record's ``console.csv``; every file appears
complete or not at all (a temporary file and :func:`os.replace`). A save that fails (a
full disk) leaves nothing: the rows it was appending are cut off the spool again, and
its record folder is removed, so the next save writes every row exactly once.
"""

from __future__ import annotations

import copy
import csv
import io
import os
import shutil
import tempfile
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from console.engine import CONSOLE_RISE, Change, Event, LoopBase
from core.artifacts import atomic_write_text
from core.errors import ToolkitError
from core.scenario import load_scenario
from sweep.sampler import scenario_toml

if TYPE_CHECKING:
    from console.session import Snapshot

TRACE_NAME, LOG_NAME, EVENTS_NAME = "u0.csv", "console.csv", "events.csv"


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
    table: dict,
    changes: Sequence[Change],
    nominal_health: Sequence[float],
    t_end: float,
    h: float,
    rise: float = CONSOLE_RISE,
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
    rise : float
        Rise time of the console's shaped changes of u0 (``leader.u0_rise``).
    """
    data = copy.deepcopy(table)
    data["name"] = f"{table['name']}-replay"
    data["description"] = f"replay of a console run of {table['name']} to t = {t_end:g} s"
    leader = data["leader"]
    leader.pop("u0", None)
    leader["u0_csv"] = TRACE_NAME
    leader["u0_hold"] = True
    leader["u0_rise"] = float(rise)
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
    rise: float = CONSOLE_RISE,
    events: Sequence[Event] = (),
) -> Record:
    """Write ``u0.csv``, ``console.csv``, ``events.csv`` and, when replayable, the scenario.

    Parameters
    ----------
    folder : Path
        Created if missing (:func:`new_folder` makes a fresh one).
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
    rise : float
        Rise time of the shaped changes of u0.
    events : sequence of Event
        The integrator's failures, restarts and holds.
    """
    folder.mkdir(parents=True, exist_ok=True)
    text = _csv_header(columns) + _csv_rows(t_log, x_log)
    atomic_write_text(folder / LOG_NAME, text)
    write_events(folder, events)
    run = (changes, u0_start, nominal_health, restarts)
    return write_replay(folder, table, run, float(t_log[-1]), len(t_log), h, rise)


def write_events(folder: Path, events: Sequence[Event]) -> Path:
    """``events.csv``: t, kind, text of every integrator event (a header only when none).

    Parameters
    ----------
    folder : Path
        An existing folder.
    events : sequence of Event
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["t", "kind", "text"])
    w.writerows([repr(float(e.t)), e.kind, e.text] for e in events)
    return atomic_write_text(folder / EVENTS_NAME, buf.getvalue())


def write_replay(
    folder: Path,
    table: dict,
    run: tuple[Sequence[Change], Sequence[float], Sequence[float], Sequence[float]],
    t_end: float,
    rows: int,
    h: float,
    rise: float = CONSOLE_RISE,
) -> Record:
    """Write ``u0.csv`` and, when replayable, the scenario (``console.csv`` is written apart).

    Parameters
    ----------
    folder : Path
        An existing folder.
    table : dict
        The console scenario as parsed TOML.
    run : tuple
        The run's changes, u0 and healths at t = 0, and integrator restarts
        (as :func:`write_record`'s parameters).
    t_end : float
        The last logged time.
    rows : int
        Rows of ``console.csv``.
    h : float
        The console's quantum.
    rise : float
        Rise time of the shaped changes of u0.
    """
    changes, u0_start, nominal_health, restarts = run
    trace = u0_rows(changes, u0_start, t_end, restarts) if t_end > 0 else []
    head = "t," + ",".join(f"u0_{k}" for k in range(1, len(u0_start) + 1))
    body = [",".join(repr(float(v)) for v in r) for r in trace]
    atomic_write_text(folder / TRACE_NAME, "\n".join([head, *body]) + "\n")
    if t_end <= 0:
        return Record(folder, None, rows, t_end, "nothing to replay yet (t = 0)")
    used = [c for c in changes if c.t < t_end]
    data = replay_table(table, used, nominal_health, t_end, h, rise)
    data["name"] = f"{table['name']}-{folder.name}"
    path = atomic_write_text(folder / f"{data['name']}.toml", scenario_toml(data))
    try:
        load_scenario(path)
    except ToolkitError as exc:
        path.unlink()
        return Record(folder, None, rows, t_end, f"the replay is not a valid scenario: {exc}")
    return Record(folder, path, rows, t_end)


def new_folder(root: Path) -> Path:
    """Create a new record folder ``root/record-<date>-<time>-<microseconds>`` exclusively.

    A name already taken gets ``-2``, ``-3``, ... appended: a record never replaces another.

    Parameters
    ----------
    root : Path
        Where records go (created if missing).

    Raises
    ------
    ToolkitError
        When no free name is found.
    """
    root.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now().strftime("record-%Y%m%d-%H%M%S-%f")
    for k in range(1, 1000):
        folder = root / (stamp if k == 1 else f"{stamp}-{k}")
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        return folder
    raise ToolkitError(f"{root}: no free record folder named {stamp}-*")


def _csv_header(columns: Sequence[str]) -> str:
    return "t," + ",".join(columns) + "\n"


def _csv_rows(t: Sequence[float], x: np.ndarray) -> str:
    """``console.csv`` lines (shortest round-trip reprs), each ending in a newline."""
    return "".join(
        repr(float(tk)) + "," + ",".join(map(repr, row)) + "\n"
        for tk, row in zip(t, np.asarray(x, dtype=float).tolist(), strict=True)
    )


class LogSpool:
    """A run's ``console.csv`` text in one anonymous temporary file, appended to as saves
    need more rows: each logged row is formatted once, however many records hold it.

    Parameters
    ----------
    root : Path
        Folder of the temporary file (the records' root, not a RAM-backed /tmp).
    columns : sequence of str
        Names of the state columns.
    """

    def __init__(self, root: Path, columns: Sequence[str]) -> None:
        root.mkdir(parents=True, exist_ok=True)
        # unbuffered: what write() returns is on file, so a failed append can be cut off
        self.file = tempfile.TemporaryFile(dir=root, prefix=".console-log-", buffering=0)
        self.size = self.rows = 0
        #: a failed append could not be cut off: the spool must not be used again
        self.broken = False
        self._append(_csv_header(columns).encode("utf-8"))

    def _append(self, data: bytes) -> None:
        """Write ``data`` at the end, all of it or nothing (a failed write is truncated)."""
        try:
            view = memoryview(data)
            while view:
                view = view[self.file.write(view) :]
        except BaseException:
            try:
                self.file.truncate(self.size)
                self.file.seek(self.size)
            except OSError:
                self.broken = True
            raise
        self.size += len(data)

    def extend(self, t: Sequence[float], x: np.ndarray) -> None:
        """Append rows, all of them or none (a failed write leaves the spool as it was).

        Parameters
        ----------
        t : sequence of float
            Their times.
        x : ndarray, shape (len(t), len(columns))
            Their values.
        """
        self._append(_csv_rows(t, x).encode("utf-8"))
        self.rows += len(t)

    def copy_to(self, path: Path) -> None:
        """Write the rows so far to ``path`` via a temporary file and :func:`os.replace`.

        Parameters
        ----------
        path : Path
            Destination in an existing folder.
        """
        self.file.seek(0)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as out:
                shutil.copyfileobj(self.file, out, 1 << 20)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        finally:
            self.file.seek(self.size)

    def close(self) -> None:
        """Remove the temporary file."""
        self.file.close()


class Recorder:
    """Writes a console's records: a new folder per save, the log appended incrementally.

    Called with a :class:`~console.session.Snapshot` (from any thread; one save at a
    time): the rows logged since the last save of the same run are added to the run's
    :class:`LogSpool`, which is copied to the new folder's ``console.csv``. A save that
    fails removes its folder and leaves the spool as it was before it.

    Parameters
    ----------
    out : Path
        Where records go (``<out>/record-…/``).
    table : dict
        The console scenario as parsed TOML.
    loop : LoopBase
        The console's loop (its nominal settings, quantum and state columns; it is not
        read while it runs).
    """

    def __init__(self, out: Path, table: dict, loop: LoopBase) -> None:
        self.out, self.table, self.loop = Path(out), table, loop
        self.lock = threading.Lock()
        self.spool: LogSpool | None = None
        self.run = 0

    def __call__(self, snap: Snapshot) -> dict:
        """Write the record of ``snap``; the reply a page gets.

        Parameters
        ----------
        snap : Snapshot
            From :meth:`console.session.Session.snapshot`.
        """
        loop = self.loop
        with self.lock:
            folder = new_folder(self.out)
            try:
                self._spool(snap).copy_to(folder / LOG_NAME)
                nominal = loop.nominal
                run = (snap.changes, nominal.u0.tolist(), nominal.health.tolist(), snap.restarts)
                write_events(folder, snap.events)
                rec = write_replay(
                    folder, self.table, run, snap.t_end, snap.rows, loop.quantum, loop.rise
                )
            except BaseException:
                shutil.rmtree(folder, ignore_errors=True)  # no half-written record
                raise
        return rec.message()

    def _spool(self, snap: Snapshot) -> LogSpool:
        """The run's spool holding the snapshot's rows (a new one for a new run, or after
        a failed append that could not be cut off)."""
        spool = self.spool
        if spool is None or spool.broken or self.run != snap.run or spool.rows > snap.rows:
            if spool is not None:
                spool.close()
                self.spool = None
            self.spool, self.run = LogSpool(self.out, self.loop.state_columns()), snap.run
        k = self.spool.rows
        if snap.rows > k:
            X = self.loop.state_table(np.asarray(snap.log_x[k : snap.rows]))
            self.spool.extend(snap.log_t[k : snap.rows], X)
        return self.spool
