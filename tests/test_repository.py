"""The repository stands alone: no text points outside it or at the history of its making.

A reader who clones the project has only its files. Every tracked text file is scanned
for references to files outside the repository, for labels of the round of work that
produced a result (a result carries its date and command instead) and for citations of
issue numbers. The forbidden patterns are assembled from pieces so that this file does
not match them; it is excluded from the scan all the same.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from helpers import ROOT

THIS = Path(__file__).resolve().relative_to(ROOT).as_posix()
SUFFIXES = (".py", ".md", ".toml", ".c", ".h")
VENDORED = "generated/native/include/"  # third-party SUNDIALS headers, kept verbatim
SKIP_DIRS = {".git", ".venv", "out", "build", "__pycache__"}

_ORDINALS = "first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth"
_SESSION = "sess" + "ion"
FORBIDDEN: dict[str, re.Pattern[str]] = {
    "reference outside the repository": re.compile(
        "|".join((re.escape(".." + "/" + "shared"), "paper" + r"[- ]" + "spec")), re.IGNORECASE
    ),
    "round-of-work label": re.compile(
        "|".join(
            (
                rf"\b({_ORDINALS}|\d+(st|nd|rd|th))[ -]{_SESSION}s?\b",
                rf"\b{_SESSION} \d+\b",
                rf"\b(this|previous|earlier|last|next|both|these( \w+)?) {_SESSION}s?('s?)?\b",
            )
        ),
        re.IGNORECASE,
    ),
    "issue citation": re.compile(
        "|".join(
            (r"\b" + "iss" + r"ues? #?\d+\b", r"\b" + "ta" + r"sks? #?\d+\b", r"(?<![\w&])#\d+\b")
        ),
        re.IGNORECASE,
    ),
}


def _is_scanned(path: str) -> bool:
    name = path.rsplit("/", 1)[-1]
    if path == THIS or path.startswith(VENDORED):
        return False
    return name == "Makefile" or name.endswith(SUFFIXES)


def tracked_text_files() -> list[str]:
    """Tracked files to scan (git ls-files; a plain walk where there is no git checkout)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60
        ).stdout.decode("utf-8")
        paths = [p for p in out.split("\0") if p]
    except (OSError, subprocess.CalledProcessError):
        paths = [
            p.relative_to(ROOT).as_posix()
            for p in ROOT.rglob("*")
            if p.is_file() and not SKIP_DIRS.intersection(p.relative_to(ROOT).parts)
        ]
    return sorted(p for p in paths if _is_scanned(p) and (ROOT / p).is_file())


def offending_lines(text: str) -> list[tuple[int, str, str]]:
    """(line number, kind, matched text) of every forbidden string in ``text``."""
    found = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        for kind, pattern in FORBIDDEN.items():
            found.extend((lineno, kind, m.group(0)) for m in pattern.finditer(line))
    return found


BAD_SAMPLES = [
    "see " + ".." + "/shared/" + "paper" + "-spec.md",
    "(" + "paper" + "-spec section 4)",
    "measured in the " + "third " + _SESSION,
    "the 4th-" + _SESSION + " run",
    "results of " + _SESSION + " 5",
    "not in this " + _SESSION + "'s runs",
    "as these four " + _SESSION + "s' measurements go",
    "asked by " + "iss" + "ue 7",
    "fixes " + "iss" + "ues #12",
    "see " + "ta" + "sk 3",
    "closes " + "#" + "13",
]
GOOD_SAMPLES = [
    "a shared library (-shared -fPIC)",
    "the shared error family",
    "start_new_" + _SESSION + "=True",
    "repr round-trips exactly; round-off allowance 1e-7",
    "colour #1f77b4 and &#8212;",
    "docs/reading.md, 'Controller'",
]


@pytest.mark.parametrize("sample", BAD_SAMPLES)
def test_patterns_catch_what_they_are_for(sample):
    assert offending_lines(sample), sample


@pytest.mark.parametrize("sample", GOOD_SAMPLES)
def test_patterns_leave_ordinary_text_alone(sample):
    assert not offending_lines(sample), sample


def test_scan_covers_the_project():
    files = set(tracked_text_files())
    expected = (
        "README.md",
        "Makefile",
        "pyproject.toml",
        "docs/reading.md",
        "generated/native/driver.c",
    )
    assert set(expected) <= files
    assert not any(f.startswith(VENDORED) for f in files)
    assert THIS not in files


def test_no_outside_reference_round_label_or_issue_number():
    problems = []
    for path in tracked_text_files():
        text = (ROOT / path).read_text(encoding="utf-8", errors="replace")
        problems += [f"{path}:{n}: {kind}: {hit!r}" for n, kind, hit in offending_lines(text)]
    assert not problems, "\n".join(problems)


def _reading_sections() -> list[str]:
    text = (ROOT / "docs" / "reading.md").read_text(encoding="utf-8")
    return [m.group(1).strip() for m in re.finditer(r"^## (.+)$", text, re.MULTILINE)]


def test_references_to_reading_name_existing_sections():
    sections = _reading_sections()
    assert len(sections) >= 10
    cited = []
    for path in tracked_text_files():
        text = (ROOT / path).read_text(encoding="utf-8", errors="replace")
        cited += [(path, m.group(1)) for m in re.finditer(r"reading\.md,\s+'([^']+)'", text)]
    assert cited, "nothing points to docs/reading.md"
    for path, name in cited:
        assert any(s.startswith(name) for s in sections), f"{path}: no section {name!r}"


def test_tests_cited_in_reading_exist():
    text = (ROOT / "docs" / "reading.md").read_text(encoding="utf-8")
    cited, current = [], None
    for m in re.finditer(r"`(?:tests/(test_\w+\.py))?::(\w+)`", text):
        current = m.group(1) or current  # "`::name`" continues the file cited before it
        cited.append((current, m.group(2)))
    assert len(cited) > 30
    for fname, name in cited:
        body = (ROOT / "tests" / fname).read_text(encoding="utf-8")
        assert f"def {name}(" in body, f"tests/{fname}::{name} cited in docs/reading.md"
