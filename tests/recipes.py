"""The three recipes of docs/ARCHITECTURE.md ('Where new things go'), applied to a copy of
the tree as a newcomer would follow them.

Each edit finds its place by the code's structure (the registering import, the tuple
assigned to ``MODULES`` or ``BUILTIN``, the package's bullet of the architecture text),
never by the exact text of a line, so a reformatted or reordered line does not move the
anchor. The new modules are written as ``ruff format`` writes them: the copy must pass
the same lint as the tree (tests/test_recipes_hold.py).
"""

from __future__ import annotations

import ast
import re
import shutil
import tomllib
from pathlib import Path

from helpers import ROOT

#: the project's packages: the import contract's root packages (pyproject.toml)
PACKAGES = tuple(
    tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["root_packages"]
)

#: what a copy of the tree holds: the packages, their tests, the docs the tests read and
#: the configuration of ruff, import-linter and pytest
TREE = (
    *PACKAGES,
    "tests",
    "docs",
    "scenarios",
    "studies",
    "pyproject.toml",
    "README.md",
    "Makefile",
)
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", ".import_linter_cache", "build")


def copy_tree(dst: Path, parts: tuple[str, ...] = TREE) -> Path:
    """Copy ``parts`` of the repository into ``dst`` (created) and return ``dst``.

    Parameters
    ----------
    dst : Path
    parts : tuple of str
        Top-level folders and files.
    """
    dst.mkdir(parents=True, exist_ok=True)
    for part in parts:
        src = ROOT / part
        if src.is_dir():
            shutil.copytree(src, dst / part, ignore=_IGNORE)
        elif src.is_file():
            shutil.copy2(src, dst / part)
    return dst


def _assigned(tree: ast.Module, name: str) -> ast.expr:
    """The value of the module-level assignment to ``name`` (with or without annotation)."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == name for t in node.targets
        ):
            return node.value
        if isinstance(node, ast.AnnAssign) and getattr(node.target, "id", None) == name:
            assert node.value is not None
            return node.value
    raise AssertionError(f"no module-level assignment to {name}")


def _offset(text: str, line: int, col: int) -> int:
    """The character offset of (1-based line, 0-based UTF-8 byte column) in ``text``."""
    lines = text.splitlines(keepends=True)
    head = "".join(lines[: line - 1])
    return len(head) + len(lines[line - 1].encode()[:col].decode())


def append_to_tuple(path: Path, name: str, element: str) -> None:
    """Add ``element`` (source text) as the last element of the tuple assigned to ``name``.

    Parameters
    ----------
    path : Path
        The module.
    name : str
        The assigned name (``MODULES``, ``BUILTIN``).
    element : str
        One expression.
    """
    text = path.read_text(encoding="utf-8")
    value = _assigned(ast.parse(text), name)
    assert isinstance(value, ast.Tuple) and value.elts, f"{path}: {name} is not a tuple"
    last = value.elts[-1]
    if last.end_lineno == value.end_lineno:  # on one line with the closing parenthesis
        at = _offset(text, last.end_lineno, last.end_col_offset)
        new = f", {element}"
    else:  # one element per line, as ruff lays out a tuple with a trailing comma
        at = _offset(text, last.end_lineno + 1, 0)
        new = f"{' ' * last.col_offset}{element},\n"
    path.write_text(text[:at] + new + text[at:], encoding="utf-8")


def add_to_registering_import(path: Path, package: str, module: str) -> None:
    """Add ``module`` to the ``from <package> import a, b  # registers`` statement.

    The statement is the one importing submodules of ``package`` (the names that are
    files of its folder); the names stay sorted, as ruff's import sorting keeps them.

    Parameters
    ----------
    path : Path
        The package's ``__init__.py``.
    package : str
        Its dotted name (``core.models``).
    module : str
        The new submodule's name.
    """
    text = path.read_text(encoding="utf-8")
    folder = path.parent
    for node in ast.parse(text).body:
        if (
            isinstance(node, ast.ImportFrom)
            and node.module == package
            and all((folder / f"{a.name}.py").is_file() for a in node.names)
        ):
            names = sorted({a.name for a in node.names} | {module})
            start = _offset(text, node.lineno, node.col_offset)
            end = _offset(text, node.end_lineno, node.end_col_offset)
            new = f"from {package} import {', '.join(names)}"
            path.write_text(text[:start] + new + text[end:], encoding="utf-8")
            return
    raise AssertionError(f"{path}: no statement importing submodules of {package}")


def name_in_architecture(repo: Path, package: str, words: str) -> None:
    """Add ``words`` (naming a new module) to the end of ``package``'s bullet in
    docs/ARCHITECTURE.md's 'Packages' list.

    Parameters
    ----------
    repo : Path
    package : str
        ``core``, ``verify``, ``generated``, ...
    words : str
        A sentence naming the module, e.g. ``` `damped_arm.py`: ...```.
    """
    doc = repo / "docs" / "ARCHITECTURE.md"
    lines = doc.read_text(encoding="utf-8").splitlines(keepends=True)
    start = next(i for i, ln in enumerate(lines) if ln.startswith(f"- `{package}/`"))
    end = start + 1
    while end < len(lines) and lines[end].startswith("  "):
        end += 1
    lines[end - 1] = lines[end - 1].rstrip("\n") + f" {words}\n"
    doc.write_text("".join(lines), encoding="utf-8")


# --- a follower model ------------------------------------------------------------------------

MODEL_NAME = "damped_arm"
MODEL = '''"""The paper's two-link arm with viscous friction c1, c2 in its joints, n = 2."""

