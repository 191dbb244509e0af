"""Generated reports carry their date, commit and machine (core/provenance.py)."""

from __future__ import annotations

import datetime as dt
import json
import subprocess

from helpers import ROOT

from core.provenance import (
    Provenance,
    current_commit,
    provenance,
    provenance_line,
    write_provenance,
)


def test_commit_is_the_checkouts_head():
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.strip()
    commit = current_commit()
    assert commit.removesuffix("+modified") == head[:12]


def test_provenance_is_now_and_here(tmp_path):
    before = dt.datetime.now(dt.UTC).replace(microsecond=0)
    p = provenance()
    after = dt.datetime.now(dt.UTC)
    assert before <= dt.datetime.fromisoformat(p.date) <= after
    assert "cores" in p.machine
    path = write_provenance(tmp_path, p)
    assert Provenance(**json.loads(path.read_text())) == p


def test_line_names_all_three():
    p = Provenance(date="2000-01-02T03:04:05+00:00", commit="0123456789ab", machine="M, 2 cores")
    assert (
        provenance_line(p) == "measured 2000-01-02T03:04:05+00:00, commit 0123456789ab, M, 2 cores"
    )
