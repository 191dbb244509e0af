"""CSV operator traces (``leader.u0_csv``): recorded commands t, u0_1..u0_p, read and checked."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from core.files import FileRefused, read_regular_file
from core.reading import ReadingContext, frozen_array

MAX_TRACE_ROWS = 1_000_000  # rows of a CSV operator trace
MAX_TRACE_BYTES = 64 * 2**20  # size of a CSV operator trace (read whole)


def load_trace(
    ctx: ReadingContext, scen_path: Path, rel: Any, p: int, horizon: float
) -> np.ndarray:
    """Recorded operator commands: CSV with columns t, u0_1..u0_p (see docs/scenario-format.md).

    An optional header line and ``#`` comment lines are skipped. Time must be
    strictly increasing and cover [0, horizon]; u0 is linear between rows.
    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    scen_path : Path
        The scenario file (the trace's path is relative to it).
    rel : object
        ``leader.u0_csv`` as given.
    p : int
        Operator inputs (columns after t).
    horizon : float
        The run's horizon, which the trace must cover.
    """
    key = "leader.u0_csv"
    if not isinstance(rel, str) or not rel.strip():
        raise ctx.err(key, "is not a path", "a CSV path relative to the scenario file")
    try:
        fpath = (scen_path.parent / rel).resolve()
        text = read_regular_file(fpath, MAX_TRACE_BYTES).decode("utf-8")
        rows: list[tuple[int, list[str]]] = []
        reader = csv.reader(io.StringIO(text, newline=""))
        for r in reader:
            if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#"):
                rows.append((reader.line_num, r))
            if len(rows) > MAX_TRACE_ROWS:
                raise ctx.err(key, f"{rel} has more than {MAX_TRACE_ROWS} rows", "a shorter trace")
    except OSError as exc:
        raise ctx.err(key, f"cannot read {rel}: {exc.strerror}", "an existing CSV file") from None
    except FileRefused as exc:
        raise ctx.err(
            key,
            f"{rel} {exc}",
            f"a regular CSV file of at most {MAX_TRACE_BYTES >> 20} MiB: copy a recorded "
            "stream to a file first, or use a shorter or coarser trace",
        ) from None
    except (UnicodeDecodeError, csv.Error, ValueError) as exc:  # binary file, NUL byte, bad path
        raise ctx.err(
            key, f"{rel} is not a readable CSV text file ({type(exc).__name__})", "UTF-8 CSV text"
        ) from None
    if rows and not _is_float(rows[0][1][0]):
        rows = rows[1:]  # header
    if len(rows) < 2:
        raise ctx.err(
            key, f"{rel} has fewer than two data rows", "columns t, u0_1..u0_p, two rows or more"
        )
    data = []
    for line, r in rows:
        if len(r) != 1 + p:
            raise ctx.err(
                key, f"{rel} line {line} has {len(r)} columns", f"{1 + p} columns: t and {p} inputs"
            )
        if not all(_is_float(x) for x in r):
            raise ctx.err(key, f"{rel} line {line} is not numeric", "numbers")
        vals = [float(x) for x in r]
        if not all(map(math.isfinite, vals)):
            raise ctx.err(key, f"{rel} line {line} is not finite", "finite numbers")
        if data and vals[0] <= data[-1][0]:
            raise ctx.err(
                key,
                f"{rel} line {line}: time {vals[0]:g} does not increase (previous {data[-1][0]:g})",
                "a trace strictly increasing in time",
            )
        data.append(vals)
    arr = np.array(data)
    if arr[0, 0] > 0.0 or arr[-1, 0] < horizon:
        raise ctx.err(
            key,
            f"{rel} covers [{arr[0, 0]:g}, {arr[-1, 0]:g}] but the horizon is [0, {horizon:g}]",
            "a trace covering [0, integration.horizon] (or a shorter horizon)",
        )
    return frozen_array(arr)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except (ValueError, OverflowError):
        return False
    return True
