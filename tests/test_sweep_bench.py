"""The study benchmark's pure helpers: the copy of a study changes only the sample count
(same ids, same draws); the per-round ratios of the interleaved blocks and the split of the
scenario files between the two same-load loops hold their defining properties. Nothing is
timed here."""

from __future__ import annotations

import random
import tomllib
from pathlib import Path

import pytest
from helpers import ROOT

from benchmarks.catalogue import BenchError
from benchmarks.study import _study_copy, round_ratios, split_files
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


def test_round_ratio_is_the_slowdown_of_each_round_and_ignores_one_slow_first_task():
    rng = random.Random(3)
    slowdowns = [1.0, 1.3, 0.8, 2.5]
    lones = [[rng.uniform(0.1, 0.2) for _ in range(5)] for _ in slowdowns]
    tasks = [
        rng.sample([c * x for x in lo], len(lo)) for c, lo in zip(slowdowns, lones, strict=True)
    ]
    assert round_ratios(lones, tasks) == pytest.approx(slowdowns, rel=1e-12)
    # a worker's first task pays its imports: the slowest task made the first and much
    # slower moves no round's ratio
    slow_first = [[100.0, *sorted(t)[:-1]] for t in tasks]
    assert round_ratios(lones, slow_first) == pytest.approx(slowdowns, rel=1e-12)
    with pytest.raises(ValueError):
        round_ratios(lones, tasks[:-1])  # every round has both halves


@pytest.mark.parametrize("n", [2, 3, 10, 81])
def test_the_two_loops_get_disjoint_halves_of_the_files(n):
    files = [Path(f"s-{k:04d}.toml") for k in random.Random(n).sample(range(1000), n)]
    a, b = split_files(files, 2)
    assert a and b and not set(a) & set(b) and sorted(a + b) == sorted(files)
    assert abs(len(a) - len(b)) <= 1
    assert a == [f for f in files if f in a] and b == [f for f in files if f in b]  # order kept
    with pytest.raises(BenchError, match="--lone"):
        split_files(files[:1], 2)
