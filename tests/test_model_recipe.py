"""The recipe of docs/ARCHITECTURE.md for a follower model, followed verbatim in a copy of
the packages: one new module in core/models/ (a two-link arm with viscous joint friction,
a Rayleigh dissipation function) and its one import line reach ``python -m generated sim``
and ``python -m verify check``.

Independent truths: the derived friction force against its closed form c_k q_k; the
generated closed loop against the numpy second implementation (verify/reference.py, its
own plant and control law) at random states; every guaranteed row of the run holds.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pandas as pd
import pytest
import recipes
from helpers import SMALL

#: in the copy: D against c q, and the generated loop against the numpy reference
CHECK = """
import json, sys
import numpy as np
from core.models import build_model
from core.scenario import load_scenario
from generated.api import ensure_gains
from symbolic.closed_loop import build_closed_loop
from verify.reference import Reference
from pathlib import Path

sc = load_scenario(sys.argv[1])
m = build_model("damped_arm", {})
rng = np.random.default_rng(1)
p, q = rng.normal(size=2), rng.normal(size=2)
d = np.array(m.D(p, q)).ravel()
gains, _ = ensure_gains(sc, Path(sys.argv[2]))
cl = build_closed_loop(sc, gains)
ref = Reference(sc, gains)
worst = 0.0
for t in (0.0, 0.05, 0.3):
    for _ in range(3):
        x = cl.x0 + 0.3 * rng.normal(size=cl.x0.size)
        want, got = ref.rhs(t, x), np.array(cl.ode(t, x)).ravel()
        worst = max(worst, float(np.max(np.abs(got - want)) / np.max(np.abs(want))))
print(json.dumps({"D": d.tolist(), "cq": [2.0 * q[0], 3.0 * q[1]], "rhs": worst,
                  "checks": dict(m.checks)}))
"""


def _follow_the_recipe(root):
    repo = recipes.copy_tree(root / "repo")
    recipes.add_model(repo)
    return repo


def _run(repo, *args):
    return subprocess.run(
        [sys.executable, *args],
        cwd=repo,
        env={**os.environ, "PYTHONPATH": str(repo)},
        capture_output=True,
        text=True,
        timeout=900,
    )


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_a_model_with_dissipation_by_the_recipe_runs_and_verifies(tmp_path):
    repo = _follow_the_recipe(tmp_path)
    scenario = tmp_path / "damped.toml"
    text = SMALL.replace('model = "two_link"', 'model = "damped_arm"')
    scenario.write_text(text.replace('name = "small"', 'name = "damped"'))
    out = tmp_path / "out"
    sim = _run(repo, "-m", "generated", "sim", str(scenario), "--out", str(out), "--no-progress")
    assert sim.returncode == 0, sim.stderr
    ver = _run(repo, "-m", "verify", "check", str(scenario), "--out", str(out), "--no-gif")
    assert ver.returncode == 0, ver.stdout + ver.stderr
    table = pd.read_csv(out / "damped" / "bounds.csv")
    guaranteed = table[table["kind"] == "guaranteed"]
    assert len(guaranteed) and guaranteed["holds"].astype(str).eq("True").all()
    chk = _run(repo, "-c", CHECK, str(scenario), str(out / "damped"))
    assert chk.returncode == 0, chk.stderr
    got = json.loads(chk.stdout.splitlines()[-1])
    assert got["D"] == pytest.approx(got["cq"], rel=1e-12)
    assert got["rhs"] < 1e-9
    assert got["checks"]["dissipation"] == "exact"
