"""make SET=/VARIANT= reach the command lines; misspelt knobs are refused in one line."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from core.errors import UsageError
from verify.__main__ import _parser as verify_parser

ROOT = Path(__file__).resolve().parents[1]


#: what a parent make (``make test``) hands its children; a user's shell has none of it
_PARENT_MAKE = ("MAKELEVEL", "MAKEFLAGS", "MFLAGS", "MAKEOVERRIDES")


def _make(*args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in _PARENT_MAKE}
    return subprocess.run(
        ["make", "-s", *args, "PY=/bin/echo"], cwd=ROOT, capture_output=True, text=True, env=env
    )


def test_readme_example_reaches_sim() -> None:
    r = _make("sim", "SET=options.tau_threshold=0.1;followers[2].g=[[0, 1], [5, 0.5]]", "VARIANT=x")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("--set ")[1:] == [
        "options.tau_threshold=0.1 ",
        "followers[2].g=[[0, 1], [5, 0.5]] --variant x\n",
    ]


@pytest.mark.parametrize("target", ["synth", "verify", "report", "demo"])
def test_every_scenario_target_takes_knobs(target: str) -> None:
    r = _make(target, "SET=options.ablation=true", "VARIANT=v")
    assert r.returncode == 0 and "--set options.ablation=true --variant v" in r.stdout


@pytest.mark.parametrize(
    ("var", "right"),
    [("set", "SET"), ("OVERRIDE", "SET"), ("SETS", "SET"), ("VARIANTS", "VARIANT")],
)
def test_misspelt_knob_is_refused(var: str, right: str) -> None:
    r = _make("sim", f"{var}=options.ablation=true")
    assert r.returncode != 0 and f"use {right}=" in r.stderr


def test_knobs_refused_where_not_taken() -> None:
    r = _make("sweep", "SET=options.ablation=true")
    assert r.returncode != 0 and "not by sweep" in r.stderr


def test_verify_variant_without_set_is_refused() -> None:
    from core.overrides import scenario_knobs

    args = verify_parser().parse_args(["check", "--variant", "x"])
    with pytest.raises(UsageError):
        scenario_knobs(args)


def test_verify_and_sim_name_the_same_run() -> None:
    from core.overrides import load, scenario_knobs
    from generated.__main__ import _parser as sim_parser

    line = ["scenarios/paper.toml", "--set", "options.ablation=true", "--variant", "v1"]
    names = []
    for args in (
        sim_parser().parse_args(["sim", *line]),
        verify_parser().parse_args(["check", *line]),
    ):
        names.append(load(args.scenario, *scenario_knobs(args)).name)
    assert names == ["paper-v1", "paper-v1"]
