"""``make bench`` (study part): what a study costs per sample, measured in one run.

::

    python -m benchmarks.study                      # studies/faults.toml, 1,000 samples
    python -m benchmarks.study --samples 40 --compare 10 --recompile 2 --rounds 2 --block 5

Measured, all on the same study (default ``studies/faults.toml``, its samples share one
compiled library through ``options.fault_slots``), in this order:

lone
    ``--lone`` sample scenarios (written by ``python -m sweep samples --write-scenarios``)
    run one after another in this process after a warm-up run: the integration and its
    outputs (:func:`generated.api.run`'s ``integration`` + ``outputs`` seconds) plus the
    checks (:func:`verify.pipeline.verify_run`, the study's verification), medians
    (:func:`benchmarks.lone.sample_times`). They run again after the whole study: this
    machine's speed drifts by tens of percent over minutes, so the serial lone cost a
    study sample is compared with is the mean of the two.
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
interleaved blocks
    ``--rounds`` rounds, each a block of ``--block`` lone samples in this process
    immediately followed by ``python -m sweep run --workers 1 --ids`` on the same ids;
    every round has ids of its own, after those of the lone samples. Per round: median
    task ``wall_s`` / median lone sample (:func:`round_ratios`; the task excludes cluster
    start-up, the median the worker's first two samples, which pay its imports and its
    first checks). The study's own per-sample cost with the drift between the two halves
    down to seconds.
same-load lone
    Two ``python -m benchmarks.lone`` processes at once, each timing lone samples on its
    own half (:func:`split_files`) of the scenario files written above, after an untimed
    warm-up and a common start: the lone cost with both cores busy (median over both),
    right before and right after the whole study.
the whole study
    ``--samples`` samples (the study with its count replaced) with ``--workers 2``, timed;
    the per-sample cost is wall x workers / samples (start-up, the first sample of each
    worker and the report included), against the serial lone cost (the target's strict
    reading) and against the same-load lone cost (mean of before and after; the machine's
    2-core slowdown taken out). From the same run's rows: the median task (``wall_s``)
    against the lone cost, and the part of a task that is neither simulating nor checking
    (``wall_s - simulate_s - checks_s``: drawing, validating, summarizing).

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

from benchmarks.catalogue import BenchError
from benchmarks.lone import sample_times
from core.artifacts import OUT_ROOT, atomic_write_text
from core.cli_args import count
from core.errors import CliParser, run_cli
from core.provenance import current_commit, machine

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_STUDY = ROOT / "studies" / "faults.toml"
#: the acceptance target: a study sample within 25 % of a lone integration plus its checks
TARGET = 1.25


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
    rounds: int
    block: int
    block_ratios: list[float]
    block_ratio_median: float
    block_lone_s: float
    block_task_s: float
    block_pooled_ratio: float
    same_load_before_s: float
    same_load_after_s: float
    same_load_lone_s: float
    same_load_vs_serial: float
    per_sample_vs_same_load: float


def _sweep_proc(args: list[str], env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m sweep ARGS`` to completion (raises on failure)."""
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
    return proc


def _sweep(args: list[str], env: dict[str, str] | None = None) -> float:
    """Run ``python -m sweep ARGS`` to completion; its wall time (raises on failure)."""
    t0 = time.perf_counter()
    _sweep_proc(args, env)
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


