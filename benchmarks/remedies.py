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
import sys
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.variants import (
    Variant,
    chosen,
    g,
    guaranteed_counts,
    nums,
    pair_counts,
    run_variant,
    stat,
    study_variant,
)
from core.artifacts import OUT_ROOT, atomic_write_text
from core.cli_args import count
from core.errors import CliParser, run_cli
from core.provenance import provenance_line
from core.shaping import DEFAULT_RISE, DEFAULT_SHAPE

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_STUDY = ROOT / "studies" / "steps.toml"


def _shaped(shape: str, rise: float, what: str) -> Variant:
    name = f"{shape}-{rise:g}"
    return Variant(name, {"leader.u0_rise": rise, "leader.u0_shape": shape}, what)


#: the remedies compared, in the table's order
REMEDIES: tuple[Variant, ...] = (
    Variant("raw", {"leader.u0_rise": 0.0}, "raw steps (`u0_rise = 0`)"),
    *(_shaped("smoothstep", T, f"smoothstep over {T:g} s") for T in (0.25, 0.5, 1.0, 1.5, 2.0)),
    *(_shaped("prefilter", T, f"prefilter 1/(1 + {T:g}s)²") for T in (0.25, 0.5)),
    _shaped("ramp", 1.0, "rate limit: ramp over 1 s"),
    Variant(
        "filtered",
        {"leader.u0_rise": 0.0, "options.derivatives": "filtered"},
        "raw steps, filtered derivatives (200 rad/s)",
    ),
    *(
        Variant(
            f"phimin-{f:g}",
            {"leader.u0_rise": 0.0, "observer.phi_min": f},
            f"raw steps, boundary layer floor φ_min = {f:g}",
        )
        for f in (0.05, 0.5)
    ),
)


def summarize(remedy: Variant, table: pd.DataFrame) -> dict[str, Any]:
    """One line of the comparison from a variant's results.

    Parameters
    ----------
    remedy : Variant
    table : DataFrame
        Its ``results.parquet``.

    Returns
    -------
    dict
        Counts and statistics over the ``ok`` samples (guaranteed rows pooled).
    """
    ok = table[table["status"] == "ok"]
    return {
        "remedy": remedy.name,
        "what": remedy.what,
        "samples": len(table),
        "ok": len(ok),
        "tail_et_median": stat(nums(ok, "tail_max_et"), "median"),
        "tail_et_max": stat(nums(ok, "tail_max_et"), "max"),
        "peak_u_late_median": stat(nums(ok, "peak_u_late"), "median"),
        "peak_u_late_max": stat(nums(ok, "peak_u_late"), "max"),
        "step_peak_u_max": stat(nums(ok, "step_peak_u"), "max"),
        "steps_median": stat(nums(ok, "steps"), "median"),
        "deviation_max": stat(nums(ok, "step_deviation_max"), "max"),
        "recovery_max_s": stat(nums(ok, "step_recovery_s"), "max"),
        **pair_counts(ok, "step"),
        **guaranteed_counts(ok),
        "samples_all_held": int(ok["guaranteed_held"].astype(bool).sum()),
    }


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
        f"| {r['what']} | {r['ok']}/{r['samples']} | {g(r['tail_et_median'])} "
        f"({g(r['tail_et_max'])}) | {g(r['peak_u_late_median'])} ({g(r['peak_u_late_max'])}) "
        f"| {g(r['step_peak_u_max'])} | {g(r['steps_median'])} | {g(r['deviation_max'])} | {g(r['recovery_max_s'])} "
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
    rows = []
    for remedy in chosen(REMEDIES, a.only, "remedy"):
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
