"""docs/scenario-format.md states what the loader does: every key, type and default.

The tables of the document are parsed and compared with the declarations the
loader reads (:mod:`core.settings` fields of the sections, the rules of
:data:`core.scenario.RULES`, the declared keys of the top level, ``[leader]``,
``[graph]`` and ``[[followers]]`` in :data:`core.scenario.TABLES`); a file that
omits every optional key must load with exactly the documented defaults.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from core import scenario as S
from core.models import REGISTRY
from core.settings import OFF, SYNTH, Derived, settings_of

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "scenario-format.md"


def doc_tables(text: str) -> dict[str, list[tuple[str, str, str]]]:
    """``{section: [(key, type, default), ...]}`` from the key/type/default/meaning tables."""
    tables: dict[str, list[tuple[str, str, str]]] = {}
    section = None
    for line in text.splitlines():
        if line.startswith("## "):
            m = re.match(r"## `\[{1,2}(\w+)\]{1,2}`", line)
            section = "top" if line == "## Top level" else (m.group(1) if m else None)
            continue
        if section is None or not line.startswith("| `"):
            continue
        cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        if len(cells) != 4:
            continue
        key = cells[0].strip("`").strip("[]")
        tables.setdefault(section, []).append((key, cells[1].replace("`", ""), cells[2]))
    return tables


def _toml(cell: str) -> object:
    return tomllib.loads(f"v = {cell.strip('`')}")["v"]


def _same(a: object, b: object) -> bool:
    return a == b and type(a) is type(b)


def _same_default(cell: str, declared: object) -> bool:
    """A documented default against a declared one: words for a derived one, else a value."""
    if isinstance(declared, Derived):
        return cell == declared.text
    return cell.startswith("`") and _same(_toml(cell), declared)


def mismatches(text: str) -> list[str]:
    """Every difference between the document's tables and the loader's declarations."""
    tables, out = doc_tables(text), []
    declared_tables = {
        section: settings_of(cls) for section, cls in {**S.SECTIONS, **S.OPTIONAL_SECTIONS}.items()
    }
    declared_tables.update(S.TABLES)
    for section, declared in declared_tables.items():
        rows = tables.get(section, [])
        if [r[0] for r in rows] != list(declared):
            out.append(f"[{section}] keys {[r[0] for r in rows]} != {list(declared)}")
        for key, typ, default in rows:
            if key not in declared:
                continue
            want = S.type_text(section, key)
            if typ != want:
                out.append(f"[{section}] {key}: type {typ!r}, declared {want!r}")
            if not _same_default(default, declared[key].default):
                out.append(
                    f"[{section}] {key}: default {default}, declared {declared[key].default!r}"
                )
    return out


def test_every_documented_key_type_and_default_is_the_declared_one():
    assert mismatches(DOC.read_text()) == []


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("| `delta1` | number > 0 | `0.5` |", "| `delta1` | number > 0 | `0.6` |"),  # default
        (
            "| `max_steps` | whole number > 0 | `200000` |",
            "| `max_steps` | number > 0 | `200000` |",
        ),
        ("| `sign_width` | number > 0 |", "| `sign_width` | number ≥ 0 |"),  # range
        ("| `feedforward` | boolean | `true` |", "| `feedforwards` | boolean | `true` |"),  # key
        ("| `p0` | list of n numbers | required |", "| `p0` | list of n numbers | zeros |"),
        ("| `q0` | list of n numbers | zeros |", "| `q0` | list of n numbers | required |"),
        ("| `g` | health (see *Actuator health*) | `1.0` |", "| `g` | health | `1.0` |"),
        ("(see *Actuator health*) | `1.0` |", "(see *Actuator health*) | `0.95` |"),
        ("| `f` | expression, or list of n expressions | `0.0` |", "| `f` | expression | `0` |"),
        ("| `pinning` | list of N numbers ≥ 0 |", "| `pinning` | list of N numbers |"),
        ("| `alpha` | number > 0 | required |", "| `alpha` | number > 0 | `1.0` |"),
        ('| `description` | string | `""` |', '| `desc` | string | `""` |'),
        ("| `u0_csv` | string | — |", "| `u0_csv` | string | required |"),
        ("| `eta0` | list of m numbers | zeros |", "| `eta0` | list of n numbers | zeros |"),
    ],
)
def test_a_drifted_document_is_caught(old, new):
    text = DOC.read_text()
    assert old in text
    assert mismatches(text.replace(old, new)), new


MINIMAL = """
[leader]
A0 = [[0, 1], [0, 0]]
B0 = [[0], [1]]
C0 = [[1, 0], [0, 1]]
u0 = ["cos(t)"]
alpha = 1
[graph]
adjacency = [[0, 0], [1, 0]]
pinning = [1, 0]
[[followers]]
model = "point_mass_2d"
p0 = [0, 0]
b0 = [1, 0]
[[followers]]
model = "point_mass_2d"
p0 = [1, 0]
b0 = [0, 1]
"""


def test_omitted_tables_take_the_documented_defaults(tmp_path):
    path = tmp_path / "minimal.toml"
    path.write_text(MINIMAL)
    sc = S.load_scenario(path)
    tables = doc_tables(DOC.read_text())
    for section in S.SECTIONS:
        obj = getattr(sc, section)
        for key, _, default in tables[section]:
            doc_value, held = _toml(default), getattr(obj, key)
            if doc_value in (SYNTH, OFF):  # held as None
                assert held is None, (section, key)
            elif isinstance(held, np.ndarray):
                assert held.shape[0] == sc.N and np.all(held == doc_value), (section, key)
            else:
                assert _same(held, doc_value), (section, key, held, doc_value)


def _documented_default(cell: str, sc: S.Scenario, fo: S.Follower, key: str) -> object:
    """The value a documented default cell means for ``fo`` of the minimal scenario."""
    if cell == "zeros":
        return np.zeros(sc.m if key == "eta0" else sc.n)
    if cell == "the model's defaults":
        return REGISTRY[fo.model].defaults  # independent of the loader: the model's own table
    if cell.startswith("sup |f_ir|"):
        return np.zeros(sc.n)  # f = 0 in the minimal file
    if cell == "file name without `.toml`":
        return "minimal"
    return _toml(cell)


def test_omitted_keys_of_leader_and_followers_take_the_documented_defaults(tmp_path):
    path = tmp_path / "minimal.toml"
    path.write_text(MINIMAL)
    sc = S.load_scenario(path)
    tables = doc_tables(DOC.read_text())
    fo = sc.followers[0]
    held = {
        ("top", "name"): sc.name,
        ("top", "description"): sc.description,
        ("leader", "eta0"): sc.leader.eta0,
        ("followers", "params"): fo.params,
        ("followers", "q0"): fo.q0,
        ("followers", "d"): fo.d,
    }
    for (section, key), value in held.items():
        cell = dict((k, d) for k, _, d in tables[section])[key]
        want = _documented_default(cell, sc, fo, key)
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, want), (section, key)
        else:
            assert value == want, (section, key, value, want)
    defaults = dict((k, d) for k, _, d in tables["followers"])
    ts = np.linspace(0.0, sc.integration.horizon, 101)
    for other in sc.followers:  # g and f as functions of time: the documented constants
        assert np.all(other.g.expr.numpy(ts) == _toml(defaults["g"]))
        assert all(np.all(e.numpy(ts) == _toml(defaults["f"])) for e in other.f)
