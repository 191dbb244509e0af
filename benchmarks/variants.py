"""Variant studies: one study run again with a few ``[set]`` keys on top, and their summary.

:mod:`benchmarks.remedies` (remedies for operator steps) and :mod:`benchmarks.links`
(switching models for link losses) each compare variants of one study: the same samples
(same seeds, same draws) with a variant's keys in ``[set]``, run through ``python -m sweep
run`` (``sweep`` is the layer above, so only its command line is used) and summarised from
its ``results.parquet``. This module holds what they share: the variant, its study file, the
run, the pooled counts over the ``ok`` samples and the table's number format.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.artifacts import atomic_write_text
from core.errors import UsageError

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Variant:
    """One variant of a study: a name, its ``[set]`` keys and a description.

    Attributes
    ----------
    name : str
        Short name (part of the variant study's name).
    keys : dict
        ``--set`` keys applied to every sample.
    what : str
        One line for the table.
    """

    name: str
    keys: dict[str, Any]
    what: str


def chosen(variants: Sequence[Variant], only: list[str] | None, kind: str) -> list[Variant]:
    """The variants named by ``--only`` (all without it), in their order.

    Parameters
    ----------
    variants : sequence of Variant
    only : list of str or None
        The ``--only`` names.
    kind : str
        What a variant is called in the error (``remedy``, ``model``).

    Raises
    ------
    UsageError
        A name that is not a variant's.
    """
    names = [v.name for v in variants]
    unknown = sorted(set(only or []) - set(names))
    if unknown:
        raise UsageError(f"--only {' '.join(unknown)}: unknown {kind}; one of {', '.join(names)}")
    return [v for v in variants if not only or v.name in only]


def study_variant(study: Path, variant: Variant, count: int, folder: Path) -> Path:
    """The study with ``count`` samples, an absolute base and the variant's keys in ``[set]``.

    Parameters
    ----------
    study : Path
        The study compared.
    variant : Variant
    count : int
        Samples (the first ``count`` of the study: same seeds for every variant).
    folder : Path
        Where the variant's file is written.

    Returns
    -------
    Path
        ``<folder>/<study name>-<variant>.toml``.
    """
    data = tomllib.loads(study.read_text(encoding="utf-8"))
    data["base"] = str((study.parent / data["base"]).resolve())
    data["count"] = count
    data["name"] = f"{data['name']}-{variant.name}".replace(".", "p")
    data["set"] = {**data.get("set", {}), **variant.keys}
    path = folder / f"{data['name']}.toml"
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, toml_text(data))
    return path


def toml_text(data: dict[str, Any]) -> str:
    """A study table as TOML: top-level values, then one ``[table]`` per dict (inline below).

    Parameters
    ----------
    data : dict
        Values are numbers, strings, booleans, lists and dicts.
    """
    top = [f"{_key(k)} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    out = ["\n".join(top)]
    for k, v in data.items():
        if isinstance(v, dict):
            body = "\n".join(f"{_key(a)} = {_value(b)}" for a, b in v.items())
            out.append(f"[{_key(k)}]\n{body}")
    return "\n\n".join(out) + "\n"


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else _value(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(a)} = {_value(b)}" for a, b in v.items()) + " }"
    raise UsageError(f"study value {v!r}: not a TOML number, string, list or table")


def run_variant(path: Path, out: Path, workers: int) -> pd.DataFrame:
    """``python -m sweep run PATH``; its results table (failed samples are rows too).

    Parameters
    ----------
    path : Path
        The variant study.
    out : Path
        Output root.
    workers : int
        Local worker processes.
    """
    cmd = [sys.executable, "-m", "sweep", "run", str(path), "--out", str(out)]
    cmd += ["--workers", str(workers)]
    proc = subprocess.run(cmd, cwd=ROOT, env=dict(os.environ), capture_output=True, text=True)
    results = out / tomllib.loads(path.read_text(encoding="utf-8"))["name"] / "results.parquet"
    if proc.returncode not in (0, 1) or not results.exists():  # 1: some sample failed
        last = (proc.stderr.strip().splitlines() or ["?"])[-1]
        raise UsageError(f"python -m sweep run {path} failed: {last}")
    return pd.read_parquet(results)


def nums(table: pd.DataFrame, col: str) -> np.ndarray:
    """A results column as floats (NaN where missing or not a number; all NaN without it).

    Parameters
    ----------
    table : DataFrame
    col : str
    """
    if col not in table.columns:
        return np.full(len(table), np.nan)
    return pd.to_numeric(table[col], errors="coerce").to_numpy(float)


def stat(v: np.ndarray, how: str) -> float:
    """The median or the max of the values that are not NaN (NaN when none is).

    Parameters
    ----------
    v : ndarray
    how : {"median", "max"}
    """
    v = v[~np.isnan(v)]
    if not len(v):
        return math.nan
    return float(np.median(v) if how == "median" else np.max(v))


def pair_counts(ok: pd.DataFrame, prefix: str) -> dict[str, int]:
    """(event, follower) pairs pooled over the ok samples: all, back within 2 s, undefined.

    Parameters
    ----------
    ok : DataFrame
        The ``ok`` rows of a results table.
    prefix : str
        The columns' prefix: ``step`` (operator steps) or ``switch`` (link switches).
    """
    pairs = int(np.nansum(nums(ok, f"{prefix}_pairs")))
    late = int(np.nansum(nums(ok, f"{prefix}_pairs_late")))
    undefined = int(np.nansum(nums(ok, f"{prefix}_pairs_undefined")))
    return {"pairs": pairs, "pairs_back": pairs - late - undefined, "pairs_undefined": undefined}


def guaranteed_counts(ok: pd.DataFrame) -> dict[str, int]:
    """The verification table's guaranteed rows pooled over the ok samples: held, all.

    Parameters
    ----------
    ok : DataFrame
        The ``ok`` rows of a results table.
    """
    failed = ok["guaranteed_failed"].fillna("").astype(str)
    n_failed = int(sum(len([x for x in f.split("; ") if x]) for f in failed))
    n_rows = int(np.nansum(nums(ok, "n_guaranteed")))
    return {"guaranteed_held": n_rows - n_failed, "guaranteed_rows": n_rows}


def g(x: float) -> str:
    """A table cell: three significant digits, ``-`` for NaN.

    Parameters
    ----------
    x : float
    """
    return "-" if isinstance(x, float) and math.isnan(x) else f"{x:.3g}"
