"""``python -m sweep samples STUDY [--write-scenarios DIR]``: list a study's samples.

One line per sample: id, seed, ``ok`` or ``refused``, the drawn values as JSON (and the
loader's reason for a refused sample). ``--write-scenarios DIR`` also writes each valid
sample's scenario file, so ``make sim SCENARIO=DIR/<name>.toml`` runs it.
"""

from __future__ import annotations

import json
import sys

from core.errors import CliParser, run_cli
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
    args = ap.parse_args(argv)
    study = load_study(args.study)
    refused = 0
    for s in samples(study):
        status = "ok" if s.scenario is not None else "refused"
        line = f"{s.id}\t{s.seed}\t{status}\t{json.dumps(s.params)}"
        if s.reason:
            refused += 1
            line += f"\t{s.reason}"
        elif args.write_scenarios:
            line += f"\t{write_scenario(s, args.write_scenarios)}"
        print(line)
    print(f"{study.count} samples, {refused} refused by the loader", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
