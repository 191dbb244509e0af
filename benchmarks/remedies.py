"""Remedies for operator steps compared on one step study (docs/verification.md, 'Operator steps').

::

    python -m benchmarks.remedies                    # studies/steps.toml, 24 samples each
    python -m benchmarks.remedies --samples 8 --only raw smoothstep-1

Each remedy is the study with a few ``[set]`` keys on top (:data:`REMEDIES`): the raw
steps (``leader.u0_rise = 0``), the command shaped before it reaches the leader
(``smoothstep`` over T, the critically damped ``prefilter`` with time constant τ, a rate
limit ``ramp``; core/shaping.py), the filtered derivatives (``options.derivatives =
"filtered"``) and a boundary layer of the observer's robust term that does not collapse
to 0.005 (``observer.phi_min``). Every variant runs the same samples (same seeds, same
drawn steps) through ``python -m sweep run`` (``sweep`` is the layer above, so only its
command line is used) and is summarised from its ``results.parquet``: samples ``ok``, tail
error, peak |u_i| after 1 s, integrator steps, the pinned followers' return to their
slots (:mod:`verify.operator_steps`) and the guaranteed rows of the verification table
that hold. Results: ``<out>/remedies.md`` (date, commit, machine, command) and
``<out>/remedies.csv``; the variants' study files and results stay under ``<out>``, and
a rerun resumes them.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.artifacts import OUT_ROOT, atomic_write_text
from core.cli_args import count
from core.errors import CliParser, UsageError, run_cli
from core.provenance import provenance_line
from core.shaping import DEFAULT_RISE, DEFAULT_SHAPE

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_STUDY = ROOT / "studies" / "steps.toml"


@dataclass(frozen=True)
class Remedy:
    """One way of taking operator steps: a name, its ``[set]`` keys and a description.

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


def _shaped(shape: str, rise: float, what: str) -> Remedy:
    name = f"{shape}-{rise:g}"
    return Remedy(name, {"leader.u0_rise": rise, "leader.u0_shape": shape}, what)


#: the remedies compared, in the table's order
REMEDIES: tuple[Remedy, ...] = (
    Remedy("raw", {"leader.u0_rise": 0.0}, "raw steps (`u0_rise = 0`)"),
    *(_shaped("smoothstep", T, f"smoothstep over {T:g} s") for T in (0.25, 0.5, 1.0, 1.5, 2.0)),
    *(_shaped("prefilter", T, f"prefilter 1/(1 + {T:g}s)²") for T in (0.25, 0.5)),
    _shaped("ramp", 1.0, "rate limit: ramp over 1 s"),
    Remedy(
        "filtered",
        {"leader.u0_rise": 0.0, "options.derivatives": "filtered"},
        "raw steps, filtered derivatives (200 rad/s)",
    ),
    *(
        Remedy(
            f"phimin-{f:g}",
            {"leader.u0_rise": 0.0, "observer.phi_min": f},
            f"raw steps, boundary layer floor φ_min = {f:g}",
        )
        for f in (0.05, 0.5)
    ),
)


def study_variant(study: Path, remedy: Remedy, count: int, folder: Path) -> Path:
    """The study with ``count`` samples, an absolute base and the remedy's keys in ``[set]``.

    Parameters
    ----------
    study : Path
        The step study.
    remedy : Remedy
    count : int
        Samples (the first ``count`` of the study: same seeds for every remedy).
    folder : Path
        Where the variant's file is written.

    Returns
    -------
    Path
        ``<folder>/<study name>-<remedy>.toml``.
    """
    data = tomllib.loads(study.read_text(encoding="utf-8"))
    data["base"] = str((study.parent / data["base"]).resolve())
    data["count"] = count
    data["name"] = f"{data['name']}-{remedy.name}".replace(".", "p")
    data["set"] = {**data.get("set", {}), **remedy.keys}
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


def _nums(table: pd.DataFrame, col: str) -> np.ndarray:
    if col not in table.columns:
        return np.full(len(table), np.nan)
    return pd.to_numeric(table[col], errors="coerce").to_numpy(float)


def _stat(v: np.ndarray, how: str) -> float:
    v = v[~np.isnan(v)]
    if not len(v):
        return math.nan
    return float(np.median(v) if how == "median" else np.max(v))


