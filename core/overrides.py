"""``--set`` overrides of a scenario's fields: parsing, applying, naming the variant, loading.

Also the command-line knobs every command that takes a scenario shares
(:func:`add_scenario_knobs`, :func:`scenario_knobs`).

A scenario with overrides is a distinct scenario: its name gets a suffix
(``paper-ablation``; ``variant=`` chooses it) and its SHA-256 is that of the file
plus the overrides, so its gains, library and outputs never mix with the base run.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from core.errors import ScenarioError, UsageError
from core.files import FileRefused, read_regular_file
from core.model import MAX_SCENARIO_BYTES
from core.scenario import SECTIONS, TABLES, Scenario, load_scenario, scenario_from_dict

#: deepest nesting of arrays and inline tables a --set value may have (a scenario needs 3)
MAX_SET_DEPTH = 16
#: largest integer magnitude a value may have: TOML's own range (64-bit signed)
MAX_SET_INT = 2**63 - 1
#: longest variant label (the part after ``<name>-``); longer automatic labels are
#: shortened to a readable prefix and a hash, so out/<name>/ stays a short path component
MAX_VARIANT_CHARS = 60


def parse_override(text: str) -> tuple[str, Any]:
    """``"options.ablation=true"`` -> ``("options.ablation", True)`` (value read as TOML).

    A value that is not valid TOML is taken as a string (``integration.method=fixed``).

    Parameters
    ----------
    text : str
        ``KEY=VALUE`` as given to ``--set``.
    """
    if "=" not in text:
        raise ScenarioError(
            "--set", _brief_text(text), "is not KEY=VALUE", "e.g. options.ablation=true"
        )
    key, _, val = text.partition("=")
    key, val = key.strip(), val.strip()
    depth = _bracket_depth(val)
    if depth > MAX_SET_DEPTH:
        raise ScenarioError("--set", _brief_text(key), *_too_deep(depth))
    try:
        value = tomllib.loads(f"v = {val}")["v"]
    except tomllib.TOMLDecodeError:
        value = val
    except ValueError:  # an integer beyond Python's int-from-text digit limit
        raise ScenarioError("--set", _brief_text(key), *_too_long_int()) from None
    except RecursionError:  # unreachable below MAX_SET_DEPTH; kept as the last guard
        raise ScenarioError("--set", _brief_text(key), *_too_deep(depth)) from None
    _check_value("--set", key, value)
    return key, value


def _brief_text(text: str, limit: int = 60) -> str:
    """``text`` cut to ``limit`` characters for an error message."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _too_deep(depth: int) -> tuple[str, str]:
    return (
        f"value is nested {depth} levels deep",
        f"at most {MAX_SET_DEPTH} levels of [ ] and {{ }}",
    )


def _too_long_int() -> tuple[str, str]:
    return (
        "value has an integer beyond 64 bits",
        f"integers of magnitude <= {MAX_SET_INT} (19 digits); write large numbers as floats, "
        "e.g. 1e30",
    )


