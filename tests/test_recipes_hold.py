"""The three recipes of docs/ARCHITECTURE.md ('Where new things go') leave the tree green.

Followed together in a copy of the tree (tests/recipes.py: a damped arm, a joint-speed
check, the Adams-Moulton method), the copy passes ``make lint`` (ruff check, ruff format
--check, lint-imports) and the quick tests the recipes touch (the model library, the
docstrings, the architecture listing, the method registry, the scenario format's tables).
The copy's tests are shown to see the new things: their verbose output names the new
model's parametrised case, and the copy's registries list all three. The end-to-end runs
of each recipe (simulation, verification) are tests/test_model_recipe.py,
tests/test_claim_recipe.py and tests/test_method_registry.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import recipes

#: what ``make lint`` lints
LINTED = (*recipes.PACKAGES, "tests")
#: the quick tests that read what the recipes change
TOUCHED = (
    "tests/test_models.py",
    "tests/test_docstrings.py",
    "tests/test_repository.py",
    "tests/test_method_registry.py",
    "tests/test_scenario_docs.py",
)
BIN = Path(sys.executable).parent

#: in the copy: the registries after the recipes
REGISTRIES = """
import json
from core import methods
from core.models import REGISTRY
from verify import checks
print(json.dumps({"models": sorted(REGISTRY), "methods": list(methods.names()),
                  "checks": list(checks.MODULES)}))
"""


def _run(repo: Path, *cmd: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(c) for c in cmd],
        cwd=repo,
        env={**os.environ, "PYTHONPATH": str(repo)},
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.mark.slow
def test_the_three_recipes_leave_lint_and_the_touched_tests_green(tmp_path):
    repo = recipes.copy_tree(tmp_path / "repo")
    recipes.add_model(repo)
    recipes.add_check(repo)
    recipes.add_method(repo)
    for cmd in (
        (BIN / "ruff", "check", *LINTED),
        (BIN / "ruff", "format", "--check", *LINTED),
        (BIN / "lint-imports",),
    ):
        r = _run(repo, *cmd)
        assert r.returncode == 0, f"{cmd[0].name} {' '.join(cmd[1:])}:\n{r.stdout}{r.stderr}"
    reg = _run(repo, sys.executable, "-c", REGISTRIES)
    assert reg.returncode == 0, reg.stderr
    got = json.loads(reg.stdout)
    assert recipes.MODEL_NAME in got["models"]
    assert recipes.METHOD_NAME in got["methods"]
    assert f"verify.{recipes.CHECK_NAME}" in got["checks"]
    quick = ("-m", "not slow", "-o", "addopts=", "-v", "-p", "no:cacheprovider")
    tests = _run(repo, sys.executable, "-m", "pytest", *quick, *TOUCHED)
    assert tests.returncode == 0, tests.stdout[-4000:] + tests.stderr[-2000:]
    assert f"test_properties_symbolically[{recipes.MODEL_NAME}] PASSED" in tests.stdout
