"""Every shipped scenario runs: ``scenarios/*.toml``, globbed at collection, so a file
added later is covered too; every shipped study (``studies/*.toml``) loads and its first
sample runs.

Each is simulated over a short horizon with its own method and must reach it; the
command line is run as a subprocess for paper-csv.toml (exit status 0). The scenario
with the recorded operator input must equal paper.toml in everything but that input.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from helpers import ROOT

from core.scenario import load_scenario
from generated import api
from generated.values import CodegenSettings
from sweep.sampler import samples, write_scenario
from sweep.study import load_study

SHIPPED = sorted(ROOT.glob("scenarios/*.toml"))
STUDIES = sorted(ROOT.glob("studies/*.toml"))
SHORT = 0.5  # seconds simulated: past the start-up transient (t < 0.1 s)


@pytest.fixture(scope="module")
def roots(tmp_path_factory):
    """One output root and one build cache for the module (the CLI test reuses both)."""
    root = tmp_path_factory.mktemp("shipped")
    return root / "out", root / "build"


def _horizon(path: Path) -> float:
    """The shortest horizon >= SHORT that the scenario's output step divides."""
    step = load_scenario(path).integration.output_step
    return round(step * math.ceil(SHORT / step - 1e-9), 12)


def test_scenarios_are_found():
    names = {p.name for p in SHIPPED}
    assert {"paper.toml", "paper-csv.toml", "paper-synth.toml"} <= names
    assert "example.toml" in {p.name for p in STUDIES}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_scenario_reaches_a_short_horizon(path, roots):
    _reaches_a_short_horizon(path, roots)


@pytest.mark.parametrize("path", STUDIES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_shipped_study_first_sample_reaches_a_short_horizon(path, roots, tmp_path, stored_designs):
    """A study is not a scenario: it loads, and its first sample (written as a scenario
    file, the way ``python -m sweep samples --write-scenarios`` does) runs, to its own
    horizon: a drawn fault onset or link loss may lie past a short one."""
    first = next(samples(_study(path), ids=[0]))
    assert first.reason is None, first.reason
    _reaches_a_short_horizon(write_scenario(first, tmp_path), roots, own_horizon=True)


def _study(path: Path):
    """The study of a study file, or of a search file (a study plus ``[search]``)."""
    import tomllib

    if "search" in tomllib.loads(path.read_text()):
        from search.spec import load_search

        return load_search(path).study
    return load_study(path)


def _reaches_a_short_horizon(path: Path, roots, own_horizon: bool = False) -> None:
    out, build = roots
    horizon = load_scenario(path).integration.horizon if own_horizon else _horizon(path)
    cg = CodegenSettings(optimization="-O0", jacobian="auto", build_root=str(build))
    res = api.run(
        path,
        overrides={"integration.horizon": horizon},
        codegen=cg,
        out_root=out,
        progress=False,
    )
    tr = res.trajectory
    assert tr.complete, tr.message
    assert tr.t[-1] == horizon and res.meta["complete"]
    assert len(res.frame) == round(horizon / load_scenario(path).integration.output_step) + 1


def test_command_line_runs_paper_csv(roots):
    """``python -m generated sim scenarios/paper-csv.toml``: exit status 0, rows written."""
    out, build = roots
    path = ROOT / "scenarios" / "paper-csv.toml"
    horizon = _horizon(path)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "generated",
            "sim",
            str(path),
            "--set",
            f"integration.horizon={horizon}",
            "--out",
            str(out),
            "--opt=-O0",
            "--no-progress",
        ],
        cwd=ROOT,
        env={**os.environ, "HITL_BUILD_DIR": str(build)},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    rows = round(horizon / load_scenario(path).integration.output_step) + 1
    assert f"{rows} rows" in proc.stderr
    csv = out / f"paper-csv-horizon-{horizon}" / "trajectory.csv"
    assert len(csv.read_text().splitlines()) == rows + 1  # header + rows


def test_paper_csv_is_paper_with_a_recorded_input():
    """paper-csv.toml differs from paper.toml only in its name and the operator input."""
    paper = tomllib.loads((ROOT / "scenarios" / "paper.toml").read_text())
    csv = tomllib.loads((ROOT / "scenarios" / "paper-csv.toml").read_text())
    for d in (paper, csv):
        d.pop("name"), d.pop("description")
    assert paper["leader"].pop("u0") == ["2*cos(t)"]
    assert csv["leader"].pop("u0_csv") == "traces/operator.csv"
    assert csv == paper
