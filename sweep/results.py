"""A study's outputs: its folders and the results table, one row per sample.

Rows are committed to ``<study>/results.parquet`` by an atomic replace of the whole
table (a temporary file named after its writer's PID, then ``os.replace``): an
interrupted study leaves the last committed table, and a rerun resumes from it
(:mod:`sweep.resume`). A file that is not such a table is refused, never overwritten.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from core.artifacts import atomic_write_bytes
from core.errors import ToolkitError
from core.files import FileRefused, read_regular_file

RESULTS = "results.parquet"
#: largest results table read (bytes)
MAX_RESULTS_BYTES = 1 << 32
#: columns a results table must have to be read as one
REQUIRED_COLUMNS = ("id", "status")
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
    "t_reached",
    "t_stop",
    "stop_state",
    "stop_abs",
    "rows_abs",
    "switch_before_stop",
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
    "switch_recovery_s",
    "switch_pairs",
    "switch_pairs_late",
    "switch_pairs_undefined",
    "switch_pairs_out_before",
    "switch_deviation_max",
    "peak_u_late_nolosses",
    "switch_pairs_late_nolosses",
    "switch_pairs_undefined_nolosses",
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


class ResultsError(ToolkitError):
    """A results file that is not a results table (truncated, foreign, not a regular file)."""


def read_results(path: Path) -> pd.DataFrame:
    """The committed rows (an empty table when the file does not exist).

    Parameters
    ----------
    path : Path
        ``results.parquet``: a regular file of at most :data:`MAX_RESULTS_BYTES`, a
        Parquet table with the columns :data:`REQUIRED_COLUMNS`.

    Raises
    ------
    ResultsError
        One line naming the file, what is wrong with it and the fix; the file is kept.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return pd.DataFrame(columns=BASE_COLUMNS)
    try:
        data = read_regular_file(path, MAX_RESULTS_BYTES)
        table = pq.read_table(pa.BufferReader(data)).to_pandas()
    except FileRefused as exc:
        raise _unreadable(path, str(exc)) from None
    except (pa.ArrowException, ValueError, OSError) as exc:
        raise _unreadable(path, f"is not a Parquet table ({type(exc).__name__}: {exc})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in table.columns]
    if missing:
        raise _unreadable(path, f"has no column {', '.join(missing)}: not a study's results")
    return table


def _unreadable(path: Path, problem: str) -> ResultsError:
    return ResultsError(
        f"{path} {problem[:300]}; it is kept: move or delete it, or give another --out DIR "
        "(`python -m sweep run --restart` discards it)"
    )


def commit_rows(
    path: Path, old: pd.DataFrame, rows: list[dict], info: dict[str, str]
) -> pd.DataFrame:
    """Write ``old`` plus ``rows`` as the whole table: a temporary file, then ``os.replace``
    (:func:`core.artifacts.atomic_write_bytes`).

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
    sink = pa.BufferOutputStream()
    pq.write_table(arrow.replace_schema_metadata(meta), sink)
    # a temporary name per writer (its PID), then os.replace: never a half-written table
    atomic_write_bytes(path, sink.getvalue().to_pybytes())
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
