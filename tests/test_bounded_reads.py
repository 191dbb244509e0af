"""JSON read within limits (core/files.py): the nesting depth counted without parsing, and
the artifacts read back with it refused or ignored, never a ``RecursionError``."""

from __future__ import annotations

import json

import pytest
from helpers import PAPER
from hypothesis import given
from hypothesis import strategies as st

from core.files import FileRefused, json_depth, parse_json, read_json_file
from core.scenario import load_scenario
from generated.reuse import reuse_problem

JSON = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=30,
)


def _depth(v) -> int:
    """The nesting of a parsed value, recursively (the reference)."""
    if isinstance(v, list):
        return 1 + max((_depth(x) for x in v), default=0)
    if isinstance(v, dict):
        return 1 + max((_depth(x) for x in v.values()), default=0)
    return 0


@given(JSON, st.booleans())
def test_depth_without_parsing_equals_the_parsed_values(v, ascii_only):
    """Strings holding brackets, quotes and escapes do not count."""
    text = json.dumps(v, ensure_ascii=ascii_only).encode("utf-8")
    assert json_depth(text) == _depth(v)
    assert parse_json(text, _depth(v)) == v
    if _depth(v):
        with pytest.raises(FileRefused, match="levels deep"):
            parse_json(text, _depth(v) - 1)


def test_deep_and_bad_files(tmp_path):
    f = tmp_path / "x.json"
    f.write_text("[" * 200_000 + "]" * 200_000)
    with pytest.raises(FileRefused, match="nests 200000 levels deep"):
        read_json_file(f, 1 << 20, 32)
    with pytest.raises(FileRefused, match="above the limit of 100"):
        read_json_file(f, 100, 32)
    f.write_text('{"a": [1, 2}')
    with pytest.raises(ValueError):
        read_json_file(f, 1 << 20, 32)


def test_deep_meta_json_is_not_reused(tmp_path):
    (tmp_path / "meta.json").write_text("[" * 200_000)
    (tmp_path / "trajectory.csv").write_text("t\n0\n")
    assert reuse_problem(tmp_path, load_scenario(PAPER))[0] == "meta.json unreadable"
