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
        "generated/native/agents.c",
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


# --- hand-written docs describe the software as it is ---------------------------------------
#
# README.md and docs/*.md carry no commit hashes, no clock times or dates of measurements and
# no narrative of the work ("before/after", "tried", "not kept"): a measured figure belongs to
# the generated report that carries its date, commit and machine (make bench, make demo, a
# study's report.md); the docs name the command that regenerates it.

_HEX = "0-9a-f"
HISTORY: dict[str, re.Pattern[str]] = {
    "commit hash": re.compile(
        rf"(?<![\w#/.-])(?=[{_HEX}]*\d)(?=[{_HEX}]*[a-f])[{_HEX}]{{7,40}}(?![\w-])"
    ),
    "clock time": re.compile(
        r"(?<![\w:\[.])([01]?\d|2[0-3]):[0-5]\d(:[0-5]\d)?(?![\w:\]])", re.IGNORECASE
    ),
    "date": re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b"),
    "narrative": re.compile(
        "|".join(
            (
                r"\bnot (kept|adopted|tried)\b",
                r"\bnone (was )?kept\b",
                r"\b(was|were|been|we) (built and )?tried\b",
                r"\btried, (measured|and)\b",
                r"\b(to|yester)day\b",
                r"\b(ours|results|numbers|times) before\b",
                r"\bbefore the (fix|change)s?\b",
                r"\bafter the (fix|change)s?\b",
                r"\bearlier runs?\b",
                r"\b(a few|several|\d+) (minutes|hours|days) (later|earlier|ago)\b",
                r"\bmeasured on (this|that|the \d|\d)",
                r"\bprevious(ly)? (version|code|run|default)s?\b",
                r"\bas of this writing\b",
            )
        ),
        re.IGNORECASE,
    ),
}


def history_lines(text: str) -> list[tuple[int, str, str]]:
    """(line number, kind, matched text) of every trace of the work's history in ``text``."""
    found = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        for kind, pattern in HISTORY.items():
            found.extend((lineno, kind, m.group(0)) for m in pattern.finditer(line))
    return found


def hand_written_docs() -> list[Path]:
    """README.md and every page of docs/."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


HISTORY_SAMPLES = [
    ("commit hash", "reverted by " + "5ac4" + "fd8"),
    ("commit hash", "SHA-256 " + "dd75" + "0b07…"),
    ("commit hash", "| " + "c959" + "843 (01:38) | 100.4 |"),
    ("clock time", "started " + "03" + ":41 UTC"),
    ("clock time", "at " + "17" + ":05:12 the run"),
    ("date", "Measured " + "2026" + "-12-02 on this machine"),
    ("narrative", "was built and measured, " + "not " + "kept"),
    ("narrative", "Follower by follower: " + "tried" + ", measured"),
    ("narrative", "| GMRES (" + "ours " + "before) |"),
    ("narrative", "six runs of the benchmark " + "to" + "day"),
    ("narrative", "1.4× slower " + "a few hours " + "later"),
    ("narrative", "Results " + "before the " + "change"),
    ("narrative", "Measured " + "on this " + "2-core machine"),
]
HISTORY_CLEAN = [
    "a slice x[10:20] of the output grid",
    "colour #1f77b4, dimension 2x2, tolerance 1e-10",
    "the step before the horizon; the error after t = 1 s",
    "each listed type is tried with representative values",
    "a folder whose PID is no longer running",
    "ratio 3:1 and the key `f(t)`",
    "seed 20260121 and hash deadbeef",
]


@pytest.mark.parametrize(("kind", "sample"), HISTORY_SAMPLES)
def test_history_detector_catches_planted_examples(kind, sample):
    assert kind in {k for _, k, _ in history_lines(sample)}, sample


@pytest.mark.parametrize("sample", HISTORY_CLEAN)
def test_history_detector_leaves_reference_text_alone(sample):
    assert not history_lines(sample), sample


def test_docs_carry_no_history():
    problems = []
    for path in hand_written_docs():
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(ROOT).as_posix()
        problems += [f"{rel}:{n}: {kind}: {hit!r}" for n, kind, hit in history_lines(text)]
    assert not problems, "\n".join(problems)


README_MAX_LINES = 160


def test_readme_is_a_front_door():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= README_MAX_LINES
    for target in ("make demo", "make test", "make check", "make sim", "make verify"):
        assert target in text, target


# --- docs/ARCHITECTURE.md lists every module -------------------------------------------------

PACKAGES = (
    "core",
    "synthesis",
    "symbolic",
    "generated",
    "verify",
    "design",
    "sweep",
    "benchmarks",
    "search",
    "console",
)


def _package_bullets(text: str) -> dict[str, str]:
    """The text of each ``- `pkg/` — ...`` bullet of ARCHITECTURE.md, by package."""
    bullets: dict[str, str] = {}
    current = None
    for line in text.splitlines():
        m = re.match(r"- `(\w+)/`", line)
        if m:
            current = m.group(1)
            bullets[current] = ""
        elif line.startswith(("- ", "#")):
            current = None
        if current:
            bullets[current] += line + "\n"
    return bullets


def unlisted_modules(text: str, root: Path = ROOT) -> list[str]:
    """Package modules (``__init__``/``__main__`` aside) the architecture text does not name.

    A module ``pkg/sub/name.py`` is named by its full path anywhere in the text, or by
    ``sub/name.py`` or `` `name.py` `` in the package's bullet.
    """
    bullets = _package_bullets(text)
    missing = []
    for pkg in PACKAGES:
        bullet = bullets.get(pkg, "")
        for f in sorted((root / pkg).rglob("*.py")):
            if f.name in ("__init__.py", "__main__.py") or "__pycache__" in f.parts:
                continue
            rel = f.relative_to(root / pkg).as_posix()
            if f"{pkg}/{rel}" in text or f"`{f.name}`" in bullet:
                continue
            if re.search(r"(?<![\w/])" + re.escape(rel) + r"\b", bullet):
                continue
            missing.append(f"{pkg}/{rel}")
    return missing


def test_architecture_lists_every_module():
    text = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    missing = unlisted_modules(text)
    assert not missing, f"docs/ARCHITECTURE.md does not name: {', '.join(missing)}"


def test_architecture_check_catches_an_unlisted_module(tmp_path):
    (tmp_path / "core" / "models").mkdir(parents=True)
    for name in ("core/errors.py", "core/models/base.py", "core/models/new_arm.py"):
        (tmp_path / name).write_text("")
    text = "## Packages\n- `core/` — `errors.py` and `models/` (`base.py`)\n"
    assert unlisted_modules(text, tmp_path) == ["core/models/new_arm.py"]
