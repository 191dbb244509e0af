"""``python -m sweep cost STUDY [--ids ...]``: what a study's sample costs against a lone
run of the same sample, measured sample by sample in one process.

For each id in turn (the first one untimed, as a warm-up): the *lone run*, the sample's
scenario file written and run as ``make sim`` then the checks would run it
(:func:`benchmarks.lone.sample_times`: :func:`generated.api.run`'s integration + outputs
seconds plus :func:`verify.pipeline.verify_run`), then the study's own
:func:`sweep.worker.run_sample` of the same id (its ``wall_s``, ``simulate_s``,
``checks_s``). Alternating sample by sample keeps this machine's drift (tens of percent
over minutes) out of the ratio, and one process keeps Dask and the second core out: what
is left is the cost of the study's own steps (drawing and validating the sample, gains,
binding the shared library, summarizing). ``python -m benchmarks.study`` measures the
whole study on Dask. Everything is written to a temporary folder; the table is printed.
"""

from __future__ import annotations

import statistics
import tempfile
from dataclasses import dataclass
from pathlib import Path

from core.errors import UsageError
from sweep.sampler import samples, write_scenario
from sweep.study import load_study
from sweep.worker import run_sample


@dataclass(frozen=True)
class SampleCost:
    """One timed sample (seconds).

    Attributes
    ----------
    id : int
        The sample id.
    lone_s : float
        The lone run: integration + outputs + checks.
    task_s : float
        The study's task (``wall_s``): drawing, simulating, checking, summarizing.
    simulate_s, checks_s : float
        The task's parts simulating (gains, library, integration, outputs) and checking.
    """

    id: int
    lone_s: float
    task_s: float
    simulate_s: float
    checks_s: float


def measure(study_path: str | Path, ids: list[int], work: Path) -> list[SampleCost]:
    """Time the lone run and the study task of each valid sample of ``ids``, alternating.

    Parameters
    ----------
    study_path : str or Path
        The study file.
    ids : list of int
        Sample ids; the first valid one is the untimed warm-up. Refused samples are skipped.
    work : Path
        Scratch folder (scenario files, lone runs, the study's run folder).

    Returns
    -------
    list of SampleCost
        One per timed sample, in the order run.

    Raises
    ------
    UsageError
        If fewer than two of ``ids`` are valid samples.
    """
    from benchmarks.lone import sample_times

    study = load_study(study_path)
    files = {s.id: write_scenario(s, work / "samples") for s in samples(study, ids) if s.scenario}
    if len(files) < 2:
        raise UsageError("--ids: give at least two samples the loader accepts (one warms up)")
    path, order = str(Path(study_path).resolve()), list(files)
    sample_times([files[order[0]]], work / "lone")
    run_sample(path, order[0], str(work / "study"))
    out = []
    for k in order[1:]:
        ((integ, checks),) = sample_times([files[k]], work / "lone")
        row = run_sample(path, k, str(work / "study"))
        if row["status"] != "ok":
            raise UsageError(f"sample {k}: {row['status']}: the cost of a sample needs ok samples")
        out.append(SampleCost(k, integ + checks, row["wall_s"], row["simulate_s"], row["checks_s"]))
    return out


def markdown(costs: list[SampleCost]) -> str:
    """Medians of the timed samples and the study task over the lone run, as Markdown.

    Parameters
    ----------
    costs : list of SampleCost
        From :func:`measure`.
    """
    med = statistics.median
    lone, task = med(c.lone_s for c in costs), med(c.task_s for c in costs)
    rest = med(c.task_s - c.simulate_s - c.checks_s for c in costs)
    rows = [
        ("samples timed", f"{len(costs)}"),
        ("lone run: integration + outputs + checks [s] (median)", f"{lone:.4g}"),
        ("study task: wall_s [s] (median)", f"{task:.4g}"),
        ("study task: simulate_s / checks_s [s] (medians)", _pair(costs)),
        ("study task: drawing, validating, summarizing [s] (median)", f"{rest:.3g}"),
        ("median task / median lone", f"{task / lone:.3g}"),
        ("median of the per-sample ratios task / lone", f"{_ratio_median(costs):.3g}"),
    ]
    return "\n".join(["| quantity | value |", "|---|---|", *(f"| {q} | {v} |" for q, v in rows)])


def _pair(costs: list[SampleCost]) -> str:
    med = statistics.median
    return f"{med(c.simulate_s for c in costs):.4g} / {med(c.checks_s for c in costs):.4g}"


def _ratio_median(costs: list[SampleCost]) -> float:
    return statistics.median(c.task_s / c.lone_s for c in costs)


def run(study_path: str, ids: list[int]) -> str:
    """:func:`measure` in a temporary folder, then :func:`markdown`.

    Parameters
    ----------
    study_path : str
        The study file.
    ids : list of int
        Sample ids (the first valid one warms up).
    """
    with tempfile.TemporaryDirectory(prefix="sweep-cost-") as tmp:
        return markdown(measure(study_path, ids, Path(tmp)))
