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
import recipes
from helpers import ROOT, SMALL


def _follow_the_recipe(root):
    repo = recipes.copy_tree(root / "repo")
    recipes.add_check(repo)
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
    rows = table[table["claim_id"] == recipes.CHECK_CLAIM].sort_values("agent")
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
    rest = table[table["claim_id"] != recipes.CHECK_CLAIM].reset_index(drop=True)
    pd.testing.assert_frame_equal(rest, before)
