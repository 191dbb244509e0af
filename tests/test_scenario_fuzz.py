"""Property-based: randomly mutated copies of scenarios/paper.toml never crash the loader.

Whatever the mutation (deleted keys, changed types, NaN/inf/huge/negative
values, truncated or nested lists, unknown keys, broken TOML syntax), only
the project's own error family (ToolkitError: ScenarioError/ExpressionError)
may escape :func:`load_scenario`; and a file that loads is a valid Scenario.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.errors import ToolkitError
from core.scenario import Scenario, load_scenario

ROOT = Path(__file__).resolve().parents[1]
PAPER_TEXT = (ROOT / "scenarios" / "paper.toml").read_text()
PAPER = tomllib.loads(PAPER_TEXT)


# --------------------------------------------------------------------------- a tiny TOML writer
def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are valid TOML basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps(doc: dict) -> str:
    """Every top-level key as ``"key" = <inline value>`` (valid TOML for any JSON-like doc)."""
    return "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in doc.items())


def test_writer_round_trips_the_paper_scenario():
    assert tomllib.loads(dumps(PAPER)) == PAPER


# --------------------------------------------------------------------------- mutations
def _paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path (tuple of keys/indices) into the document."""
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _paths(v, prefix + (i,))
    return out


def _get(obj: Any, path: tuple) -> Any:
    for k in path:
        obj = obj[k]
    return obj


WEIRD = st.one_of(
    st.sampled_from(
        [
            math.nan,
            math.inf,
            -math.inf,
            1e308,
            -1e308,
            1e-308,
            0,
            0.0,
            -1,
            -1.0,
            10**30,
            2**63 - 1,
            10**400,
            True,
            False,
            "",
            "synthesize",
            "t",
            "nan",
            "__import__('os')",
            "1" * 400,
            [],
            [[]],
            [[[1.0]]],
            {},
            {"x": 1},
            [1.0, "a"],
            "9**9**9",
            "exp(exp(t))",
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.text(max_size=12),
    st.lists(st.floats(min_value=-1e3, max_value=1e3), max_size=6),
)


@st.composite
def mutated(draw) -> str:
    doc = json.loads(json.dumps(PAPER))  # deep copy (the paper file has no NaN/inf)
    for _ in range(draw(st.integers(1, 4))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        kind = draw(
            st.sampled_from(["delete", "replace", "truncate", "nest", "unknown", "negate", "wrap"])
        )
        if not path:
            if kind == "unknown":
                doc[draw(st.text(min_size=1, max_size=8))] = draw(WEIRD)
            continue
        parent, last = _get(doc, path[:-1]), path[-1]
        value = parent[last]
        if kind == "delete":
            del parent[last]
        elif kind == "replace":
            parent[last] = draw(WEIRD)
        elif kind == "truncate" and isinstance(value, list | str):
            parent[last] = value[: draw(st.integers(0, max(len(value) - 1, 0)))]
        elif kind == "nest":
            parent[last] = [value]
        elif kind == "unknown" and isinstance(value, dict):
            value[draw(st.sampled_from(["extra", "Q", "A0", "g", "lambda", "x y"]))] = draw(WEIRD)
        elif kind == "negate" and isinstance(value, int | float) and not isinstance(value, bool):
            parent[last] = -value * draw(st.sampled_from([1, 1e300, 1e-300]))
        elif kind == "wrap" and isinstance(value, list) and value:
            parent[last] = value + value[:1]  # one entry too many
    return dumps(doc)


@st.composite
def broken_text(draw) -> str:
    """Character-level damage to the original file (breaks TOML syntax or changes a value)."""
    text = PAPER_TEXT
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(text)))
        op = draw(st.sampled_from(["cut", "insert", "truncate", "swap"]))
        if op == "cut":
            text = text[:i] + text[i + draw(st.integers(1, 20)) :]
        elif op == "insert":
            text = text[:i] + draw(st.sampled_from(list("[]{}=\"',.#\n-0e9xn"))) + text[i:]
        elif op == "truncate":
            text = text[:i]
        else:
            junk = ["nan", "inf", "-", "1e999", "[[", "9" * 5000, "[" * 3000 + "]" * 3000]
            text = text[:i] + draw(st.sampled_from(junk)) + text[i:]
    return text


def _check(tmp_path: Path, text: str) -> None:
    path = tmp_path / "mutant.toml"
    path.write_text(text)
    try:
        s = load_scenario(path)
    except ToolkitError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg and str(path) in msg
        return
    # it loaded: then it must be a consistent Scenario
    assert isinstance(s, Scenario)
    assert len(s.followers) == s.N == s.graph.adjacency.shape[0]
    assert all(0 < f.g.minimum <= 1 for f in s.followers)


@settings(
    max_examples=120,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(mutated())
def test_mutated_documents_only_raise_toolkit_errors(tmp_path, text):
    _check(tmp_path, text)


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(broken_text())
def test_damaged_text_only_raises_toolkit_errors(tmp_path, text):
    _check(tmp_path, text)
