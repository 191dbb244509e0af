"""Settings declared once: each dataclass field carries its file default and its checks.

A section of a scenario (``[observer]``, ``[integration]``, ...) is a frozen
dataclass whose fields are made by :func:`setting`. The field's metadata holds a
:class:`Setting`: the value a file may omit, how a TOML value is read (its
shape) and the range :class:`Check` objects. The loader reads a table by walking
these fields, :meth:`core.scenario.Scenario.validate` re-applies the same checks
to the values held, and ``tests/test_scenario_docs.py`` compares the tables of
``docs/scenario-format.md`` with them, so the default, the checks and the
documented type of a key have one owner.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

SYNTH = "synthesize"
#: the string of an optional feature that is off (held as None)
OFF = "none"

#: how a TOML value is read into the field (documented type words, without range);
#: ``{0}`` and ``{1}`` stand for the symbolic dimensions ``dims`` of the setting
SHAPES = {
    "number": "number",
    "integer": "whole number",
    "boolean": "boolean",
    "choice": "",  # rendered as the list of options
    "matrix": "matrix {0}×{1}",
    "vector": "list of {0} numbers",
    "per_follower": "per follower",
    "per_coordinate": "per follower and coordinate",
    "rows_m": "number, list of m, or N lists of m",
    "rows_n": "number, list of n, or N lists of n",
    # read by the loader's own parsers (names, expressions, health, paths, tables)
    "string": "string",
    "expressions": "list of {0} expressions of t",
    "expression_or_list": "expression, or list of {0} expressions",
    "health": "health (see *Actuator health*)",
    "numbers_table": "table of numbers",
    "table": "table",
    "tables": "array of tables",
}
_SCALAR_SHAPES = ("number", "integer", "boolean", "choice")
#: shapes whose range words follow the shape after a space ("number > 0"), not a comma
_SPACED_SHAPES = ("number", "integer", "vector")


@dataclass(frozen=True)
class Derived:
    """A default that is not one TOML value: it is made by the loader, or from the sizes.

    Attributes
    ----------
    text : str
        Its words in the default column of docs/scenario-format.md (``"zeros"``).
    of : callable or None
        The TOML value from the scenario's sizes (``{"m": 2, ...}``); None when the
        loader computes it from other keys (e.g. ``d`` from ``f``, ``name`` from the path).
    """

    text: str
    of: Callable[[Mapping[str, int]], Any] | None = None


def zeros(dim: str) -> Derived:
    """The default "zeros": a list of ``dim`` zeros (``dim`` is ``"m"``, ``"n"``, ...).

    Parameters
    ----------
    dim : str
        The symbolic size of the list.
    """
    return Derived("zeros", lambda sizes: [0.0] * sizes[dim])


#: the default of a key a file must give
REQUIRED = Derived("required")
#: the default of a key that is one of a pair a file must give exactly one of
EITHER = Derived("—")


@dataclass(frozen=True)
class Check:
    """A range rule on the numbers of one setting.

    Attributes
    ----------
    text : str
        Its words in the type column of docs/scenario-format.md (``"> 0"``); empty
        when the shape already says it.
    ok : callable
        Elementwise test on a float or an array of floats.
    problem, expected : str
        The error's two parts; ``problem`` is formatted with the offending value ``v``.
    """

    text: str
    ok: Callable[[Any], Any]
    problem: str
    expected: str

    def error(self, value: float) -> tuple[str, str]:
        """``(problem, expected)`` for the offending ``value``.

        Parameters
        ----------
        value : float
            The value that failed the check.
        """
        return self.problem.format(v=value), self.expected


POSITIVE = Check("> 0", lambda x: x > 0, "{v} is not positive", "a value > 0")
NONNEG = Check("≥ 0", lambda x: x >= 0, "{v} is negative", "a value >= 0")
WHOLE = Check(
    "",
    lambda x: (np.floor(x) == x) & (x <= 1e12),
    "{v!r} is not a whole number",
    "an integer <= 1e12",
)


@dataclass(frozen=True)
class Setting:
    """How one key of a section is read and checked.

    Attributes
    ----------
    default : object
        The value a file may omit, in its TOML form (``1.0``, ``"tanh"``, ``"synthesize"``).
    shape : str
        A key of :data:`SHAPES`: how the TOML value is read.
    checks : tuple of Check
        Range rules, applied in order to every number.
    options : tuple of str
        The allowed strings of a ``choice``.
    dims : tuple of str
        Symbolic shape of a ``matrix`` (``("p", "m")``).
    synth : bool
        The string ``"synthesize"`` is accepted and held as ``None``.
    off : bool
        The string ``"none"`` (the feature is off) is accepted and held as ``None``.
    """

    default: Any
    shape: str
    checks: tuple[Check, ...] = ()
    options: tuple[str, ...] = ()
    dims: tuple[str, str] = ("", "")
    synth: bool = False
    off: bool = False

    @property
    def keyword(self) -> str | None:
        """The string held as None (``"synthesize"`` or ``"none"``), if any."""
        return SYNTH if self.synth else OFF if self.off else None

    def type_text(self, rule_words: tuple[str, ...] = ()) -> str:
        """The type column of docs/scenario-format.md for this setting.

        Parameters
        ----------
        rule_words : tuple of str
            Words of the cross-field rules on this key (``"< delta1"``).
        """
        if self.shape == "choice":
            return ", ".join(f'"{o}"' for o in self.options)
        shape = SHAPES[self.shape].format(*self.dims)
        words = [c.text for c in self.checks if c.text] + list(rule_words)
        sep = " " if self.shape in _SPACED_SHAPES else ", "
        text = shape + (sep + ", ".join(words) if words else "")
        return text + f' or "{self.keyword}"' if self.keyword else text

    def default_for(self, sizes: Mapping[str, int]) -> Any:
        """The TOML value an omitted key takes, given the sizes known so far.

        Parameters
        ----------
        sizes : mapping
            The scenario's sizes by symbol (``"N"``, ``"n"``, ``"m"``, ``"p"``).
        """
        if isinstance(self.default, Derived):
            assert self.default.of is not None, "this default is computed by the loader"
            return self.default.of(sizes)
        return self.default

    def violation(self, value: Any) -> tuple[str, str, str] | None:
        """The first problem of a held ``value``: ``(index, problem, expected)``, or None.

        ``index`` is ``""`` for a scalar, else the 0-based position (``"[2][1]"``).

        Parameters
        ----------
        value : object
            The setting's value as the scenario holds it.
        """
        if value is None and self.keyword:
            return None
        if self.shape == "choice":
            if isinstance(value, str) and value in self.options:
                return None
            return "", f"{brief(value)} is not allowed", "one of " + ", ".join(self.options)
        if self.shape == "boolean":
            if isinstance(value, bool | np.bool_):
                return None
            return "", f"{brief(value)} is not a boolean", "true or false"
        return _number_violation(value, self.checks)


def _number_violation(value: Any, checks: tuple[Check, ...]) -> tuple[str, str, str] | None:
    """First non-finite or out-of-range entry of a number or an array of numbers."""
    if isinstance(value, bool | str):
        return "", f"{brief(value)} is not a number", "a finite number"
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return "", f"{brief(value)} is not a number", "a finite number"
    tests = [(np.isfinite, ("{v} is not finite", "a finite number"))]
    tests += [(c.ok, (c.problem, c.expected)) for c in checks]
    for ok, (problem, expected) in tests:
        mask = ~np.asarray(ok(arr), dtype=bool)
        if not mask.any():
            continue
        if arr.ndim == 0:
            return "", problem.format(v=float(arr)), expected
        idx = tuple(int(i) for i in np.argwhere(mask)[0])
        return "".join(f"[{i}]" for i in idx), problem.format(v=float(arr[idx])), expected
    return None


def setting(
    default: Any,
    shape: str,
    *checks: Check,
    options: tuple[str, ...] = (),
    dims: tuple[str, str] = ("", ""),
    synth: bool = False,
    off: bool = False,
) -> Any:
    """A dataclass field declared with its :class:`Setting`.

    Scalar settings also get ``default`` as the field's default value (``"synthesize"``
    and ``"none"`` become ``None``); per-follower settings have none (their value depends on N) and
    need ``kw_only`` sections.

    Parameters
    ----------
    default : object
        The TOML value a file may omit.
    shape : str
        A key of :data:`SHAPES`.
    *checks : Check
        Range rules, in order.
    options, dims, synth, off
        See :class:`Setting`.
    """
    if shape not in SHAPES:
        raise ValueError(f"unknown shape {shape!r}")
    s = Setting(default, shape, checks, options, dims, synth, off)
    meta = {"setting": s}
    if s.keyword is not None and default == s.keyword:
        return dataclasses.field(default=None, metadata=meta)
    if shape in _SCALAR_SHAPES:
        value = float(default) if shape == "number" else default
        return dataclasses.field(default=value, metadata=meta)
    return dataclasses.field(metadata=meta)


def declare(
    default: Any,
    shape: str,
    *checks: Check,
    dims: tuple[str, str] = ("", ""),
) -> Setting:
    """A :class:`Setting` of a table the loader reads key by key (``[leader]``, ...).

    Parameters
    ----------
    default : object
        The TOML value a file may omit, or a :class:`Derived` (:data:`REQUIRED`, ...).
    shape : str
        A key of :data:`SHAPES`.
    *checks : Check
        Range rules, in order.
    dims : tuple of str
        Symbolic sizes of a matrix, vector or list (``("m", "")``).
    """
    if shape not in SHAPES:
        raise ValueError(f"unknown shape {shape!r}")
    return Setting(default, shape, checks, dims=dims)


def required_keys(table: Mapping[str, Setting]) -> set[str]:
    """The keys of a declared table that a file must give.

    Parameters
    ----------
    table : mapping
        Key -> :class:`Setting`, e.g. :data:`core.scenario.LEADER`.
    """
    return {k for k, s in table.items() if s.default is REQUIRED}


def settings_of(cls: type) -> dict[str, Setting]:
    """The :class:`Setting` of every field of a section dataclass, in declaration order.

    Parameters
    ----------
    cls : type
        A dataclass whose fields were made by :func:`setting` (class or instance).
    """
    return {f.name: f.metadata["setting"] for f in dataclasses.fields(cls)}


def default_of(cls: type, name: str) -> Any:
    """The file default of setting ``name`` of section ``cls`` (one owner of each default).

    Parameters
    ----------
    cls : type
        A section dataclass, e.g. :class:`core.scenario.Integration`.
    name : str
        The key, e.g. ``"max_steps"``.
    """
    return settings_of(cls)[name].default


def brief(v: Any) -> str:
    """``repr`` of a user value, shortened so the message stays one readable line.

    Parameters
    ----------
    v : object
        The value a message quotes.
    """
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."
