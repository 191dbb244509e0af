"""Where and when a measurement was made: the date, the commit and the machine.

Generated reports (``make bench``'s tables, a study's report) carry this line, so that
their numbers can be compared and regenerated; hand-written docs carry none.

::

    from core.provenance import provenance_line, write_provenance
    provenance_line()           # 'measured 2026-01-01T12:00:00+00:00, commit 1a2b3c4d5e6f, ...'
    write_provenance(folder)    # folder/provenance.json beside CSV outputs
"""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import subprocess
from dataclasses import asdict, dataclass
from pathlib import Path

from core.artifacts import atomic_write_text

#: the checkout whose commit is recorded (the package tree's parent)
REPO = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Provenance:
    """The date (UTC, ISO 8601), the commit and the machine of a measurement.

    Attributes
    ----------
    date : str
    commit : str
        ``git rev-parse HEAD`` (12 hex digits), with ``+modified`` when the tracked files
        differ from it; ``unknown`` outside a git checkout.
    machine : str
        Operating system, architecture, processor and core count.
    """

    date: str
    commit: str
    machine: str


def _git(*args: str) -> str | None:
    try:
        r = subprocess.run(
            ["git", *args], cwd=REPO, capture_output=True, text=True, timeout=30, check=True
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip()


def current_commit() -> str:
    """The checkout's commit (12 hex digits, ``+modified`` if tracked files changed)."""
    head = _git("rev-parse", "--short=12", "HEAD")
    if not head:
        return "unknown"
    dirty = _git("status", "--porcelain", "--untracked-files=no")
    return head + ("+modified" if dirty else "")


def machine() -> str:
    """One line naming the operating system, architecture, processor and core count."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.system()} {platform.machine()}, {cpu}, {os.cpu_count()} cores"


def provenance() -> Provenance:
    """The provenance of a measurement made now, in this checkout, on this machine."""
    now = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    return Provenance(date=now, commit=current_commit(), machine=machine())


def provenance_line(p: Provenance | None = None) -> str:
    """``measured <date>, commit <commit>, <machine>`` (one line for a report's header).

    Parameters
    ----------
    p : Provenance, optional
        Default: :func:`provenance` now.
    """
    p = p or provenance()
    return f"measured {p.date}, commit {p.commit}, {p.machine}"


def write_provenance(folder: str | Path, p: Provenance | None = None) -> Path:
    """Write ``folder/provenance.json`` (beside outputs that have no header, such as CSV).

    Parameters
    ----------
    folder : str or Path
    p : Provenance, optional
        Default: :func:`provenance` now.

    Returns
    -------
    Path
        The written file.
    """
    p = p or provenance()
    return atomic_write_text(Path(folder) / "provenance.json", json.dumps(asdict(p), indent=1))
