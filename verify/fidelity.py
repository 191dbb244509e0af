"""Which function implements which equation: a scan of the ``# eq. (N)`` comments.

``python -m verify.fidelity`` prints the Markdown table used in ``docs/fidelity.md``
(equations (1)–(42), each with the functions whose code carries its number).
"""

from __future__ import annotations

import ast
import re
import sys
from collections import defaultdict
from pathlib import Path

PACKAGES = ("core", "synthesis", "symbolic", "generated", "verify", "benchmarks")
_EQ = re.compile(r"#.*?\beqs?\.\s*\((\d+)\)(?:\s*[–-]\s*\((\d+)\))?")
_MORE = re.compile(r"\((\d+)\)(?:\s*[–-]\s*\((\d+)\))?")


def _functions(tree: ast.AST) -> list[tuple[int, int, str]]:
    """(first line, last line, qualified name) of every function and class."""
    out: list[tuple[int, int, str]] = []

    def walk(node: ast.AST, prefix: str) -> None:
        for ch in ast.iter_child_nodes(node):
            if isinstance(ch, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{ch.name}"
                out.append((ch.lineno, ch.end_lineno or ch.lineno, name))
                walk(ch, name + ".")
            else:
                walk(ch, prefix)

    walk(tree, "")
    return out


def equation_map(root: str | Path = ".") -> dict[int, list[str]]:
    """Equation number -> sorted ``module:function`` locations whose comments cite it.

    Parameters
    ----------
    root : str or Path
        The repository root.

    Returns
    -------
    dict
    """
    root = Path(root)
    found: dict[int, set[str]] = defaultdict(set)
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            if "build" in path.parts:
                continue
            text = path.read_text(encoding="utf-8")
            try:
                funcs = _functions(ast.parse(text))
            except SyntaxError:
                continue
            mod = ".".join(path.relative_to(root).with_suffix("").parts)
            for lineno, line in enumerate(text.splitlines(), start=1):
                hash_at = line.find("#")
                if hash_at < 0:
                    continue
                comment = line[hash_at:]
                m = _EQ.search(comment)
                if not m:
                    continue
                nums = {int(m.group(1))}
                if m.group(2):  # a range "(36)–(38)"
                    nums |= set(range(int(m.group(1)), int(m.group(2)) + 1))
                for a, b in _MORE.findall(comment[m.end() :]):  # further numbers and ranges
                    nums |= set(range(int(a), int(b or a) + 1))
                inner = [f for f in funcs if f[0] <= lineno <= f[1]]
                where = max(inner, key=lambda f: f[0])[2] if inner else "<module>"
                for k in nums:
                    if 1 <= k <= 42:
                        found[k].add(f"{mod}:{where}")
    return {k: sorted(v) for k, v in sorted(found.items())}


def markdown(root: str | Path = ".") -> str:
    """The table of equations (1)–(42) with their implementing functions.

    Parameters
    ----------
    root : str or Path
        The repository root.
    """
    emap = equation_map(root)
    rows = ["| eq. | implemented in (from `# eq. (N)` comments) |", "|---|---|"]
    for k in range(1, 43):
        locs = emap.get(k)
        rows.append(f"| ({k}) | {', '.join(f'`{x}`' for x in locs) if locs else '—'} |")
    return "\n".join(rows)


if __name__ == "__main__":
    sys.stdout.write(markdown(sys.argv[1] if len(sys.argv) > 1 else ".") + "\n")
