"""``python -m symbolic summary SCENARIO``: load, validate, derive the models, print a summary.

Bad input is one line on stderr and exit status 2 (:func:`core.errors.run_cli`).
"""

from __future__ import annotations

import sys

from core.errors import CliParser, run_cli


def main(argv: list[str]) -> int:
    """Entry point; returns the exit status.

    Parameters
    ----------
    argv : list of str
        Command-line arguments without the program name.
    """
    parser = CliParser(prog="python -m symbolic", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("summary", help="validate a scenario file and print its summary")
    p.add_argument("scenario", help="path to a scenario TOML file")
    args = parser.parse_args(argv)

    from core.scenario import load_scenario
    from core.summary import summarize

    sys.stdout.write(summarize(load_scenario(args.scenario)))
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
