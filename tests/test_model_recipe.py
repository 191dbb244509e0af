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
from helpers import ROOT, SMALL

NEW_MODEL = '''"""The paper's two-link arm with viscous friction c1, c2 in its joints, n = 2."""

from core.models.base import ModelSpec, register


def _lagrangian(prm):
    import sympy as sp

    p1, p2 = sp.symbols("p1 p2", real=True)
    q1, q2 = sp.symbols("q1 q2", real=True)
    m1, m2, r1, r2, J1, J2, g0, c1, c2 = (
        sp.nsimplify(prm[k]) for k in ("m1", "m2", "r1", "r2", "J1", "J2", "g0", "c1", "c2")
    )
    T = sp.Rational(1, 2) * (m1 + m2) * r1**2 * q1**2
    T += sp.Rational(1, 2) * m2 * (r2**2 * (q1 + q2) ** 2 + 2 * r1 * r2 * sp.cos(p2) * q1 * (q1 + q2))
    T += sp.Rational(1, 2) * J1 * q1**2 + sp.Rational(1, 2) * J2 * q2**2
    V = g0 * ((m1 + m2) * r1 * sp.sin(p1) + m2 * r2 * sp.sin(p1 + p2))
    R = sp.Rational(1, 2) * (c1 * q1**2 + c2 * q2**2)  # Rayleigh: viscous friction
    return T, V, [p1, p2], [q1, q2], R


SPEC = register(
    ModelSpec(
        name="damped_arm",
        n=2,
        defaults={"m1": 0.5, "m2": 1.5, "r1": 1.0, "r2": 0.8, "J1": 5.0, "J2": 5.0, "g0": 9.81,
                  "c1": 2.0, "c2": 3.0},
        lagrangian=_lagrangian,
        description="two-link arm with viscous joint friction",
        nonnegative=frozenset({"g0", "J1", "J2", "c1", "c2"}),
    )
)
'''
ANCHOR = (
    "from core.models import point_mass_2d, point_mass_3d, two_link  # noqa: F401  (registers)\n"
)
LINE = "from core.models import damped_arm  # noqa: F401  (registers)\n"

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
    repo = root / "repo"
    for pkg in ("core", "synthesis", "symbolic", "generated", "verify"):
        shutil.copytree(ROOT / pkg, repo / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    (repo / "core" / "models" / "damped_arm.py").write_text(NEW_MODEL)
    reg = repo / "core" / "models" / "__init__.py"
    text = reg.read_text()
    assert text.count(ANCHOR) == 1, "core/models/__init__.py: the import line the recipe names"
    reg.write_text(text.replace(ANCHOR, ANCHOR + LINE))
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
