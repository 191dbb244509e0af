"""``make bench`` (study part): what a study costs per sample, measured in one run.

::

    python -m benchmarks.study                      # studies/faults.toml, 1,000 samples
    python -m benchmarks.study --samples 40 --compare 10 --recompile 2   # a quick look

Measured, all on the same study (default ``studies/faults.toml``, its samples share one
compiled library through ``options.fault_slots``):

lone
    ``--lone`` sample scenarios (written by ``python -m sweep samples --write-scenarios``)
    run one after another in this process after a warm-up run: the integration and its
    outputs (:func:`generated.api.run`'s ``integration`` + ``outputs`` seconds) plus the
    checks (:func:`verify.pipeline.verify_run`, the study's verification), medians. They
    run again after the whole study: this machine's speed drifts by tens of percent over
    minutes, so the cost a study sample is compared with is the mean of the two.
shared against recompiled
    ``python -m sweep run`` on ids ``0 .. --compare - 1`` with one worker and a warm build
    cache, against ``--recompile`` samples each run by a fresh ``python -m sweep run --ids
    k`` with a throw-away ``HITL_BUILD_DIR`` (so each generates and compiles its library,
    what every sample cost before the numbers became runtime parameters). Per-sample
    cost = the task's own ``wall_s`` (results.parquet), median.
2 workers against 1
    The same ``--compare`` ids with ``--workers 2``: samples per second from the wall
    time of each command (cluster start-up included).
the study's own cost
    The 1-worker run follows the lone samples within a minute: its median task against
    them is the study's own cost per sample (drawing, validating, gains, binding,
    summarizing, Dask) with the machine's drift kept small.
the whole study
    ``--samples`` samples (the study with its count replaced) with ``--workers 2``, timed;
    the per-sample cost is wall x workers / samples (start-up, the first sample of each
    worker and the report included). From the same run's rows: the median task
    (``wall_s``) against the lone cost, and the part of a task that is neither simulating
    nor checking (``wall_s - simulate_s - checks_s``: drawing, validating, summarizing).

``sweep`` is the layer above ``benchmarks``, so the study runner is used through its
command line only. Results: ``<out>/study.json`` and ``<out>/study.md`` with the date and
the command; ratios are reported, no timing is asserted.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd

from benchmarks.bench import BenchError
from core.artifacts import OUT_ROOT, atomic_write_text
from core.errors import run_cli

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_STUDY = ROOT / "studies" / "faults.toml"


@dataclass
class StudyBench:
    """The measured numbers (seconds unless named otherwise)."""

    study: str
    lone_integration_s: float
    lone_checks_s: float
    lone_s: float
    lone_after_s: float
    shared_task_s: float
    shared_task_vs_lone: float
    recompile_task_s: float
    shared_vs_recompile: float
    one_worker_samples_per_s: float
    two_worker_samples_per_s: float
    two_vs_one: float
    samples: int
    samples_wall_s: float
    samples_per_s: float
    per_sample_cost_s: float
    per_sample_vs_lone: float
    samples_task_median_s: float
    samples_task_vs_lone: float
    samples_task_overhead_s: float
    samples_ok: int


def _sweep(args: list[str], env: dict[str, str] | None = None) -> float:
    """Run ``python -m sweep ARGS`` to completion; its wall time (raises on failure)."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "sweep", *args],
        cwd=ROOT,
        env={**os.environ, **(env or {})},
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["?"])[-1]
        raise BenchError(f"python -m sweep {' '.join(args)} failed: {last}")
    return time.perf_counter() - t0


def _study_copy(study: Path, count: int, folder: Path) -> Path:
    """The study with ``count`` samples and its base as an absolute path, in ``folder``."""
    text = study.read_text(encoding="utf-8")
    base = re.search(r'^base\s*=\s*"([^"]+)"', text, re.M)
    text = text.replace(base.group(0), f'base = "{(study.parent / base.group(1)).resolve()}"')
    head, table, rest = text.partition("\n[")  # the top-level keys come before any table
    head = re.sub(r"^count\s*=\s*\d+", f"count = {count}", head, flags=re.M)
    text = head + table + rest
    path = folder / study.name
    path.write_text(text, encoding="utf-8")
    return path


