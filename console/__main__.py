"""``python -m console serve SCENARIO`` (``make console``): the live operator console.

Serves http://127.0.0.1:PORT/ (loopback only unless ``--allow-remote``); docs/console.md.
Exit status 2 with one line on stderr on any toolkit error.
"""

from __future__ import annotations

import sys

from console.server import FPS_RANGE
from core.errors import CliParser, UsageError, run_cli


def _parser() -> CliParser:
    ap = CliParser(prog="python -m console", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("serve", help="serve the console for a scenario")
    s.add_argument("scenario", help="scenario TOML file (make console: scenarios/paper.toml)")
    s.add_argument("--port", type=int, default=8765)
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default loopback)")
    s.add_argument(
        "--allow-remote",
        action="store_true",
        help="accept connections from non-loopback addresses (anyone who reaches the port drives)",
    )
    s.add_argument("--fps", type=float, default=30.0, help="frames per second to pages (20-60)")
    s.add_argument("--bias-max", type=float, default=5.0, help="largest bias component")
    s.add_argument("--out", default=None, help="output root for gains and records (default out/)")
    return ap


def main(argv: list[str]) -> int:
    """Entry point; see the module docstring.

    Parameters
    ----------
    argv : list of str
        The command line after ``python -m console``.
    """
    from console.app import check_host, open_console, serve

    args = _parser().parse_args(argv)
    check_host(args.host, args.allow_remote)  # before the (slow) build
    if not FPS_RANGE[0] <= args.fps <= FPS_RANGE[1]:
        raise UsageError(f"--fps: {args.fps:g} (expected {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g})")
    con = open_console(
        args.scenario,
        out_root=args.out,
        bias_max=args.bias_max,
        fps=args.fps,
        allow_remote=args.allow_remote,
    )
    serve(con, host=args.host, port=args.port)
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
