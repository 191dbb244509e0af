"""The variant studies' plumbing shared by benchmarks.remedies and benchmarks.links."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT

from benchmarks import links, remedies
from benchmarks.variants import (
    Variant,
    chosen,
    guaranteed_counts,
    pair_counts,
    stat,
    study_variant,
)
from core.errors import UsageError


@pytest.mark.parametrize("name", ["steps.toml", "links.toml"])
def test_study_variant_reads_back_as_the_study_with_the_keys(name, tmp_path):
    study = ROOT / "studies" / name
    original = tomllib.loads(study.read_text(encoding="utf-8"))
    v = Variant("fade-0.5", {"graph.link_fade": 0.5, "a b": 'x"y'}, "a variant")
    data = tomllib.loads(study_variant(study, v, 3, tmp_path).read_text(encoding="utf-8"))
    assert data["count"] == 3 and data["name"] == f"{original['name']}-fade-0p5"
    assert data["set"] == {**original.get("set", {}), **v.keys}
    assert data["base"] == str((study.parent / original["base"]).resolve())
    rest = {k: x for k, x in data.items() if k not in ("count", "name", "set", "base")}
    assert rest == {k: x for k, x in original.items() if k not in ("count", "name", "set", "base")}


def test_chosen_keeps_the_order_and_names_an_unknown_variant():
    assert chosen(links.MODELS, None, "model") == list(links.MODELS)
    picked = chosen(remedies.REMEDIES, ["ramp-1", "raw"], "remedy")
    assert [r.name for r in picked] == ["raw", "ramp-1"]
    with pytest.raises(UsageError, match="--only bogus: unknown model; one of raw, fade-0.25"):
        chosen(links.MODELS, ["raw", "bogus"], "model")


def test_pooled_counts_by_hand():
    ok = pd.DataFrame(
        {
            "switch_pairs": [4, 3, np.nan],
            "switch_pairs_late": [1, 0, 0],
            "switch_pairs_undefined": [0, 2, 0],
            "n_guaranteed": [5, 5, 5],
            "guaranteed_failed": ["", "row a; row b", None],
        }
    )
    assert pair_counts(ok, "switch") == {"pairs": 7, "pairs_back": 4, "pairs_undefined": 2}
    assert pair_counts(ok, "step") == {"pairs": 0, "pairs_back": 0, "pairs_undefined": 0}
    assert guaranteed_counts(ok) == {"guaranteed_held": 13, "guaranteed_rows": 15}
    assert stat(np.array([3.0, np.nan, 1.0, 2.0]), "median") == 2.0
    assert stat(np.array([3.0, np.nan, 1.0]), "max") == 3.0
    assert math.isnan(stat(np.array([np.nan]), "max"))
