"""The study benchmark's copy of a study: only the sample count changes, so the timed
samples are the study's own (same ids, same draws)."""

from __future__ import annotations

import tomllib

from helpers import ROOT

from benchmarks.study import _study_copy
from sweep.sampler import samples
from sweep.study import load_study

FAULTS = ROOT / "studies" / "faults.toml"


def test_copy_changes_only_the_count_and_draws_the_same_samples(tmp_path):
    copy = _study_copy(FAULTS, 1000, tmp_path)
    a, b = tomllib.loads(FAULTS.read_text()), tomllib.loads(copy.read_text())
    assert b["count"] == 1000 and b["faults"]["count"] == a["faults"]["count"]
    assert {k: v for k, v in b.items() if k not in ("count", "base")} == {
        k: v for k, v in a.items() if k not in ("count", "base")
    }
    original, copied = load_study(FAULTS), load_study(copy)
    assert copied.base == original.base and copied.count == 1000
    ids = [0, 7, 199]
    assert [s.params for s in samples(copied, ids)] == [s.params for s in samples(original, ids)]