from core.models.base import ModelSpec, register


def _lagrangian(prm):
    import sympy as sp

    p1, p2 = sp.symbols("p1 p2", real=True)
    q1, q2 = sp.symbols("q1 q2", real=True)
    m1, m2, r1, r2, J1, J2, g0, c1, c2 = (
        sp.nsimplify(prm[k]) for k in ("m1", "m2", "r1", "r2", "J1", "J2", "g0", "c1", "c2")
    )
    T = sp.Rational(1, 2) * (m1 + m2) * r1**2 * q1**2
    T += (
        sp.Rational(1, 2)
        * m2
        * (r2**2 * (q1 + q2) ** 2 + 2 * r1 * r2 * sp.cos(p2) * q1 * (q1 + q2))
    )
    T += sp.Rational(1, 2) * J1 * q1**2 + sp.Rational(1, 2) * J2 * q2**2
    V = g0 * ((m1 + m2) * r1 * sp.sin(p1) + m2 * r2 * sp.sin(p1 + p2))
    R = sp.Rational(1, 2) * (c1 * q1**2 + c2 * q2**2)  # Rayleigh: viscous friction
    return T, V, [p1, p2], [q1, q2], R


SPEC = register(
    ModelSpec(
        name="damped_arm",
        n=2,
        defaults={
            "m1": 0.5,
            "m2": 1.5,
            "r1": 1.0,
            "r2": 0.8,
            "J1": 5.0,
            "J2": 5.0,
            "g0": 9.81,
            "c1": 2.0,
            "c2": 3.0,
        },
        lagrangian=_lagrangian,
        description="two-link arm with viscous joint friction",
        nonnegative=frozenset({"g0", "J1", "J2", "c1", "c2"}),
    )
)
'''


def add_model(repo: Path) -> None:
    """'A follower model': its module, its import line, its name in the architecture."""
    (repo / "core" / "models" / f"{MODEL_NAME}.py").write_text(MODEL, encoding="utf-8")
    init = repo / "core" / "models" / "__init__.py"
    add_to_registering_import(init, "core.models", MODEL_NAME)
    name_in_architecture(repo, "core", f"`{MODEL_NAME}.py`: the two-link arm with joint friction.")


# --- a check along trajectories --------------------------------------------------------------

CHECK_NAME = "joint_speed"
CHECK_CLAIM = "recipe.joint_speed"
CHECK = '''"""Peak joint speed |q_i| of each follower over the run (info)."""

