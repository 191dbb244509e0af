"""``python -m verify demo|check|report [SCENARIO]`` (``make demo|verify|report``).

- ``check``: the Theorem 1/2 checks and the bound-vs-actual table; exit 0 when every
  check the theory guarantees holds, 1 otherwise; ``--strict`` (or ``STRICT=1``)
  also fails on the paper's own claims that do not hold.
- ``report``: ``check`` plus the figures, ``bounds.csv`` and ``report.md``
  (simulating the eq. (42) ablation run for Fig. 13 if needed).
- ``demo``: the whole pipeline from scratch — synthesis, simulation, ablation,
  verification, report — ending with where the report is and the table.
The performance benchmark sits above this stage: ``python -m benchmarks.bench`` (``make bench``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from core.artifacts import OUT_ROOT
from core.errors import CliParser, run_cli, strict_mode
from core.overrides import add_scenario_knobs, scenario_knobs
from verify.bounds import VerifyConfig, VerifyError

if TYPE_CHECKING:
    from verify.pipeline import Run
    from verify.report import Verification

DEFAULT_SCENARIO = "scenarios/paper.toml"


def _parser() -> argparse.ArgumentParser:
    ap = CliParser(prog="python -m verify", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name, helptext in (
        ("check", "verify the theorems and print the bound-vs-actual table"),
        ("report", "check, then write figures, bounds.csv and report.md"),
        ("demo", "synth, sim, ablation, verify and report from scratch"),
    ):
        p = sub.add_parser(name, help=helptext)
        p.add_argument("scenario", nargs="?", default=DEFAULT_SCENARIO)
        p.add_argument(
            "--strict",
            action="store_true",
            help="also fail on the paper's own claims (or STRICT=1)",
        )
        p.add_argument("--out", default=None, help="output root (default out/ or $HITL_OUT)")
        p.add_argument(
            "--tail",
            type=float,
            default=0.5,
            help="asymptotic window: last fraction of the horizon (default 0.5)",
        )
        p.add_argument(
            "--delta", type=float, default=0.5, help="Lemma 1's delta, 0 < delta < 1 (default 0.5)"
        )
        p.add_argument(
            "--no-lyapunov",
            action="store_true",
            help="skip the exact dV/dt checks (table from the trajectory only)",
        )
        p.add_argument("--no-gif", action="store_true", help="skip the animation")
        add_scenario_knobs(p)
    return ap


def _strict(flag: bool) -> bool:
    """``--strict`` or ``STRICT=1`` (one reading for every command: :func:`strict_mode`)."""
    return strict_mode(flag)


def _stage_line(label: str, run) -> None:
    """One line per simulated run: where its gains and trajectory are, and how it went.

    Parameters
    ----------
    label : str
        Name of the run in the line.
    run : verify.pipeline.Run
        The run (its ``meta`` is the simulation's meta.json).
    """
    m = run.meta or {}
    state = "complete" if m.get("complete", True) else f"INCOMPLETE at t = {m.get('t_reached')}"
    print(
        f"[{label}] gains {m.get('gains_path')} "
        f"({'reused' if m.get('gains_reused') else 'synthesised'}); "
        f"trajectory {run.folder / 'trajectory.csv'} "
        f"({'reused' if not run.simulated else m.get('method')}, {m.get('steps')} steps, "
        f"library {'cached' if m.get('cache_hit') else 'built'}, {state})"
    )


def main(argv: list[str]) -> int:
    """Entry point; returns the exit status.

    Parameters
    ----------
    argv : list of str
        Command-line arguments without the program name.
    """
    args = _parser().parse_args(argv)
    from verify import pipeline as P

    if not Path(args.scenario).is_file():
        raise VerifyError(f"scenario {args.scenario!r} does not exist: give a TOML file path")
    strict = _strict(args.strict)
    cfg = VerifyConfig(lemma1_delta=args.delta, tail_fraction=args.tail)
    root = Path(args.out) if args.out else OUT_ROOT
    run, ablation = _obtain_runs(args, root)
    v = P.verify_run(
        run, ablation=ablation, config=cfg, out_root=root, lyapunov=not args.no_lyapunov
    )
    if args.cmd in ("report", "demo"):
        rpath, bpath = _write_report(args, v, run, ablation, strict)
    else:
        from core.artifacts import atomic_write_text

        bpath = atomic_write_text(run.folder / "bounds.csv", v.table.to_csv(index=False))
        rpath = None
    return _print_outcome(v, bpath, rpath, strict)


def _obtain_runs(args: argparse.Namespace, root: Path) -> tuple[Run, Run | None]:
    """The run and the eq. (42) ablation run (None for ``check`` unless fresh on disk).

    Parameters
    ----------
    args : Namespace
        Parsed command line.
    root : Path
        Output root.

    Returns
    -------
    (verify.pipeline.Run, verify.pipeline.Run or None)
    """
    from generated import api
    from verify import pipeline as P

    force = args.cmd == "demo"
    overrides, variant = scenario_knobs(args)
    abl_over = {**(overrides or {}), **P.ABLATION}
    abl_variant = None if variant is None else f"{variant}-ablation"
    if args.cmd == "demo":  # what is being run, before the stages
        from core.summary import summarize

        print(summarize(api.load(args.scenario, overrides, variant)), end="\n\n")
    run = P.obtain_run(args.scenario, overrides, variant=variant, out_root=root, force=force)
    _stage_line("run", run)
    ablation = None
    if args.cmd in ("report", "demo"):
        ablation = P.obtain_run(
            args.scenario, abl_over, variant=abl_variant, out_root=root, force=force
        )
        _stage_line("ablation (42)", ablation)
    else:  # check: use the ablation run only if it is already there and fresh
        asc = api.load(args.scenario, abl_over, abl_variant)
        if P._fresh(root / asc.name, asc) is not None:
            ablation = P.obtain_run(args.scenario, abl_over, variant=abl_variant, out_root=root)
    return run, ablation


def _write_report(
    args: argparse.Namespace, v: Verification, run: Run, ablation: Run | None, strict: bool
) -> tuple[Path, Path]:
    """Figures, ``bounds.csv`` and ``report.md`` into the run's folder.

    Parameters
    ----------
    args : Namespace
        Parsed command line (``--no-gif``).
    v : Verification
        The verification results; the figures and their notes are added to it.
    run : Run
        The run.
    ablation : Run or None
        The eq. (42) ablation run.
    strict : bool
        Whether the paper's own claims count as failures.

    Returns
    -------
    (report path, bounds path)
    """
    from verify.figures import all_figures, lyapunov_figures
    from verify.report import write_report

    files, notes = all_figures(
        run.frame,
        run.scenario.leader.C0,
        run.folder / "figures",
        None if ablation is None else ablation.frame,
        gif=not args.no_gif,
    )
    files += lyapunov_figures(v.theorem1, v.theorem2, run.folder / "figures")
    v.figures, v.notes = files, v.notes + notes
    return write_report(v, run.folder, strict=strict)


def _print_outcome(v: Verification, bpath: Path, rpath: Path | None, strict: bool) -> int:
    """Print the checks, the table and the verdict; return the exit status (0 pass, 1 fail).

    Parameters
    ----------
    v : Verification
        The verification results.
    bpath : Path
        Where ``bounds.csv`` is.
    rpath : Path or None
        Where ``report.md`` is (None for ``check``).
    strict : bool
        Whether the paper's own claims count as failures.
    """
    from verify.report import console_table

    for chk in v.theorem1 + v.theorem2:
        print(chk.where())
    print(v.ablation_summary)
    print()
    print(console_table(v.table))
    print()
    bad = v.failed(strict)
    from verify.rows import failed_mask

    paper_bad = v.table[(v.table["kind"] == "paper") & failed_mask(v.table)]
    print(f"bounds: {bpath}")
    if rpath is not None:
        print(f"report: {rpath}")
    if len(paper_bad):
        print(
            f"{len(paper_bad)} of the paper's own claims do not hold on these numbers"
            + ("" if strict else " (reported; --strict or STRICT=1 makes them fail)")
        )
    if len(bad):
        print(
            f"FAIL: {len(bad)} check(s) failed" + (" (strict)" if strict else ""), file=sys.stderr
        )
        for line in v.headline(strict)[1:]:
            print(line, file=sys.stderr)
        for r in bad.itertuples(index=False):
            print(
                f"  {r.claim} [follower {r.agent}] bound {r.bound:.4g} observed "
                f"{r.observed:.4g}: {r.note}",
                file=sys.stderr,
            )
        return 1
    head = v.headline(strict)
    print(head[0] + (" (strict)" if strict else ""))
    for line in head[1:]:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
