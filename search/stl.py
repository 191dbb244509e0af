"""Signal temporal logic robustness over a run's logged signals (docs/search.md).

The fragment: comparisons of a signal with a constant (``x <= c``, ``x < c``, ``x >= c``,
``x > c``, also ``c >= x``), ``not``, ``and``, ``or``, ``always[a, b]`` and
``eventually[a, b]`` over time windows in seconds, and parentheses. Robustness follows the
quantitative semantics of RTAMT's discrete-time monitor (``tests/test_search_stl.py``
compares the two): ``x <= c`` has robustness ``c - x``, ``and`` is the minimum, ``or`` the
maximum, ``not`` the negation, ``always[a, b] phi`` at time t the minimum of ``phi`` over
the samples in ``[t + a, t + b]`` and ``eventually`` the maximum; a window reaching past
the last sample uses the samples it holds. A formula's robustness is its value at the
first sample: negative means violated.

A formula is bounded: at most :data:`MAX_CHARS` characters, :data:`MAX_ATOMS` comparisons
and :data:`MAX_DEPTH` nested operators (``not``, ``always``, ``eventually``, parentheses);
beyond these it is refused in one line, and ``and``/``or`` chains are one node however
long, so neither parsing nor evaluation recurses deeper than the nesting.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np


class FormulaError(ValueError):
    """A formula that does not parse or names an unknown signal (one line; the search
    file's loader reports it with the file and the field)."""


@dataclass(frozen=True)
class Node:
    """One node of a parsed formula.

    Attributes
    ----------
    op : str
        ``cmp``, ``not``, ``and``, ``or``, ``always``, ``eventually``.
    args : tuple
        ``cmp``: (signal, relation, constant, signal_on_left); temporal: (a, b, child);
        ``not``: (child,); ``and``/``or``: the operands of the chain, two or more.
    """

    op: str
    args: tuple


_TOKEN = re.compile(
    r"\s*(?:(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<name>[A-Za-z_]\w*)"
    r"|(?P<rel><=|>=|<|>)|(?P<punct>[()\[\],]))"
)
_TEMPORAL = {"always": "always", "G": "always", "eventually": "eventually", "F": "eventually"}
#: the bounds of a formula (module docstring)
MAX_CHARS = 100_000
MAX_ATOMS = 500
MAX_DEPTH = 50


def _tokens(text: str) -> list[tuple[str, str]]:
    out, pos = [], 0
    text = text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise FormulaError(f"unexpected character {text[pos:].strip()[:1]!r} at {pos + 1}")
        kind = m.lastgroup or ""
        out.append((kind, m.group(kind)))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, text: str, signals: frozenset[str]):
        self.toks, self.k, self.signals = _tokens(text), 0, signals
        self.depth = self.atoms = 0

    def peek(self) -> tuple[str, str] | None:
        return self.toks[self.k] if self.k < len(self.toks) else None

    def take(self, value: str | None = None, kind: str | None = None) -> str:
        tok = self.peek()
        if tok is None or (value is not None and tok[1] != value) or (kind and tok[0] != kind):
            want = repr(value) if value else (kind or "a term")
            got = "the end" if tok is None else repr(tok[1])
            raise FormulaError(f"expected {want}, found {got}")
        self.k += 1
        return tok[1]

    def formula(self) -> Node:
        node = self.disjunction()
        if self.peek() is not None:
            raise FormulaError(f"unexpected {self.peek()[1]!r} after a complete formula")
        return node

    def disjunction(self) -> Node:
        parts = [self.conjunction()]
        while self.peek() == ("name", "or"):
            self.take()
            parts.append(self.conjunction())
        return parts[0] if len(parts) == 1 else Node("or", tuple(parts))

    def conjunction(self) -> Node:
        parts = [self.unary()]
        while self.peek() == ("name", "and"):
            self.take()
            parts.append(self.unary())
        return parts[0] if len(parts) == 1 else Node("and", tuple(parts))

    def unary(self) -> Node:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise FormulaError(
                f"nested more than {MAX_DEPTH} levels deep (not, always, eventually, "
                "parentheses); write a shallower formula"
            )
        try:
            return self._unary()
        finally:
            self.depth -= 1

    def _unary(self) -> Node:
        tok = self.peek()
        if tok == ("name", "not"):
            self.take()
            return Node("not", (self.unary(),))
        if tok is not None and tok[0] == "name" and tok[1] in _TEMPORAL:
            self.take()
            self.take("[")
            a = float(self.take(kind="num"))
            self.take(",")
            b = float(self.take(kind="num"))
            self.take("]")
            if not 0 <= a <= b or not math.isfinite(b):
                raise FormulaError(f"{tok[1]}[{a:g}, {b:g}]: give 0 <= a <= b, finite")
            return Node(_TEMPORAL[tok[1]], (a, b, self.unary()))
        if tok == ("punct", "("):
            self.take()
            node = self.disjunction()
            self.take(")")
            return node
        return self.comparison()

    def comparison(self) -> Node:
        self.atoms += 1
        if self.atoms > MAX_ATOMS:
            raise FormulaError(f"more than {MAX_ATOMS} comparisons; write a shorter formula")
        left = self.operand()
        rel = self.take(kind="rel")
        right = self.operand()
        if (left[0] == "name") == (right[0] == "name"):
            raise FormulaError(f"{left[1]} {rel} {right[1]}: compare one signal with a number")
        signal, number = (left[1], right[1]) if left[0] == "name" else (right[1], left[1])
        c = float(number)
        if not math.isfinite(c):
            raise FormulaError(f"{signal} {rel} {number}: give a finite number")
        return Node("cmp", (signal, rel, c, left[0] == "name"))

    def operand(self) -> tuple[str, str]:
        tok = self.peek()
        if tok is None or tok[0] not in ("name", "num"):
            return ("", self.take(kind="num"))
        self.take()
        if tok[0] == "name" and tok[1] not in self.signals:
            raise FormulaError(
                f"unknown signal {tok[1]!r}: one of {', '.join(sorted(self.signals))}"
            )
        return tok


