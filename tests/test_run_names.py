"""Automatic run names keep every key, index and value, and never collide."""

from __future__ import annotations

import re

from hypothesis import given
from hypothesis import strategies as st

from core.overrides import MAX_VARIANT_CHARS, variant_label

KEYS = st.sampled_from(
    ["options.ablation", "integration.horizon", "integration.method", "observer.margin"]
) | st.from_regex(r"[a-z]{1,6}(\[[1-9]\])?(\.[a-z]{1,6}(\[[1-9]\])?){0,2}", fullmatch=True)
VALUES = st.recursive(
    st.booleans()
    | st.integers(-(2**63) + 1, 2**63 - 1)
    | st.floats(allow_nan=False)
    | st.text(max_size=20),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)
OVERRIDES = st.dictionaries(KEYS, VALUES, min_size=1, max_size=3)


def _plain(name: str) -> bool:
    return re.fullmatch(r"[A-Za-z0-9_.-]+", name) is not None and not name.startswith(".")


def test_indices_are_kept() -> None:
    fault = [{"type": "bias", "onset": 1.0}]
    a = variant_label({"followers[2].faults": fault})
    b = variant_label({"followers[3].faults": fault})
    assert a != b and "followers2" in a and "followers3" in b


def test_readable_names_stay() -> None:
    assert variant_label({"options.ablation": True}) == "ablation"
    assert variant_label({"integration.horizon": 0.2}) == "horizon-0.2"


@given(OVERRIDES, OVERRIDES)
def test_distinct_overrides_distinct_names(a: dict, b: dict) -> None:
    na, nb = variant_label(a), variant_label(b)
    assert _plain(na) and len(na) <= MAX_VARIANT_CHARS
    if a != b:
        assert na != nb