def _results(out: Path) -> pd.DataFrame:
    """The one results table under ``out`` (``<out>/<study name>/results.parquet``)."""
    (path,) = out.glob("*/results.parquet")
    return pd.read_parquet(path)


def lone(study: Path, n: int, work: Path) -> tuple[float, float]:
    """Median integration (+ outputs) and checks seconds of ``n`` samples after a warm-up.

    Parameters
    ----------
    study : Path
        The study file.
    n : int
        Samples timed (ids 1 .. n; id 0 warms the build).
    work : Path
        Scratch folder.
    """
    from generated import api
    from verify import pipeline as P

    ids = [str(k) for k in range(n + 1)]
    _sweep(["samples", str(study), "--ids", *ids, "--write-scenarios", str(work / "lone")])
    integ, checks = [], []
    for k, f in enumerate(sorted((work / "lone").glob("*.toml"))):
        res = api.run(f, out_root=work / "lone-out", progress=False)
        run = P.Run(api.load(f), res.frame, res.trajectory.x, res.meta, res.csv_path.parent)
        t0 = time.perf_counter()
        P.verify_run(run, out_root=work / "lone-out")
        if k:  # id 0 built the library
            ws = res.meta["wall_seconds"]
            integ.append(ws["integration"] + ws["outputs"])
            checks.append(time.perf_counter() - t0)
    return statistics.median(integ), statistics.median(checks)


def task_median(out: Path) -> float:
    """Median of the tasks' own ``wall_s`` in the results under ``out``.

    Parameters
    ----------
    out : Path
        The ``--out`` of a ``python -m sweep run``.
    """
    return float(_results(out)["wall_s"].median())


def measure(study: Path, a: argparse.Namespace, work: Path) -> StudyBench:
    """Every number of :class:`StudyBench`, in one run (see the module docstring).

    Parameters
    ----------
    study : Path
        The study file.
    a : argparse.Namespace
        ``--samples``, ``--compare``, ``--recompile``, ``--lone``.
    work : Path
        Scratch folder (emptied first); its ``build`` is the warm cache.
    """
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    env = {"HITL_BUILD_DIR": str(work / "build")}
    os.environ.update(env)  # the lone runs and every command share the warm cache
    li, lc = lone(study, a.lone, work)
    cmp_study = _study_copy(study, max(a.compare, a.recompile), work)
    ids = ["--ids", *(str(k) for k in range(a.compare))]
    w1 = _sweep(["run", str(cmp_study), *ids, "--workers", "1", "--out", str(work / "w1")], env)
    w2 = _sweep(["run", str(cmp_study), *ids, "--workers", "2", "--out", str(work / "w2")], env)
    rc = []
    for k in range(a.recompile):  # a throw-away build cache per sample: it compiles
        out = work / f"rc{k}"
        fresh = {"HITL_BUILD_DIR": str(work / f"build-rc{k}")}
        _sweep(["run", str(cmp_study), "--ids", str(k), "--workers", "1", "--out", str(out)], fresh)
        rc.append(task_median(out))
    (work / "big").mkdir()
    big = _study_copy(study, a.samples, work / "big")
    wall = _sweep(["run", str(big), "--workers", "2", "--out", str(work / "big-out")], env)
    res = _results(work / "big-out")
    shutil.rmtree(work / "lone-out")  # the same samples alone again: the machine's drift
    li2, lc2 = lone(study, a.lone, work)
    lone_s = (li + lc + li2 + lc2) / 2
    shared, recompiled = task_median(work / "w1"), statistics.median(rc)
    cost = wall * 2 / a.samples
    task = float(res["wall_s"].median())
    return StudyBench(
        study=str(study),
        lone_integration_s=li,
        lone_checks_s=lc,
        lone_s=li + lc,
        lone_after_s=li2 + lc2,
        shared_task_s=shared,
        shared_task_vs_lone=shared / (li + lc),
        recompile_task_s=recompiled,
        shared_vs_recompile=recompiled / shared,
        one_worker_samples_per_s=a.compare / w1,
        two_worker_samples_per_s=a.compare / w2,
        two_vs_one=w1 / w2,
        samples=a.samples,
        samples_wall_s=wall,
        samples_per_s=a.samples / wall,
        per_sample_cost_s=cost,
        per_sample_vs_lone=cost / lone_s,
        samples_task_median_s=task,
        samples_task_vs_lone=task / lone_s,
        samples_task_overhead_s=float(
            (res["wall_s"] - res["simulate_s"] - res["checks_s"]).median()
        ),
        samples_ok=int((res["status"] == "ok").sum()),
    )


