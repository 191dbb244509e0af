"""The recipe of docs/ARCHITECTURE.md for a new check, followed verbatim in a copy of the
packages: one new module in verify/ and its one line in ``verify.checks.MODULES`` reach
``bounds.csv`` through ``python -m verify check``.

Independent truth: the new row's observed value is recomputed here from trajectory.csv.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT, SMALL

NEW_CHECK = '''"""Peak joint speed |q_i| of each follower over the run (info)."""

import math

from verify import claims as CL
from verify import signals as S
from verify.checks import CheckInput, register_check

SPEED = CL.register("recipe.joint_speed", "peak |q_i| over the run", CL.Kind.INFO)


@register_check
def joint_speed_rows(R, inp: CheckInput) -> None:
    t = S.column(inp.df, "t")
    dm = S.dims(inp.df)
    for i in range(dm.N):
        q = S.agent_norm(inp.df, "q", i + 1, dm.n)
        R.add(SPEED, CL.Kind.INFO, math.inf, float(q.max()), (float(t[0]), float(t[-1])), agent=i)
'''
ANCHOR = 'MODULES: tuple[str, ...] = ("verify.effort", "verify.demanded_effort")'
LINE = ANCHOR.replace(")", ', "verify.joint_speed")')


def _follow_the_recipe(root):
    repo = root / "repo"
    for pkg in ("core", "synthesis", "symbolic", "generated", "verify"):
        shutil.copytree(ROOT / pkg, repo / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    (repo / "verify" / "joint_speed.py").write_text(NEW_CHECK)
    reg = repo / "verify" / "checks.py"
    text = reg.read_text()
    assert text.count(ANCHOR) == 1, "verify/checks.py: the MODULES line the recipe names"
    reg.write_text(text.replace(ANCHOR, LINE))
    return repo


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_a_new_check_by_the_recipe_reaches_bounds_csv(tmp_path):
    repo = _follow_the_recipe(tmp_path)
    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "verify", "check", str(scenario), "--out", str(out), "--no-gif"],
        cwd=repo,
        env={**os.environ, "PYTHONPATH": str(repo)},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    table = pd.read_csv(out / "small" / "bounds.csv")
    rows = table[table["claim_id"] == "recipe.joint_speed"].sort_values("agent")
    frame = pd.read_csv(out / "small" / "trajectory.csv")
    n_followers = len([c for c in frame.columns if c.startswith("q") and c.endswith("_1")])
    assert len(rows) == n_followers >= 2
    for row in rows.itertuples(index=False):
        q = frame.filter(regex=rf"^q{int(row.agent)}_\d+$").to_numpy()
        assert row.observed == pytest.approx(np.linalg.norm(q, axis=1).max(), rel=1e-12)
        assert row.kind == "info" and row.claim == "peak |q_i| over the run"
    # every other row is the table the packages without the new check write
    plain = subprocess.run(
        [
            sys.executable,
            "-m",
            "verify",
            "check",
            str(scenario),
            "--out",
            str(tmp_path / "p"),
            "--no-gif",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert plain.returncode == 0, plain.stderr
    before = pd.read_csv(tmp_path / "p" / "small" / "bounds.csv")
    rest = table[table["claim_id"] != "recipe.joint_speed"].reset_index(drop=True)
    pd.testing.assert_frame_equal(rest, before)
