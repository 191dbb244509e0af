"""Lone samples: a scenario's integration plus its checks, timed in one process.

::

    python -m benchmarks.lone --out DIR WARM FILE [FILE ...]

A lone sample is :func:`generated.api.run` (its ``integration`` + ``outputs`` seconds)
followed by :func:`verify.pipeline.verify_run` (the study's verification), timed by
:func:`sample_times`. The command is the same-load baseline of :mod:`benchmarks.study`,
which starts two of them at once on disjoint scenario files (both cores busy): each runs
``WARM`` untimed (it loads the shared library and fills the per-process caches), prints
``ready``, waits for one line on stdin (so the two start timing together), runs each
``FILE`` and prints one JSON line ``{"integration_s": [...], "checks_s": [...]}``, one
entry per file in the given order. Outputs go under ``DIR``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from core.errors import CliParser, run_cli


def sample_times(files: list[Path], out_root: Path) -> list[tuple[float, float]]:
    """Integration (+ outputs) and checks seconds of each scenario file, run in turn.

    Parameters
    ----------
    files : list of Path
        Scenario files (every one must load and simulate).
    out_root : Path
        Where the runs and their checks write.

    Returns
    -------
    list of (float, float)
        Per file: ``integration + outputs`` seconds (the run's own ``wall_seconds``) and
        the seconds of :func:`verify.pipeline.verify_run`.
    """
    from generated import api
    from verify import pipeline as P

    times = []
    for f in files:
        res = api.run(f, out_root=out_root, progress=False)
        run = P.Run(api.load(f), res.frame, res.trajectory.x, res.meta, res.csv_path.parent)
        t0 = time.perf_counter()
        P.verify_run(run, out_root=out_root)
        ws = res.meta["wall_seconds"]
        times.append((ws["integration"] + ws["outputs"], time.perf_counter() - t0))
    return times


def main(argv: list[str]) -> int:
    """Warm up on one file, wait for a line on stdin, time the others (JSON on stdout).

    Parameters
    ----------
    argv : list of str
        Arguments without the program name.
    """
    ap = CliParser(prog="python -m benchmarks.lone", description=__doc__)
    ap.add_argument("--out", required=True, help="output root of the runs")
    ap.add_argument("warm", help="scenario run first, untimed")
    ap.add_argument("files", nargs="+", help="scenarios timed, in this order")
    a = ap.parse_args(argv)
    out = Path(a.out)
    sample_times([Path(a.warm)], out)
    print("ready", flush=True)
    sys.stdin.readline()
    times = sample_times([Path(f) for f in a.files], out)
    integ, checks = zip(*times, strict=True)
    print(json.dumps({"integration_s": list(integ), "checks_s": list(checks)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