def parse(text: str, signals: frozenset[str] | set[str]) -> Node:
    """Parse a formula of the fragment.

    Parameters
    ----------
    text : str
        E.g. ``"always[10, 20](deviation <= 0.5)"``.
    signals : set of str
        The signal names the formula may use.

    Raises
    ------
    FormulaError
        One line naming what is wrong.
    """
    if not isinstance(text, str) or not text.strip():
        raise FormulaError("empty formula")
    if len(text) > MAX_CHARS:
        raise FormulaError(f"{len(text)} characters, above {MAX_CHARS}; write a shorter formula")
    return _Parser(text, frozenset(signals)).formula()


def signals_of(node: Node) -> set[str]:
    """The signal names a parsed formula uses.

    Parameters
    ----------
    node : Node
        From :func:`parse`.
    """
    if node.op == "cmp":
        return {node.args[0]}
    return set().union(*(signals_of(c) for c in node.args if isinstance(c, Node)))


def robustness(node: Node, t: np.ndarray, values: dict[str, np.ndarray]) -> float:
    """The formula's robustness at the first sample (negative: violated).

    Parameters
    ----------
    node : Node
        From :func:`parse`.
    t : ndarray
        Sample times, increasing.
    values : dict
        Signal name -> samples (same length as ``t``).
    """
    return float(trace(node, np.asarray(t, float), values)[0])


def trace(node: Node, t: np.ndarray, values: dict[str, np.ndarray]) -> np.ndarray:
    """The formula's robustness at every sample.

    Parameters
    ----------
    node : Node
        From :func:`parse`.
    t : ndarray
        Sample times, increasing.
    values : dict
        Signal name -> samples.
    """
    if node.op == "cmp":
        name, rel, c, signal_left = node.args
        x = np.asarray(values[name], float)
        below = (c - x) if signal_left else (x - c)  # signal <= c  /  c <= signal
        return below if rel in ("<=", "<") else -below
    if node.op == "not":
        return -trace(node.args[0], t, values)
    if node.op in ("and", "or"):
        f = np.minimum if node.op == "and" else np.maximum
        out = trace(node.args[0], t, values)
        for child in node.args[1:]:
            out = f(out, trace(child, t, values))
        return out
    a, b, child = node.args
    r = trace(child, t, values)
    lo = np.searchsorted(t, t + a - 1e-9 * max(1.0, b), side="left")
    hi = np.searchsorted(t, t + b + 1e-9 * max(1.0, b), side="right")
    return _window(r, lo, hi, node.op == "always")


def _window(r: np.ndarray, lo: np.ndarray, hi: np.ndarray, minimum: bool) -> np.ndarray:
    """min (or max) of r[lo[k]:hi[k]] for every k by a sparse table; an empty window
    (past the last sample) gives +inf for min and -inf for max."""
    x = r if minimum else -r
    table = [x]
    span = 1
    while 2 * span <= len(x):
        prev = table[-1]
        table.append(np.minimum(prev[:-span], prev[span:]))
        span *= 2
    out = np.full(len(lo), np.inf)
    n = hi - lo
    ok = n > 0
    level = np.zeros(len(lo), int)
    level[ok] = np.floor(np.log2(n[ok])).astype(int)
    for j in np.unique(level[ok]):
        sel = ok & (level == j)
        w = 1 << int(j)
        out[sel] = np.minimum(table[j][lo[sel]], table[j][hi[sel] - w])
    return out if minimum else -out
