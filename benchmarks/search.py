"""``make bench`` (search part): does the worst-case search beat random search, and what
does an evaluation cost (docs/search.md)?

::

    python -m benchmarks.search                         # studies/search-faults.toml, seeds 1-5
    python -m benchmarks.search --seeds 1 2 --budget 40 --baseline 80

Measured, all on the same search file, in this order:

time
    The search arm alone (``--baseline 0``) of the first seed, from a fresh output folder:
    the wall time of the whole command (cluster start-up, the minimisation and the report
    included), the evaluations it ran, and the compiled libraries the search arm used.
seeds
    One run per seed with the file's budget and baseline (or the ones given), each from a
    fresh output folder: the least robustness of the search arm and of the uniform random
    baseline, measured in the same run on the same space.

``search`` is a layer above ``benchmarks``, so searches run through their command line
only. Results: ``<out>/search.json`` and ``<out>/search.md`` with the date, commit and
machine; nothing is asserted.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd

from benchmarks.catalogue import BenchError
from core.artifacts import OUT_ROOT, atomic_write_text
from core.cli_args import count, natural
from core.errors import CliParser, run_cli
from core.provenance import provenance_line

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SEARCH = ROOT / "studies" / "search-faults.toml"


@dataclass
class SeedRun:
    """One seed's run: each arm's least robustness and evaluations."""

    seed: int
    search_least: float
    baseline_least: float
    search_evals: int
    baseline_evals: int
    search_violations: int
    baseline_violations: int
    wall_s: float

    @property
    def search_wins(self) -> bool:
        """The search found a run less robust than every baseline run."""
        return self.search_least < self.baseline_least


def _search(args: list[str]) -> float:
    """Run ``python -m search run ARGS`` to completion; its wall time (raises on failure)."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "search", "run", *args],
        cwd=ROOT,
        env=os.environ.copy(),
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["?"])[-1]
        raise BenchError(f"python -m search run {' '.join(args)} failed: {last}")
    return time.perf_counter() - t0


def _fresh_run(
    file: Path, seed: int, budget: int, baseline: int, out: Path, workers: int
) -> tuple[float, pd.DataFrame]:
    """``python -m search run`` with these ``[search]`` values in an emptied ``out``: its
    wall time and its results.parquet."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    args = {"--seed": seed, "--budget": budget, "--baseline": baseline, "--workers": workers}
    wall = _search(
        [str(file), *(x for kv in args.items() for x in map(str, kv)), "--out", str(out)]
    )
    (found,) = out.glob("*/results.parquet")
    return wall, pd.read_parquet(found)


def seed_run(file: Path, seed: int, budget: int, baseline: int, out: Path, workers: int) -> SeedRun:
    """One seed's search and baseline in one run, from a fresh folder.

    Parameters
    ----------
    file : Path
        The search file.
    seed, budget, baseline : int
        Replace the file's ``[search]`` values.
    out : Path
        The run's output root (emptied first).
    workers : int
        Local worker processes.
    """
    wall, rows = _fresh_run(file, seed, budget, baseline, out, workers)
    ok = rows[rows["status"] == "ok"]
    arm = {a: ok.loc[ok["arm"] == a, "robustness"].astype(float) for a in ("search", "baseline")}
    return SeedRun(
        seed=seed,
        search_least=float(arm["search"].min()),
        baseline_least=float(arm["baseline"].min()),
        search_evals=int((rows["arm"] == "search").sum()),
        baseline_evals=int((rows["arm"] == "baseline").sum()),
        search_violations=int((arm["search"] < 0).sum()),
        baseline_violations=int((arm["baseline"] < 0).sum()),
        wall_s=wall,
    )


def timed_run(file: Path, seed: int, budget: int, out: Path, workers: int) -> dict:
    """The search arm alone, timed from a fresh folder: wall time, evaluations, libraries.

    Parameters
    ----------
    file : Path
        The search file.
    seed, budget : int
        Replace the file's ``[search]`` values (the baseline is 0).
    out : Path
        The run's output root (emptied first).
    workers : int
        Local worker processes.
    """
    wall, rows = _fresh_run(file, seed, budget, 0, out, workers)
    search = rows[rows["arm"] == "search"]
    return {
        "wall_s": wall,
        "search_evals": len(search),
        "minimise_evals": int((rows["arm"] == "minimise").sum()),
        "search_libraries": int(search["library"].nunique()),
        "median_eval_s": float(search["wall_s"].median()),
        "workers": workers,
    }


def markdown(file: Path, timing: dict, runs: list[SeedRun], command: str) -> str:
    """The report: provenance, the timing line, and one row per seed.

    Parameters
    ----------
    file : Path
        The search file.
    timing : dict
        :func:`timed_run`'s numbers.
    runs : list of SeedRun
        One per seed.
    command : str
        The command that produced the report.
    """
    wins = sum(r.search_wins for r in runs)
    lines = [
        "# Worst-case search against uniform random search",
        "",
        f"{provenance_line()}; `{command}`; search file `{file.name}`.",
        "",
        f"- **Search beats the baseline in {wins} of {len(runs)} seeds** (the search arm's "
        "least robust run is less robust than the least robust baseline run of the same run).",
        f"- **Cost:** the search arm alone, {timing['search_evals']} evaluations and "
        f"{timing['minimise_evals']} minimisation steps, took {timing['wall_s']:.0f} s on "
        f"{timing['workers']} workers (whole command: cluster start-up, minimisation and report "
        f"included); median evaluation {timing['median_eval_s']:.3f} s on one worker; "
        f"{timing['search_libraries']} compiled library(ies) in the search arm.",
        "",
        "| seed | search least | baseline least | search evals | baseline evals "
        "| violations (search / baseline) | search wins | wall (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        lines.append(
            f"| {r.seed} | {r.search_least:.4g} | {r.baseline_least:.4g} | {r.search_evals} "
            f"| {r.baseline_evals} | {r.search_violations} / {r.baseline_violations} "
            f"| {'yes' if r.search_wins else 'no'} | {r.wall_s:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    """Run the benchmark and write ``search.json`` and ``search.md``.

    Parameters
    ----------
    argv : list of str
        Arguments without the program name.
    """
    ap = CliParser(prog="python -m benchmarks.search")
    ap.add_argument("--file", type=Path, default=DEFAULT_SEARCH)
    ap.add_argument("--seeds", type=natural, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--budget", type=count, default=500)
    ap.add_argument("--baseline", type=natural, default=1000)
    ap.add_argument("--workers", type=count, default=2)
    ap.add_argument("--out", type=Path, default=Path(OUT_ROOT) / "bench")
    a = ap.parse_args(argv)
    work = a.out / "search-runs"
    timing = timed_run(a.file, a.seeds[0], a.budget, work / "time", a.workers)
    runs = []
    for seed in a.seeds:
        runs.append(seed_run(a.file, seed, a.budget, a.baseline, work / f"seed-{seed}", a.workers))
        print(f"seed {seed}: {runs[-1]}", file=sys.stderr)
    command = " ".join(["python -m benchmarks.search", *argv])
    data = {"timing": timing, "runs": [asdict(r) | {"search_wins": r.search_wins} for r in runs]}
    atomic_write_text(a.out / "search.json", json.dumps(data, indent=2) + "\n")
    atomic_write_text(a.out / "search.md", markdown(a.file, timing, runs, command))
    print(f"report: {a.out / 'search.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
