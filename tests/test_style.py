"""Layout rules of the developers' guide that a formatter cannot enforce.

- No function (or method, or nested function) in the Python packages is longer than
  :data:`MAX_LINES` lines, counted from its ``def`` line to its last line.
- No tracked Python file switches the formatter off for a statement: ``ruff format``
  lays out every line. The marker is assembled from pieces so this file does not
  contain it.
"""

from __future__ import annotations

import ast
import subprocess

import pytest
from helpers import PACKAGES, ROOT

MAX_LINES = 80
MARKER = "# fmt" + ": " + "skip"


def long_functions(source: str, where: str, limit: int = MAX_LINES) -> list[str]:
    """``where:line name (n lines)`` for every function in ``source`` over ``limit`` lines."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            n = node.end_lineno - node.lineno + 1
            if n > limit:
                out.append(f"{where}:{node.lineno} {node.name} ({n} lines)")
    return out


def marker_lines(text: str, where: str) -> list[str]:
    """``where:line`` for every line of ``text`` that carries the formatter-skip marker."""
    return [f"{where}:{k}" for k, line in enumerate(text.splitlines(), 1) if MARKER in line]


def tracked_python_files() -> list[str]:
    """Python files under version control (every ``*.py`` outside ``.venv`` without git)."""
    try:
        res = subprocess.run(
            ["git", "ls-files", "-z", "*.py"], cwd=ROOT, capture_output=True, check=True, timeout=60
        )
        paths = [p for p in res.stdout.decode().split("\0") if p]
    except (OSError, subprocess.SubprocessError):
        skip = {".venv", ".git", "out"}
        paths = [
            p.relative_to(ROOT).as_posix()
            for p in ROOT.rglob("*.py")
            if not skip.intersection(p.relative_to(ROOT).parts)
        ]
    return sorted(p for p in paths if (ROOT / p).is_file())


def package_files() -> list[str]:
    """The tracked Python files of :data:`PACKAGES`."""
    return [p for p in tracked_python_files() if p.split("/", 1)[0] in PACKAGES]


def test_the_checks_find_what_they_look_for():
    def statements(k: int, indent: str) -> str:
        return "".join(f"{indent}x{j} = {j}\n" for j in range(k))

    at_limit = "def short():\n" + statements(MAX_LINES - 1, "    ")  # def line + 79 = 80
    over = "class A:\n    def long(self):\n" + statements(MAX_LINES, "        ")  # 81
    nested = "def outer():\n    def inner():\n" + statements(MAX_LINES - 1, "        ")
    assert long_functions(at_limit, "ok.py") == []
    assert long_functions(over, "long.py") == [f"long.py:2 long ({MAX_LINES + 1} lines)"]
    assert long_functions(nested, "n.py") == [f"n.py:1 outer ({MAX_LINES + 1} lines)"]
    assert marker_lines(f"x = 1\ny = (1, 2)  {MARKER}\n", "f.py") == ["f.py:2"]
    assert marker_lines("x = 1  # fmt: on\n", "f.py") == []


def test_the_packages_are_found():
    files = package_files()
    for pkg in PACKAGES:
        assert any(p.startswith(pkg + "/") for p in files), pkg


@pytest.mark.parametrize("package", PACKAGES)
def test_no_function_is_longer_than_the_limit(package):
    found = []
    for path in package_files():
        if path.startswith(package + "/"):
            found += long_functions((ROOT / path).read_text(encoding="utf-8"), path)
    assert not found, f"functions over {MAX_LINES} lines (split them):\n" + "\n".join(found)


def test_no_formatter_skip_markers():
    found = []
    for path in tracked_python_files():
        found += marker_lines((ROOT / path).read_text(encoding="utf-8", errors="replace"), path)
    assert not found, "remove the marker and let ruff format lay out:\n" + "\n".join(found)