def _bracket_depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` in a TOML value, outside quoted strings."""
    depth = deepest = 0
    quote, escaped = "", False
    for c in text:
        if quote:
            if escaped:
                escaped = False
            elif c == "\\" and quote == '"':
                escaped = True
            elif c == quote:
                quote = ""
        elif c in "\"'":
            quote = c
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def _check_value(file: str, key: str, value: Any) -> None:
    """Refuse a value nested deeper than :data:`MAX_SET_DEPTH` or with a huge integer.

    Iterative, so that the check itself cannot exhaust the stack.
    """
    stack = [(value, 0)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, dict | list | tuple):
            if depth + 1 > MAX_SET_DEPTH:
                raise ScenarioError(file, _brief_text(key), *_too_deep(depth + 1))
            items = v.values() if isinstance(v, dict) else v
            stack.extend((x, depth + 1) for x in items)
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) > MAX_SET_INT:
            raise ScenarioError(file, _brief_text(key), *_too_long_int())


def set_path(data: dict, file: str, key: str, value: Any) -> None:
    """Set a dotted key (``options.ablation``, ``followers[2].g``; 1-based) in the raw TOML.

    Parameters
    ----------
    data : dict
        The scenario file's parsed TOML, changed in place.
    file : str
        The file's path, for error messages.
    key : str
        The dotted key, as ``--set`` takes it.
    value : object
        The new value.
    """
    parts = key.split(".")
    node: Any = data
    for k, part in enumerate(parts):
        m = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?", part)
        if not m:
            raise ScenarioError(file, key, "is not a dotted key", "e.g. options.ablation")
        name, index = m.group(1), m.group(2)
        last = k == len(parts) - 1 and index is None
        if last:
            node[name] = value
            return
        if name not in node:
            node[name] = {}
        node = node[name]
        if index is not None:
            i = int(index)
            if not isinstance(node, list) or not 1 <= i <= len(node):
                raise ScenarioError(file, key, f"index {i} is out of range", "a 1-based index")
            if k == len(parts) - 1:
                node[i - 1] = value
                return
            node = node[i - 1]
        if not isinstance(node, dict):
            raise ScenarioError(file, key, f"{part} is not a table", "a key into a table")


#: length of the SHA-256 prefix that ends a shortened or inexact automatic label
LABEL_HASH_CHARS = 10
#: characters of a scenario name (``core.scenario``'s name rule); the rest become ``-``
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")
#: string values that read as another type in a label (``x-true`` is ``x=true``)
_TYPED_WORDS = frozenset({"true", "false", "inf", "nan"})


def _section_leaves() -> dict[str, frozenset[str]]:
    """The keys of each plain table (``options``, ``leader``, ...): the unambiguous leaves."""
    tables = {s: frozenset(f.name for f in dataclasses.fields(t)) for s, t in SECTIONS.items()}
    tables.update({s: frozenset(TABLES[s]) for s in ("leader", "graph")})
    return tables


_LEAVES = _section_leaves()
#: every key name of the format: a string value equal to one could read as a key
_ALL_KEYS = frozenset().union(*_LEAVES.values(), *(frozenset(t) for t in TABLES.values()))


def _key_label(key: str) -> str:
    """``options.ablation`` -> ``ablation``; ``followers[2].faults`` -> ``followers2.faults``."""
    parts = key.split(".")
    if len(parts) == 2 and parts[1] in _LEAVES.get(parts[0], ()):
        return parts[1]
    return re.sub(r"\[(\d+)\]", r"\1", key)


def _value_label(value: Any) -> str:
    """The value as label text: ``''`` for true, numbers as Python writes them, else JSON."""
    if value is True:
        return ""
    if value is False:
        return "false"
    if isinstance(value, float):
        return repr(value).replace("+", "")
    if isinstance(value, str):
        return value
    return json.dumps(value, default=str, separators=(",", ":"))


def _exact(key: str, value: Any) -> bool:
    """Whether ``key-value`` in a label can be read back as this override and no other.

    True for a leaf of a plain table (unique across the format) with ``true``, ``false``,
    a finite number, or a word that is neither a key nor a TOML literal.
    """
    parts = key.split(".")
    if len(parts) != 2 or parts[1] not in _LEAVES.get(parts[0], ()):
        return False
    if isinstance(value, bool) or (isinstance(value, int) and not isinstance(value, bool)):
        return True
    if isinstance(value, float):
        return math.isfinite(value)
    return (
        isinstance(value, str)
        and re.fullmatch(r"[A-Za-z][A-Za-z0-9_.]*", value) is not None
        and value not in _ALL_KEYS
        and value.lower() not in _TYPED_WORDS
    )


def variant_label(overrides: Mapping[str, Any]) -> str:
    """Name suffix made from the overrides (``ablation``, ``method-fixed``).

    Every key, index and value is kept (sanitised to the name charset). A label that
    cannot be read back as exactly these overrides (a section's key path, a list, a
    string with other characters), or that is longer than :data:`MAX_VARIANT_CHARS`,
    ends in :data:`LABEL_HASH_CHARS` hex digits of the SHA-256 of the overrides'
    canonical text, so distinct overrides never share a folder.

    Parameters
    ----------
    overrides : Mapping
        ``--set`` key paths and their values, in the order given.

    Returns
    -------
    str
        The label (the run folder's suffix).
    """
    parts = []
    for k, v in overrides.items():
        text = _value_label(v)
        parts.append(_key_label(k) + (f"-{text}" if text else ""))
    label = _UNSAFE.sub("-", "-".join(parts)).strip("-.") or "variant"
    exact = all(_exact(k, v) for k, v in overrides.items())
    if exact and len(label) <= MAX_VARIANT_CHARS:
        return label
    digest = hashlib.sha256(_canonical(overrides).encode()).hexdigest()[:LABEL_HASH_CHARS]
    prefix = re.sub(r"-{2,}", "-", label)[: MAX_VARIANT_CHARS - LABEL_HASH_CHARS - 1].rstrip("-.")
    return f"{prefix}-{digest}" if prefix else digest


def _canonical(overrides: Mapping[str, Any]) -> str:
    """The overrides as canonical JSON (sorted keys): their identity in hashes."""
    return json.dumps({k: overrides[k] for k in sorted(overrides)}, sort_keys=True, default=str)


def load(
    path: str | Path,
    overrides: Mapping[str, Any] | None = None,
    variant: str | None = None,
) -> Scenario:
    """Load and validate a scenario, optionally with overrides of its fields.

    Parameters
    ----------
    path : str or Path
        The scenario TOML file.
    overrides : mapping, optional
        Dotted keys as in the file (``{"options.ablation": True}``,
        ``{"integration.method": "fixed"}``, ``{"followers[2].g": 0.5}``). The result
        is validated exactly like a file.
    variant : str, optional
        Name suffix of the overridden scenario (default: made from the keys, e.g.
        ``ablation``); the scenario is then called ``<name>-<variant>``.

    Returns
    -------
    Scenario
        With overrides, ``sha256`` is the SHA-256 of the file's hash and the overrides.
    """
    sc = load_scenario(path)
    if not overrides:
        return sc
    for k, v in overrides.items():  # programmatic overrides get the --set bounds too
        _check_value(str(path), k, v)
    if variant is not None and len(variant) > MAX_VARIANT_CHARS:
        raise ScenarioError(
            str(path),
            "variant",
            f"{_brief_text(variant)!r} has {len(variant)} characters",
            f"at most {MAX_VARIANT_CHARS} (it names the folder out/<name>-<variant>/)",
        )
    try:  # read again, as the loader read it: the file may have changed in between
        raw = read_regular_file(path, MAX_SCENARIO_BYTES)
        data = tomllib.loads(raw.decode("utf-8"))
    except (FileRefused, ValueError, RecursionError) as exc:
        raise ScenarioError(str(path), "(file)", f"changed while it was read ({exc})") from None
    for k, v in overrides.items():
        set_path(data, str(path), k, v)
    sha = hashlib.sha256((sc.sha256 + "\n" + _canonical(overrides)).encode()).hexdigest()
    # the loader's own validation, on the modified table
    out = scenario_from_dict(data, path=path, sha256=sha)
    label = variant if variant is not None else variant_label(overrides)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", label):
        raise ScenarioError(
            str(path), "variant", f"{_brief_text(label)!r} is not a plain name", "[A-Za-z0-9_.-]"
        )
    return dataclasses.replace(out, name=f"{sc.name}-{label}", sha256=sha)


def add_scenario_knobs(parser: argparse.ArgumentParser) -> None:
    """Give a command that takes a scenario ``--set KEY=VALUE`` (repeatable) and ``--variant``.

    The one definition every command line uses (``make ... SET=... VARIANT=...`` passes
    them); read them back with :func:`scenario_knobs`.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The (sub)command's parser.
    """
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario field (TOML value), e.g. options.ablation=true or "
        "'followers[2].g=0.5'; repeatable; the run goes to out/<name>-<variant>/",
    )
    parser.add_argument(
        "--variant",
        default=None,
        metavar="NAME",
        help="name suffix of the overridden run (default made from the overrides)",
    )


def scenario_knobs(
    args: argparse.Namespace, extra: Mapping[str, Any] | None = None
) -> tuple[dict[str, Any] | None, str | None]:
    """The overrides and variant of a command line made by :func:`add_scenario_knobs`.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed command line (``overrides``, ``variant``).
    extra : mapping, optional
        Overrides a flag of the command adds (``sim --ablation``).

    Returns
    -------
    (dict or None, str or None)
        The overrides (None when there are none) and the variant.

    Raises
    ------
    UsageError
        A key given twice, ``--variant`` without an override (it would name nothing), or
        a ``--variant`` that is not a plain name (empty, blanks, a slash).
    """
    pairs = [parse_override(s) for s in args.overrides] + list((extra or {}).items())
    overrides: dict[str, Any] = {}
    for key, value in pairs:
        if key in overrides:
            raise UsageError(f"--set: {_brief_text(key)} is given twice (give each key once)")
        overrides[key] = value
    if args.variant is not None and not re.fullmatch(r"[A-Za-z0-9_.-]+", args.variant):
        raise UsageError(
            f"--variant {_brief_text(args.variant)!r}: not a plain name (give letters, digits, "
            "'_', '.' or '-', or leave --variant out for a name made from the overrides)"
        )
    if args.variant is not None and not overrides:
        raise UsageError(
            f"--variant {_brief_text(args.variant)!r} without --set: a variant names an "
            "overridden run (give --set KEY=VALUE, or make SET='KEY=VALUE')"
        )
    return overrides or None, args.variant