import math

from verify import claims as CL
from verify.checks import CheckInput, register_check
from verify.signals import Signal

SPEED = CL.register("recipe.joint_speed", "peak |q_i| over the run", CL.Kind.INFO)


@register_check
def joint_speed_rows(R, inp: CheckInput) -> None:
    """Peak |q_i| of every follower over the run.

    Parameters
    ----------
    R : Rows
        Rows to append to.
    inp : CheckInput
        The table's inputs.
    """
    t = inp.view.t
    for i in range(inp.view.dims.N):
        q = inp.view.norm(Signal.Q, i + 1)
        R.add(SPEED, CL.Kind.INFO, math.inf, float(q.max()), (float(t[0]), float(t[-1])), agent=i)
'''


def add_check(repo: Path) -> None:
    """'A check along trajectories': its module, its name in ``MODULES``, in the architecture."""
    (repo / "verify" / f"{CHECK_NAME}.py").write_text(CHECK, encoding="utf-8")
    append_to_tuple(repo / "verify" / "checks.py", "MODULES", f'"verify.{CHECK_NAME}"')
    name_in_architecture(
        repo, "verify", f"`{CHECK_NAME}.py`: peak joint speeds, a registered check."
    )


# --- an integrator method --------------------------------------------------------------------

METHOD_NAME = "adams"
METHOD = '''"""Method ``adams``: CVODES' Adams-Moulton formulas through CasADi (a recipe's example)."""

from __future__ import annotations

from generated.solvers import register
from generated.solvers.engine import CasadiSolver, SundialsStepper


class AdamsStepper(SundialsStepper):
    """CVODES with the Adams-Moulton formulas (orders 1-12) and Newton iterations."""

    plugin = "cvodes"

    def plugin_options(self):
        """The Adams-Moulton formulas instead of BDF."""
        return {"linear_multistep_method": "adams"}


class Adams(CasadiSolver):
    """CVODES' Adams-Moulton formulas over the compiled right-hand side."""

    name = "adams"
    form = "ode"
    summary = "Adams-Moulton (CVODES) through CasADi"

    def stepper(self, f, settings, nx, nz):
        """One CVODES call per chunk.

        Parameters
        ----------
        f : casadi.Function
            The right-hand side in integrator form.
        settings : IntegratorSettings
        nx, nz : int
            Numbers of differential and algebraic states.
        """
        return AdamsStepper(f, settings, nz)


SOLVER = register(Adams())
'''
METHOD_SPEC = 'MethodSpec("adams", "ode", False, "generated.solvers.adams", "Adams-Moulton")'


def add_method_to_scenario_format(repo: Path, name: str) -> None:
    """Add ``"name"`` to the choices of ``method`` in docs/scenario-format.md's
    ``[integration]`` table (its type cell lists every registered method)."""
    doc = repo / "docs" / "scenario-format.md"
    text = doc.read_text(encoding="utf-8")
    row = re.compile(r'(?m)^(\| `method` \| (?:`"\w+"`, )*`"\w+"`)( \|)')
    assert len(row.findall(text)) == 1, "docs/scenario-format.md: the method row"
    doc.write_text(row.sub(rf'\1, `"{name}"`\2', text), encoding="utf-8")


def add_method(repo: Path) -> None:
    """'An integrator method': its module, its line in ``BUILTIN``, the docs that list it."""
    (repo / "generated" / "solvers" / f"{METHOD_NAME}.py").write_text(METHOD, encoding="utf-8")
    append_to_tuple(repo / "core" / "methods.py", "BUILTIN", METHOD_SPEC)
    add_method_to_scenario_format(repo, METHOD_NAME)
    name_in_architecture(
        repo, "generated", f"`solvers/{METHOD_NAME}.py`: CVODES' Adams-Moulton formulas."
    )
