"""``python -m search run FILE [--workers N] [--out DIR] [--seed K] [--budget N]
[--baseline N]``: run or continue a search
(docs/search.md); ``python -m search check FILE``: load and validate it only."""

from __future__ import annotations

import sys

from core.cli_args import count, natural
from core.errors import CliParser, run_cli


def main(argv: list[str]) -> int:
    """Parse the command line and run it.

    Parameters
    ----------
    argv : list of str
        Arguments without the program name.
    """
    ap = CliParser(prog="python -m search", description="Worst-case search of requirements.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    rp = sub.add_parser("run", help="run or continue a search (resumable)")
    rp.add_argument("file", help="the search TOML file")
    rp.add_argument("--out", default=None, help="output root (default out/ or $HITL_OUT)")
    rp.add_argument("--workers", type=count, default=None, help="local worker processes")
    for key, kind in (("seed", natural), ("budget", count), ("baseline", natural)):
        rp.add_argument(f"--{key}", type=kind, default=None, help=f"replace [search] {key}")
    cp = sub.add_parser("check", help="load and validate a search file")
    cp.add_argument("file", help="the search TOML file")
    args = ap.parse_args(argv)
    from search.spec import load_search

    if args.cmd == "check":
        s = load_search(args.file)
        print(f"{args.file}: {len(s.requirements)} requirements, ok")
        return 0
    from core.artifacts import OUT_ROOT
    from search.run import run_search

    path = run_search(
        args.file,
        out_root=args.out or OUT_ROOT,
        workers=args.workers,
        command=" ".join(["python -m search", *argv]),
        overrides={
            k: v for k in ("seed", "budget", "baseline") if (v := getattr(args, k)) is not None
        },
    )
    print(f"results: {path}")
    print(f"report: {path.parent / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
