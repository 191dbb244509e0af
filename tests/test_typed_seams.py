"""The stage seams are typed: no ``Any`` anywhere in the fields of ``Built``, ``Gains``,
``Trajectory`` and the verification inputs (``CheckInput``, ``TrajectoryView``), down
through the TypedDicts and aliases they name (issue: typed contracts).

The walk resolves every annotation (``typing.get_type_hints``), its arguments, the fields
of TypedDicts and dataclasses it reaches and string aliases such as ``JSONValue``.
"""

from __future__ import annotations

import dataclasses
import re
import sys
import typing
from dataclasses import dataclass
from typing import Any, ForwardRef, TypedDict

import pytest

import core.json_types as jt
from generated.built import Built
from generated.values import Trajectory
from synthesis.gains import Gains
from verify.checks import CheckInput
from verify.signals import TrajectoryView


def _anys(hint: object, where: str, seen: set[str], ns: dict | None = None) -> list[str]:
    """Where ``Any`` occurs in ``hint`` (paths), following aliases and records once.

    Annotations are read as written (strings, under ``from __future__ import
    annotations``): ``Any`` as a word is a hit; each name in them that resolves in the
    defining module to a TypedDict, a dataclass or a string alias is walked in turn (names
    imported only for type checkers are classes of their own, outside this check).
    """
    ns = vars(jt) if ns is None else ns
    if hint is Any:
        return [where]
    if isinstance(hint, ForwardRef):
        hint = hint.__forward_arg__
    if isinstance(hint, str):
        found = [where] if re.search(r"\bAny\b", hint) else []
        for name in re.findall(r"[A-Za-z_][A-Za-z_0-9]*", hint):
            if name in ns and name not in seen and name != "Any":
                seen.add(name)
                found += _anys(ns[name], f"{where}:{name}", seen, ns)
        return found
    found = []
    if isinstance(hint, type) and (typing.is_typeddict(hint) or dataclasses.is_dataclass(hint)):
        mod = ns | vars(sys.modules[hint.__module__])
        for name, sub in _annotations(hint).items():
            found += _anys(sub, f"{where}.{name}", seen, mod)
    for k, arg in enumerate(typing.get_args(hint)):
        found += _anys(arg, f"{where}[{k}]", seen, ns)
    return found


def _annotations(cls: type) -> dict[str, object]:
    out: dict[str, object] = {}
    for base in reversed(cls.__mro__):
        out.update(getattr(base, "__annotations__", {}))
    return out


@pytest.mark.parametrize("cls", [Built, Gains, Trajectory, CheckInput, TrajectoryView])
def test_no_any_in_the_fields(cls):
    assert _anys(cls, cls.__name__, set(), vars(sys.modules[cls.__module__])) == []


def test_the_walk_finds_any_where_it_hides():
    # the check itself must be able to fail: Any nested in a list, a TypedDict, an alias
    class Inner(TypedDict):
        x: list[dict[str, Any]]

    @dataclass
    class Outer:
        a: int
        b: Inner
        c: list[tuple[int, Any]]

    hits = _anys(Outer, "Outer", set(), {"Inner": Inner})
    assert hits == ["Outer.b:Inner.x", "Outer.c"]
    assert _anys(jt.JSONObject, "JSONObject", set()) == []
