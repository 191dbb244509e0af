"""``python -m sweep samples STUDY [--write-scenarios DIR]``: list a study's samples;
``python -m sweep run STUDY [--ids ...]``: run them (docs/studies.md, "Running a study");
exit status 1 and one line on stderr when some sample's status is ``failed``.
``samples STUDY --ids 17 --write-scenarios DIR`` writes one sample's scenario file (to rerun it).
``python -m sweep cost STUDY [--ids ...]``: a study sample's cost against a lone run of the
same sample, sample by sample in one process (:mod:`sweep.cost`).

One line per sample: id, seed, ``ok`` or ``refused``, the drawn values as JSON (and the
loader's reason for a refused sample). ``--write-scenarios DIR`` also writes each valid
sample's scenario file, so ``make sim SCENARIO=DIR/<name>.toml`` runs it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from core.errors import CliParser, UsageError, run_cli
from sweep.run import MAX_CHUNK
from sweep.sampler import samples, write_scenario
from sweep.study import load_study


def main(argv: list[str]) -> int:
    """Parse the command line and run it.

    Parameters
    ----------
    argv : list of str
        Arguments without the program name.
    """
    ap = CliParser(prog="python -m sweep", description="Studies: sampled scenario families.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    sp = sub.add_parser("samples", help="list a study's samples")
    sp.add_argument("study", help="the study TOML file")
    sp.add_argument("--write-scenarios", metavar="DIR", help="write each valid sample's TOML")
    sp.add_argument("--ids", type=int, nargs="+", help="only these sample ids (default all)")
    rp = sub.add_parser("run", help="simulate and verify a study's samples (resumable)")
    rp.add_argument("study", help="the study TOML file")
    rp.add_argument("--ids", type=int, nargs="+", help="only these sample ids (default all)")
    rp.add_argument("--out", default=None, help="output root (default out/ or $HITL_OUT)")
    rp.add_argument("--batch", type=int, default=10, help="rows per atomic commit (default 10)")
    rp.add_argument(
        "--workers", type=int, default=None, help="local worker processes (default: cores)"
    )
    rp.add_argument(
        "--chunk",
        type=int,
        default=None,
        help=f"samples per Dask task (default: 4+ tasks per worker, at most {MAX_CHUNK})",
    )
    rp.add_argument(
        "--keep-runs", action="store_true", help="also write each sample's scenario and run files"
    )
    rp.add_argument(
        "--restart",
        action="store_true",
        help="discard the study folder's results, report and runs first (a changed study)",
    )
    cp = sub.add_parser("cost", help="a study sample's cost against a lone run of it")
    cp.add_argument("study", help="the study TOML file")
    cp.add_argument(
        "--ids", type=int, nargs="+", help="sample ids, the first one untimed (default 0..40)"
    )
    args = ap.parse_args(argv)
    if args.cmd == "run":
        return _run(args, argv)
    if args.cmd == "cost":
        return _cost(args)
    study = load_study(args.study)
    _check_ids(args.ids, study.count)
    refused = 0
    for s in samples(study, args.ids):
        status = "ok" if s.scenario is not None else "refused"
        line = f"{s.id}\t{s.seed}\t{status}\t{json.dumps(s.params)}"
        if s.reason:
            refused += 1
            line += f"\t{s.reason}"
        elif args.write_scenarios:
            line += f"\t{write_scenario(s, args.write_scenarios)}"
        print(line)
    n = study.count if args.ids is None else len(args.ids)
    print(f"{n} samples, {refused} refused by the loader", file=sys.stderr)
    return 0


def _check_ids(ids: list[int] | None, count: int) -> None:
    """``--ids`` must name samples of the study (0 .. count - 1)."""
    for k in ids or ():
        if not 0 <= k < count:
            raise UsageError(f"--ids: sample id {k} outside 0..{count - 1}: give ids of the study")


def _cost(args: argparse.Namespace) -> int:
    """``cost``: time lone runs and study tasks of the same samples; print the table."""
    from sweep.cost import run

    study = load_study(args.study)
    ids = args.ids if args.ids is not None else list(range(min(41, study.count)))
    _check_ids(ids, study.count)
    print(run(args.study, ids))
    return 0


def _run(args: argparse.Namespace, argv: list[str]) -> int:
    """``run``: execute the study, then print where the results and report are."""
    from core.artifacts import OUT_ROOT
    from sweep.run import run_study

    if args.ids is not None and any(k < 0 for k in args.ids):
        raise UsageError("--ids: sample ids are integers >= 0")
    command = " ".join(["python -m sweep", *argv])
    if args.workers is not None and args.workers < 1:
        raise UsageError("--workers: give a number of worker processes >= 1")
    if args.chunk is not None and args.chunk < 1:
        raise UsageError("--chunk: give a number of samples per task >= 1")
    if args.batch < 1:
        raise UsageError("--batch: give a number of rows per commit >= 1")
    if args.out is not None and not args.out.strip():
        raise UsageError("--out: an empty path: give a folder (default out/ or $HITL_OUT)")
    path = run_study(
        args.study,
        out_root=args.out or OUT_ROOT,
        batch=args.batch,
        ids=args.ids,
        command=command,
        workers=args.workers,
        keep=args.keep_runs,
        chunk=args.chunk,
        restart=args.restart,
    )
    print(f"results: {path}")
    print(f"report: {path.parent / 'report.md'}")
    return _faults_status(path, args.study)


def _faults_status(results: Path, study: str) -> int:
    """Exit status 1 with one line on stderr when some sample failed, else 0."""
    from sweep.results import read_results
    from sweep.resume import faults_line

    line = faults_line(read_results(results), study)
    if line is None:
        return 0
    print(line, file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(run_cli(main))
