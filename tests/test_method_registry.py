"""One registry of integration methods (core/methods.py), and its recipe followed as written.

* One list: every method ``core.methods`` declares is implemented by the module it names,
  with the declared form and fixed-step flag, and ``generated.solvers`` lists the same names.
* No comparison of a method name outside the registry (``core/methods.py`` and
  ``generated/solvers/``): the packages are grepped, and the grep is shown to catch
  planted comparisons.
* The recipe of docs/ARCHITECTURE.md ('An integrator method'): in a copy of the packages,
  one new module in ``generated/solvers/`` (CVODES' Adams-Moulton formulas, a
  multistep family other than the BDF of ``cvodes``) plus one line in ``core/methods.py`` reach ``python -m generated sim --method`` and
  the scenario key ``integration.method``; the trajectory agrees with BDF (a second integration
  formula) and a refused name is one line, exit status 2.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import recipes
from helpers import PACKAGES, ROOT, SMALL, TIGHT

from core import methods
from generated import solvers

#: where method names may be compared: the registry and the methods' implementations
REGISTRY = ("core/methods.py", "generated/solvers/")
#: modules whose comparisons are still to be replaced by a registry attribute (such as
#: ``Solver.fixed_step``): none now. An entry must be a scanned module that still
#: holds a comparison (the test says so), so the list cannot outlive its reason
PENDING: frozenset[str] = frozenset()


def test_every_declared_method_is_implemented_as_declared():
    assert methods.names()[: len(methods.BUILTIN)] == tuple(m.name for m in methods.BUILTIN)
    assert solvers.names() == methods.names()
    for spec in methods.BUILTIN:
        solver = solvers.get(spec.name)
        assert type(solver).__module__ == spec.module
        assert (solver.name, solver.form, solver.fixed_step) == (
            spec.name,
            spec.form,
            spec.fixed_step,
        )


def test_the_loader_takes_its_choices_from_the_registry():
    from core.scenario import METHODS, Integration
    from core.settings import settings_of

    assert METHODS is methods.METHODS
    assert settings_of(Integration)["method"].options is methods.METHODS


def _comparisons(text: str, names: tuple[str, ...]) -> list[str]:
    """Comparisons of a string literal naming a method: ``== "x"``, ``in ("x", ...)``, ..."""
    alt = "|".join(re.escape(n) for n in names)
    lit = rf"""["'](?:{alt})["']"""
    patterns = (
        rf"(?:==|!=)\s*{lit}",
        rf"{lit}\s*(?:==|!=)",
        rf"\b(?:not\s+)?in\s*[\(\[\{{]\s*(?:{lit}\s*,?\s*)+[\)\]\}}]",
        rf"{lit}\s+(?:not\s+)?in\b",
        rf"(?:case)\s+{lit}",
    )
    return [m.group(0) for p in patterns for m in re.finditer(p, text)]


def _method_lists(text: str, names: tuple[str, ...]) -> list[str]:
    """Sequence literals holding every built-in method name (a second list of methods)."""
    out = []
    for m in re.finditer(r"[\(\[\{][^()\[\]{}]*[\)\]\}]", text):
        if all(re.search(rf"""["']{re.escape(n)}["']""", m.group(0)) for n in names):
            out.append(m.group(0))
    return out


def _package_sources():
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            rel = f.relative_to(ROOT).as_posix()
            if not rel.startswith(REGISTRY):
                yield rel, f.read_text(encoding="utf-8")


def test_no_method_name_is_compared_outside_the_registry():
    names = methods.names()
    found, pending, scanned = [], set(), set()
    for rel, text in _package_sources():
        scanned.add(rel)
        hits = _comparisons(text, names) + _method_lists(text, names)
        if rel in PENDING:
            if hits:
                pending.add(rel)
            continue
        found += [f"{rel}: {h}" for h in hits]
    # the grep read every package (an empty scan would pass vacuously)
    assert {rel.split("/", 1)[0] for rel in scanned} == set(PACKAGES)
    assert not found, "\n".join(found)
    assert PENDING <= scanned, f"PENDING names no module: {sorted(PENDING - scanned)}"
    assert pending == PENDING, f"no comparison left in {PENDING - pending}: drop it from PENDING"


@pytest.mark.parametrize(
    "planted",
    [
        'if sc.integration.method != "native":',
        "if method == 'cvodes' or x:",
        'if "idas" == s.method:',
        'if m in ("fixed", "cvodes"):',
        'ok = "native" not in used',
        f"ALL = ({', '.join(map(repr, methods.names()))})",  # every registered name
    ],
)
def test_the_grep_catches_planted_comparisons(planted):
    names = methods.names()
    assert _comparisons(planted, names) or _method_lists(planted, names)


def test_the_grep_leaves_lookups_and_messages_alone():
    names = methods.names()
    for text in (
        'solvers.get("native").prepare(sc, gains)',
        "raise IntegrationError(\"method 'native' needs an acyclic graph (or 'cvodes')\")",
        'DEFAULT = ("cvodes", "native")',
    ):
        assert not _comparisons(text, names) and not _method_lists(text, names), text


# --- the recipe of docs/ARCHITECTURE.md, followed in a copy of the packages ----------------


def _follow_the_recipe(root: Path) -> Path:
    """A copy of the tree with the recipe's module, its line and its docs; returns the copy."""
    repo = recipes.copy_tree(root / "repo")
    recipes.add_method(repo)
    return repo


def _sim(repo: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(repo)}
    return subprocess.run(
        [sys.executable, "-m", "generated", "sim", *args],
        cwd=repo,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def _states(out: Path, name: str) -> pd.DataFrame:
    frame = pd.read_csv(out / name / "trajectory.csv")
    return frame.filter(regex=r"^(p|q|eta)\d")


def _scenario(root: Path, name: str, method: str, tight: bool) -> Path:
    text = SMALL.replace("horizon = 0.5", "horizon = 0.2").replace(
        'name = "small"', f'name = "{name}"'
    )
    text = text.replace('method = "cvodes"', f'method = "{method}"')
    for key, value in TIGHT.items() if tight else ():
        text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text)
    path = root / f"{name}.toml"
    path.write_text(text)
    return path


def _distance(a: pd.DataFrame, b: pd.DataFrame) -> float:
    assert a.shape == b.shape and list(a.columns) == list(b.columns)
    x, y = a.to_numpy(), b.to_numpy()
    return float(np.max(np.abs(x - y) / (np.max(np.abs(y), axis=0) + 1.0)))


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_a_new_method_by_the_recipe_reaches_the_cli_and_the_scenario_key(tmp_path):
    """The key route at tight tolerances, the ``--method`` route at the scenario's own; the
    new formula and BDF converge to one trajectory as the tolerance shrinks 100-fold."""
    repo = _follow_the_recipe(tmp_path)
    out = tmp_path / "out"
    runs = {
        "adams-tight": [str(_scenario(tmp_path, "adams-tight", "adams", True))],
        "bdf-tight": [str(_scenario(tmp_path, "bdf-tight", "cvodes", True))],
        "adams": [str(_scenario(tmp_path, "adams", "cvodes", False)), "--method", "adams"],
        "bdf": [str(_scenario(tmp_path, "bdf", "cvodes", False))],
    }
    for name, args in runs.items():
        r = _sim(repo, *args, "--out", str(out))
        assert r.returncode == 0, r.stderr
        want = "adams" if name.startswith("adams") else "cvodes"
        assert f"method {want}," in r.stdout + r.stderr, (name, r.stdout, r.stderr)
    s = {name: _states(out, name) for name in runs}
    e_loose = _distance(s["adams"], s["bdf"])
    e_tight = _distance(s["adams-tight"], s["bdf-tight"])
    assert e_tight < e_loose / 10, (e_loose, e_tight)
    bad = _sim(repo, runs["bdf"][0], "--method", "adamz", "--out", str(out))
    assert bad.returncode == 2 and "adamz" in bad.stderr and "adams" in bad.stderr