def markdown(b: StudyBench, date: str, command: str) -> str:
    """The measured numbers as a Markdown report.

    Parameters
    ----------
    b : StudyBench
    date, command : str
        When and how it was measured.
    """
    rows = [
        ("lone sample: integration + outputs [s] (median)", f"{b.lone_integration_s:.3g}"),
        ("lone sample: checks (verify_run) [s] (median)", f"{b.lone_checks_s:.3g}"),
        (
            "lone sample: integration + outputs + checks, again after the study [s]",
            f"{b.lone_after_s:.3g}",
        ),
        ("study task, shared library [s] (median wall_s, 1 worker)", f"{b.shared_task_s:.3g}"),
        (
            "study task (1 worker) / lone before it (run a minute apart)",
            f"{b.shared_task_vs_lone:.3g}",
        ),
        ("study task, recompiled per sample [s] (median wall_s)", f"{b.recompile_task_s:.3g}"),
        ("shared library: samples/s ratio against recompiling", f"{b.shared_vs_recompile:.3g}"),
        ("1 worker: samples/s", f"{b.one_worker_samples_per_s:.3g}"),
        ("2 workers: samples/s", f"{b.two_worker_samples_per_s:.3g}"),
        ("2 workers against 1 (samples/s ratio)", f"{b.two_vs_one:.3g}"),
        (f"{b.samples} samples, 2 workers: wall [s]", f"{b.samples_wall_s:.4g}"),
        (f"{b.samples} samples: ok", f"{b.samples_ok}"),
        ("per-sample cost = wall x 2 / samples [s]", f"{b.per_sample_cost_s:.3g}"),
        (
            "per-sample cost / lone (integration + checks; mean of before and after)",
            f"{b.per_sample_vs_lone:.3g}",
        ),
        ("median task wall_s in that run [s]", f"{b.samples_task_median_s:.3g}"),
        ("median task wall_s / lone", f"{b.samples_task_vs_lone:.3g}"),
        (
            "median task wall_s - simulate_s - checks_s (draw, summary) [s]",
            f"{b.samples_task_overhead_s:.3g}",
        ),
    ]
    lines = [
        "# Study benchmark",
        "",
        f"`{command}` ({date}, {os.cpu_count()} cores); study `{b.study}`.",
        "",
        "| quantity | value |",
        "|---|---|",
        *(f"| {q} | {v} |" for q, v in rows),
    ]
    return "\n".join(lines) + "\n"


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.study", description=__doc__)
    ap.add_argument("--study", default=str(DEFAULT_STUDY), help="the study file")
    ap.add_argument("--samples", type=int, default=1000, help="samples timed with 2 workers")
    ap.add_argument("--compare", type=int, default=100, help="samples of the 1/2-worker runs")
    ap.add_argument("--recompile", type=int, default=3, help="samples compiled each")
    ap.add_argument("--lone", type=int, default=20, help="samples run alone in this process")
    ap.add_argument("--out", default=None, help="output folder (default out/bench)")
    return ap


def main(argv: list[str]) -> int:
    """Measure and write ``study.json`` and ``study.md``.

    Parameters
    ----------
    argv : list of str
        Arguments without the program name.
    """
    a = _parser().parse_args(argv)
    out = Path(a.out or Path(OUT_ROOT) / "bench")
    date = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    command = " ".join(["python -m benchmarks.study", *argv])
    b = measure(Path(a.study).resolve(), a, out / "study-work")
    atomic_write_text(
        out / "study.json", json.dumps({"date": date, "command": command, **asdict(b)}, indent=1)
    )
    text = markdown(b, date, command)
    atomic_write_text(out / "study.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(main))