def _write_scenarios(study: Path, ids: list[int], folder: Path) -> dict[int, Path]:
    """Write the valid samples among ``ids`` into ``folder``: id -> file, in the order of ``ids``."""
    args = ["samples", str(study), "--ids", *map(str, ids), "--write-scenarios", str(folder)]
    rows = [line.split("\t") for line in _sweep_proc(args).stdout.splitlines()]
    written = {int(r[0]): ROOT / r[-1] for r in rows if len(r) >= 5 and r[2] == "ok"}
    return {k: written[k] for k in ids if k in written}


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
        Samples timed (ids 1 .. n; id 0 warms the build). Their scenario files are
        ``<work>/lone/*.toml``.
    work : Path
        Scratch folder.
    """
    files = _write_scenarios(study, list(range(n + 1)), work / "lone")
    times = sample_times(list(files.values()), work / "lone-out")[1:]  # id 0 built the library
    return statistics.median(t[0] for t in times), statistics.median(t[1] for t in times)


def task_median(out: Path) -> float:
    """Median of the tasks' own ``wall_s`` in the results under ``out``.

    Parameters
    ----------
    out : Path
        The ``--out`` of a ``python -m sweep run``.
    """
    return float(_results(out)["wall_s"].median())


def round_ratios(lones: list[list[float]], tasks: list[list[float]]) -> list[float]:
    """Per round: median study task seconds / median lone sample seconds.

    Parameters
    ----------
    lones, tasks : list of list of float
        Per round, the lone samples' and the study tasks' seconds (one list each).
    """
    return [
        statistics.median(t) / statistics.median(lo) for lo, t in zip(lones, tasks, strict=True)
    ]


def split_files(files: list[Path], parts: int) -> list[list[Path]]:
    """``files`` dealt round-robin into ``parts`` disjoint lists (sizes differ by at most 1).

    Parameters
    ----------
    files : list of Path
        At least ``parts`` of them.
    parts : int
        Number of lists.
    """
    if len(files) < parts:
        raise BenchError(f"{len(files)} scenario files for {parts} lone loops: raise --lone")
    return [files[i::parts] for i in range(parts)]


def interleaved(study: Path, a: argparse.Namespace, work: Path) -> tuple[dict, list[Path]]:
    """The interleaved blocks: :class:`StudyBench`'s ``block_*`` fields and the files run.

    Parameters
    ----------
    study : Path
        The study file.
    a : argparse.Namespace
        ``--rounds``, ``--block`` and ``--lone`` (the blocks' ids follow the lone ones).
    work : Path
        Scratch folder; the blocks use ``<work>/blocks``.
    """
    first, k, folder = a.lone + 1, a.block, work / "blocks"
    folder.mkdir()
    copy = _study_copy(study, first + a.rounds * k, folder)
    files = _write_scenarios(copy, list(range(first, first + a.rounds * k)), folder / "scenarios")
    lones, tasks = [], []
    for r in range(a.rounds):
        ids = [i for i in range(first + r * k, first + (r + 1) * k) if i in files]
        if not ids:
            raise BenchError(f"round {r}: no sample of ids {first + r * k}.. loads: raise --block")
        lones.append([i + c for i, c in sample_times([files[i] for i in ids], folder / "lone-out")])
        out = folder / f"run{r}"  # right after the lone half: the same samples, seconds apart
        _sweep(["run", str(copy), "--ids", *map(str, ids), "--workers", "1", "--out", str(out)])
        tasks.append(_results(out)["wall_s"].tolist())
    pooled_lone = statistics.median(x for r in lones for x in r)
    pooled_task = statistics.median(x for r in tasks for x in r)
    ratios = round_ratios(lones, tasks)
    fields = {
        "rounds": a.rounds,
        "block": k,
        "block_ratios": ratios,
        "block_ratio_median": statistics.median(ratios),
        "block_lone_s": pooled_lone,
        "block_task_s": pooled_task,
        "block_pooled_ratio": pooled_task / pooled_lone,
    }
    return fields, list(files.values())


def _start_loop(warm: Path, files: list[Path], out: Path) -> subprocess.Popen:
    """Start ``python -m benchmarks.lone`` on ``files`` (stderr to ``<out>/stderr.txt``)."""
    out.mkdir(parents=True)
    cmd = [sys.executable, "-m", "benchmarks.lone", "--out", str(out), str(warm), *map(str, files)]
    with (out / "stderr.txt").open("w", encoding="utf-8") as err:
        return subprocess.Popen(
            cmd, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err, text=True
        )


def _loop_error(out: Path) -> BenchError:
    """The last line a failed lone loop wrote to its stderr, as one error."""
    last = ((out / "stderr.txt").read_text(encoding="utf-8").strip().splitlines() or ["?"])[-1]
    return BenchError(f"python -m benchmarks.lone (output {out}) failed: {last}")


def _loop_times(proc: subprocess.Popen, out: Path) -> list[float]:
    """A started loop's per-sample seconds (integration + outputs + checks) once it ends."""
    text = proc.stdout.read()
    if proc.wait() != 0:
        raise _loop_error(out)
    data = json.loads(text.strip().splitlines()[-1])
    return [i + c for i, c in zip(data["integration_s"], data["checks_s"], strict=True)]


def same_load(warm: Path, files: list[Path], work: Path) -> list[float]:
    """Per-sample lone seconds of two loops run at once, each on half of ``files``.

    Parameters
    ----------
    warm : Path
        The scenario each loop runs first, untimed.
    files : list of Path
        Scenario files timed, split between the loops (:func:`split_files`).
    work : Path
        Output folder of the loops (``loop0``, ``loop1``), created.
    """
    outs, procs = [work / "loop0", work / "loop1"], []
    try:
        for part, o in zip(split_files(files, 2), outs, strict=True):
            procs.append(_start_loop(warm, part, o))
        for p, o in zip(procs, outs, strict=True):
            if not any(line.strip() == "ready" for line in p.stdout):
                raise _loop_error(o)
        for p in procs:  # both warm: start timing together
            p.stdin.write("go\n")
            p.stdin.close()
        return [x for p, o in zip(procs, outs, strict=True) for x in _loop_times(p, o)]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def compare(study: Path, a: argparse.Namespace, work: Path) -> dict:
    """1 worker against 2 and the shared library against recompiling: those fields.

    Parameters
    ----------
    study : Path
        The study file.
    a : argparse.Namespace
        ``--compare`` and ``--recompile``.
    work : Path
        Scratch folder.
    """
    cmp_study = _study_copy(study, max(a.compare, a.recompile), work)
    ids = ["--ids", *(str(k) for k in range(a.compare))]
    w1 = _sweep(["run", str(cmp_study), *ids, "--workers", "1", "--out", str(work / "w1")])
    w2 = _sweep(["run", str(cmp_study), *ids, "--workers", "2", "--out", str(work / "w2")])
    rc = []
    for k in range(a.recompile):  # a throw-away build cache per sample: it compiles
        out = work / f"rc{k}"
        fresh = {"HITL_BUILD_DIR": str(work / f"build-rc{k}")}
        _sweep(["run", str(cmp_study), "--ids", str(k), "--workers", "1", "--out", str(out)], fresh)
        rc.append(task_median(out))
    shared, recompiled = task_median(work / "w1"), statistics.median(rc)
    return {
        "shared_task_s": shared,
        "recompile_task_s": recompiled,
        "shared_vs_recompile": recompiled / shared,
        "one_worker_samples_per_s": a.compare / w1,
        "two_worker_samples_per_s": a.compare / w2,
        "two_vs_one": w1 / w2,
    }


def whole_study(study: Path, n: int, work: Path, warm: Path, files: list[Path]) -> dict:
    """The ``n``-sample study with 2 workers between two same-load lone measurements.

    Parameters
    ----------
    study : Path
        The study file.
    n : int
        Samples.
    work : Path
        Scratch folder.
    warm, files : Path, list of Path
        The same-load loops' warm-up and timed scenario files (:func:`same_load`).
    """
    before = statistics.median(same_load(warm, files, work / "same-before"))
    (work / "big").mkdir()
    big = _study_copy(study, n, work / "big")
    wall = _sweep(["run", str(big), "--workers", "2", "--out", str(work / "big-out")])
    after = statistics.median(same_load(warm, files, work / "same-after"))
    res = _results(work / "big-out")
    return {
        "samples": n,
        "samples_wall_s": wall,
        "samples_per_s": n / wall,
        "per_sample_cost_s": wall * 2 / n,
        "samples_task_median_s": float(res["wall_s"].median()),
        "samples_task_overhead_s": float(
            (res["wall_s"] - res["simulate_s"] - res["checks_s"]).median()
        ),
        "samples_ok": int((res["status"] == "ok").sum()),
        "same_load_before_s": before,
        "same_load_after_s": after,
    }


def _against_lone(f: dict, before: tuple[float, float], after: tuple[float, float]) -> dict:
    """The lone fields and every ratio against a lone cost, from the measured fields ``f``."""
    lone_s = (sum(before) + sum(after)) / 2  # the machine drifts: mean of before and after
    same = (f["same_load_before_s"] + f["same_load_after_s"]) / 2
    return {
        "lone_integration_s": before[0],
        "lone_checks_s": before[1],
        "lone_s": sum(before),
        "lone_after_s": sum(after),
        "shared_task_vs_lone": f["shared_task_s"] / sum(before),
        "per_sample_vs_lone": f["per_sample_cost_s"] / lone_s,
        "samples_task_vs_lone": f["samples_task_median_s"] / lone_s,
        "same_load_lone_s": same,
        "same_load_vs_serial": same / lone_s,
        "per_sample_vs_same_load": f["per_sample_cost_s"] / same,
    }


def measure(study: Path, a: argparse.Namespace, work: Path) -> StudyBench:
    """Every number of :class:`StudyBench`, in one run (see the module docstring).

    Parameters
    ----------
    study : Path
        The study file.
    a : argparse.Namespace
        ``--samples``, ``--compare``, ``--recompile``, ``--lone``, ``--rounds``, ``--block``.
    work : Path
        Scratch folder (emptied first); its ``build`` is the warm cache.
    """
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    os.environ["HITL_BUILD_DIR"] = str(work / "build")  # every run and command share it
    before = lone(study, a.lone, work)
    f: dict = {"study": str(study), **compare(study, a, work)}
    blocks, block_files = interleaved(study, a, work)
    lone_files = sorted((work / "lone").glob("*.toml"))  # id 0 first: the loops' warm-up
    f |= blocks | whole_study(study, a.samples, work, lone_files[0], lone_files[1:] + block_files)
    shutil.rmtree(work / "lone-out")  # the same samples alone again: the machine's drift
    after = lone(study, a.lone, work)
    return StudyBench(**f, **_against_lone(f, before, after))


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
        *_whole_rows(b),
        ("median task wall_s in that run [s]", f"{b.samples_task_median_s:.3g}"),
        ("median task wall_s / lone", f"{b.samples_task_vs_lone:.3g}"),
        (
            "median task wall_s - simulate_s - checks_s (draw, summary) [s]",
            f"{b.samples_task_overhead_s:.3g}",
        ),
        *_block_rows(b),
    ]
    lines = [
        "# Study benchmark",
        "",
        f"`{command}` ({date}, commit {current_commit()}, {machine()}); study `{b.study}`.",
        "",
        "| quantity | value |",
        "|---|---|",
        *(f"| {q} | {v} |" for q, v in rows),
        "",
        *NOTES,
    ]
    return "\n".join(lines) + "\n"


#: under the table: which row is the target's strict reading, what the others isolate
NOTES = (
    "The target's strict reading is the row marked *strict*: the whole study's wall x 2 /",
    "samples against lone samples run one at a time in one process (target 1.25).",
    "The same-load rows compare that cost with lone samples run two processes at a time",
    "(both cores busy): the machine's 2-core slowdown is taken out, start-up and the study's",
    "own steps stay in. The interleaved blocks compare 1-worker study tasks (median",
    "`wall_s`: no cluster start-up, no first-sample imports) with lone runs of the same",
    "samples seconds before: the study's own per-sample steps, the machine's drift kept out.",
)


def _whole_rows(b: StudyBench) -> list[tuple[str, str]]:
    """The whole study's per-sample cost against the serial and the same-load lone cost."""
    return [
        (
            "**strict**: per-sample cost / serial lone (integration + checks; mean of before"
            " and after)",
            f"{b.per_sample_vs_lone:.3g} (target {TARGET})",
        ),
        (
            "same-load lone sample: two loops at once, both cores busy [s] (median; before /"
            " after the study)",
            f"{b.same_load_before_s:.3g} / {b.same_load_after_s:.3g}",
        ),
        (
            "same-load lone / serial lone (the machine's 2-core slowdown; means of before"
            " and after)",
            f"{b.same_load_vs_serial:.3g}",
        ),
        (
            "per-sample cost / same-load lone (mean of before and after)",
            f"{b.per_sample_vs_same_load:.3g}",
        ),
    ]


def _block_rows(b: StudyBench) -> list[tuple[str, str]]:
    """The interleaved blocks' rows."""
    head = f"interleaved blocks ({b.rounds} rounds of {b.block} samples, 1 worker)"
    return [
        (
            f"{head}: median task / median lone, per round",
            ", ".join(f"{r:.3g}" for r in b.block_ratios),
        ),
        (f"{head}: median of the per-round ratios", f"{b.block_ratio_median:.3g}"),
        (
            f"{head}: pooled median task / pooled median lone [s]",
            f"{b.block_task_s:.3g} / {b.block_lone_s:.3g} = {b.block_pooled_ratio:.3g}",
        ),
    ]


def _parser() -> argparse.ArgumentParser:
    ap = CliParser(prog="python -m benchmarks.study", description=__doc__)
    ap.add_argument("--study", default=str(DEFAULT_STUDY), help="the study file")
    ap.add_argument("--samples", type=count, default=1000, help="samples timed with 2 workers")
    ap.add_argument("--compare", type=count, default=100, help="samples of the 1/2-worker runs")
    ap.add_argument("--recompile", type=count, default=3, help="samples compiled each")
    ap.add_argument("--lone", type=count, default=20, help="samples run alone in this process")
    ap.add_argument("--rounds", type=count, default=6, help="rounds of interleaved blocks")
    ap.add_argument("--block", type=count, default=20, help="samples per interleaved block")
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
