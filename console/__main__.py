"""``python -m console serve SCENARIO`` (``make console``): the live operator console.

Serves http://127.0.0.1:PORT/ (loopback only unless ``--allow-remote``); docs/console.md.
A request must name a loopback host (127.0.0.1, localhost, [::1]) at PORT, the ``--host``
bound with ``--allow-remote``, or a name given as ``--allow-remote HOST``.
Exit status 2 with one line on stderr on any toolkit error.
"""

from __future__ import annotations

import ipaddress
import math
import sys

from console.engine import CONSOLE_RISE
from console.server import FPS_RANGE, is_loopback
from core.cli_args import port, positive
from core.errors import CliParser, UsageError, run_cli


def _parser() -> CliParser:
    ap = CliParser(prog="python -m console", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("serve", help="serve the console for a scenario")
    s.add_argument("scenario", help="scenario TOML file (make console: scenarios/paper.toml)")
    s.add_argument("--port", type=port, default=8765, help="TCP port, 1-65535 (default 8765)")
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default loopback)")
    s.add_argument(
        "--allow-remote",
        nargs="?",
        const="",
        action="append",
        metavar="HOST",
        help="accept connections from non-loopback addresses (anyone who reaches the port "
        "drives) and requests naming HOST (repeatable; put it after SCENARIO)",
    )
    s.add_argument("--fps", type=float, default=30.0, help="frames per second to pages (20-60)")
    s.add_argument("--bias-max", type=positive, default=5.0, help="largest bias component")
    s.add_argument("--out", default=None, help="output root for gains and records (default out/)")
    s.add_argument(
        "--rise",
        type=positive,
        default=None,
        help="seconds over which each change of u0 ramps in (default: the scenarios' "
        "default rise, docs/console.md)",
    )
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
    allow_remote = args.allow_remote is not None
    check_host(args.host, allow_remote)  # before the (slow) build
    if not FPS_RANGE[0] <= args.fps <= FPS_RANGE[1]:
        raise UsageError(f"--fps: {args.fps:g} (expected {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g})")
    rise = CONSOLE_RISE if args.rise is None else args.rise
    if not (math.isfinite(rise) and rise > 0):
        raise UsageError(f"--rise: {rise:g} (expected a rise time in seconds > 0)")
    con = open_console(
        args.scenario,
        out_root=args.out,
        bias_max=args.bias_max,
        fps=args.fps,
        allow_remote=allow_remote,
        hosts=_hosts(args.host, args.allow_remote or []),
        rise=rise,
    )
    serve(con, host=args.host, port=args.port)
    return 0


def _hosts(bound: str, named: list[str]) -> list[str]:
    """Host names accepted besides the loopback ones: ``--allow-remote HOST`` values and,
    with ``--allow-remote``, the ``--host`` bound unless it is a wildcard (0.0.0.0, ::)."""
    hosts = [h for h in named if h]
    if named and not is_loopback(bound) and not _wildcard(bound):
        hosts.append(bound)
    return hosts


def _wildcard(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False


if __name__ == "__main__":
    sys.exit(run_cli(main))