def summarize(remedy: Remedy, table: pd.DataFrame) -> dict[str, Any]:
    """One line of the comparison from a variant's results.

    Parameters
    ----------
    remedy : Remedy
    table : DataFrame
        Its ``results.parquet``.

    Returns
    -------
    dict
        Counts and statistics over the ``ok`` samples (guaranteed rows pooled).
    """
    ok = table[table["status"] == "ok"]
    failed = ok["guaranteed_failed"].fillna("").astype(str)
    n_failed = int(sum(len([x for x in f.split("; ") if x]) for f in failed))
    n_rows = int(np.nansum(_nums(ok, "n_guaranteed")))
    pairs = int(np.nansum(_nums(ok, "step_pairs")))
    late = int(np.nansum(_nums(ok, "step_pairs_late")))
    undefined = int(np.nansum(_nums(ok, "step_pairs_undefined")))
    return {
        "remedy": remedy.name,
        "what": remedy.what,
        "samples": len(table),
        "ok": len(ok),
        "tail_et_median": _stat(_nums(ok, "tail_max_et"), "median"),
        "tail_et_max": _stat(_nums(ok, "tail_max_et"), "max"),
        "peak_u_late_median": _stat(_nums(ok, "peak_u_late"), "median"),
        "peak_u_late_max": _stat(_nums(ok, "peak_u_late"), "max"),
        "step_peak_u_max": _stat(_nums(ok, "step_peak_u"), "max"),
        "steps_median": _stat(_nums(ok, "steps"), "median"),
        "deviation_max": _stat(_nums(ok, "step_deviation_max"), "max"),
        "recovery_max_s": _stat(_nums(ok, "step_recovery_s"), "max"),
        "pairs": pairs,
        "pairs_back": pairs - late - undefined,
        "pairs_undefined": undefined,
        "guaranteed_held": n_rows - n_failed,
        "guaranteed_rows": n_rows,
        "samples_all_held": int(ok["guaranteed_held"].astype(bool).sum()),
    }


def _g(x: float) -> str:
    return "-" if isinstance(x, float) and math.isnan(x) else f"{x:.3g}"


def markdown(rows: list[dict[str, Any]], study: Path, count: int, command: str) -> str:
    """The report: provenance, what was run, and the trade-off table.

    Parameters
    ----------
    rows : list of dict
        From :func:`summarize`, in order.
    study : Path
    count : int
        Samples per remedy.
    command : str
        The command that made it.
    """
    head = [
        "# Remedies for operator steps",
        "",
        f"{provenance_line()}; `{command}`.",
        "",
        f"The first {count} samples of `{study.name}` (same seeds and drawn steps for every "
        f"remedy), each run by `python -m sweep run` with the remedy's keys in `[set]`. "
        f"The loader's default for a stepped u0 is `{DEFAULT_SHAPE}` over {DEFAULT_RISE:g} s. "
        "Tail error: max over followers of sup ‖e_ti‖ on the tail window; peak |u_i| after "
        "1 s: max over followers, over the whole run; within 2 s of a step: the same, only "
        "in the 2 s after each step's onset; back in 2 s: (step, pinned follower) pairs within 0.05 "
        "of the slot within 2 s of the step, of all pairs (undefined: still out when the "
        "next step or the horizon came within 2 s); guaranteed rows: the verification "
        "table's `guaranteed` rows that hold, pooled over the ok samples.",
        "",
        "| remedy | ok | tail ‖e_t‖ median (max) | peak \\|u_i\\| after 1 s median (max) "
        "| peak \\|u_i\\| within 2 s of a step (max) "
        "| steps (median) | max distance from slot after a step | slowest return [s] "
        "| back in 2 s (undefined) | guaranteed rows held |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    body = [
        f"| {r['what']} | {r['ok']}/{r['samples']} | {_g(r['tail_et_median'])} "
        f"({_g(r['tail_et_max'])}) | {_g(r['peak_u_late_median'])} ({_g(r['peak_u_late_max'])}) "
        f"| {_g(r['step_peak_u_max'])} | {_g(r['steps_median'])} | {_g(r['deviation_max'])} | {_g(r['recovery_max_s'])} "
        f"| {r['pairs_back']}/{r['pairs']} ({r['pairs_undefined']}) "
        f"| {r['guaranteed_held']}/{r['guaranteed_rows']} |"
        for r in rows
    ]
    return "\n".join(head + body) + "\n"


def _parser() -> argparse.ArgumentParser:
    p = CliParser(prog="python -m benchmarks.remedies", description=__doc__)
    p.add_argument("--study", type=Path, default=DEFAULT_STUDY, help="the step study")
    p.add_argument("--samples", type=count, default=24, help="samples per remedy (default 24)")
    p.add_argument("--workers", type=count, default=1, help="sweep workers (default 1)")
    p.add_argument("--only", nargs="+", metavar="NAME", help="only these remedies")
    p.add_argument("--out", type=Path, default=OUT_ROOT / "remedies", help="output folder")
    return p


def main(argv: list[str]) -> int:
    """Run every remedy's variant study and write ``remedies.md`` and ``remedies.csv``.

    Parameters
    ----------
    argv : list of str
        Command-line arguments (without the program name).
    """
    a = _parser().parse_args(argv)
    names = [r.name for r in REMEDIES]
    unknown = sorted(set(a.only or []) - set(names))
    if unknown:
        raise UsageError(f"--only {' '.join(unknown)}: unknown remedy; one of {', '.join(names)}")
    chosen = [r for r in REMEDIES if not a.only or r.name in a.only]
    rows = []
    for remedy in chosen:
        path = study_variant(a.study, remedy, a.samples, a.out / "studies")
        rows.append(summarize(remedy, run_variant(path, a.out, a.workers)))
        print(f"{remedy.name}: {rows[-1]['ok']}/{rows[-1]['samples']} ok", flush=True)
    command = "python -m benchmarks.remedies " + " ".join(argv)
    atomic_write_text(a.out / "remedies.csv", pd.DataFrame(rows).to_csv(index=False))
    atomic_write_text(a.out / "remedies.md", markdown(rows, a.study, a.samples, command.strip()))
    print(f"report: {a.out / 'remedies.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
