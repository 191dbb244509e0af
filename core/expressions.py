"""Whitelist parser for expressions of time in scenario files.

Operator inputs ``u0``, biases ``f_i`` and piecewise health ``g_i(t)`` are
written as text such as ``"4*sin(2*t) + 1"``. The text is parsed with
:mod:`ast` and walked node by node; only numbers, the name ``t``, the constant
``pi``, the operators ``+ - * / **`` and the functions listed in
:data:`FUNCTIONS` are accepted. Nothing is ever passed to ``eval``, ``exec``
or ``sympify``. A parsed :class:`Expr` is evaluated with a *backend*: CasADi
(symbolic, for the closed loop) or numpy (for the independent reference).
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from core.errors import ExpressionError
from core.expression_tree import (
    BinOp,
    Call,
    Neg,
    Node,
    Num,
    Search,
    Time,
    Visitor,
    Walker,
    visit,
)
from core.memo import MEMO

#: accepted function names and their arity
FUNCTIONS: dict[str, tuple[int, ...]] = {
    "sin": (1,),
    "cos": (1,),
    "tan": (1,),
    "exp": (1,),
    "log": (1,),
    "sqrt": (1,),
    "abs": (1,),
    "tanh": (1,),
    "atan2": (2,),
    "min": (2,),
    "max": (2,),
    "step": (1,),  # Heaviside: 1 for x >= 0, else 0
    "sat": (1,),  # clip to [-1, 1]
    "smoothstep": (1,),  # C¹ step: 0 for x <= 0, 3x² - 2x³ on (0, 1), 1 for x >= 1
    "prefilter": (1,),  # C¹ step: 0 for x <= 0, 1 - (1 + x)exp(-x) for x > 0
    "mod": (2,),  # floating remainder with the sign of x (C fmod)
}
CONSTANTS = {"pi": math.pi}
_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
MAX_LENGTH = 500
_UNSET = object()  # no value kept yet (Expr._kept)
MAX_DEPTH = 40


@dataclass(frozen=True)
class Expr:
    """A parsed expression of ``t``: its text and its immutable tree.

    ``node`` is a :data:`~core.expression_tree.Node` (:class:`~core.expression_tree.Num`,
    :class:`~core.expression_tree.Time`, :class:`~core.expression_tree.Neg`,
    :class:`~core.expression_tree.BinOp` or :class:`~core.expression_tree.Call`).
    """

    text: str
    node: Node

    def __hash__(self) -> int:
        # the dataclass hash of (text, node), remembered: hashing the tree visits every
        # node, and an Expr is a memo key asked for at every numpy evaluation
        h = self.__dict__.get("_hash")
        if h is None:
            h = hash((self.text, self.node))
            object.__setattr__(self, "_hash", h)
        return h

    def _kept(self, name: str, compute: Callable[[Expr], Any]) -> Any:
        """``compute(self)`` kept on this instance, like its hash: the process's memo (whose
        key lookup compares whole trees) is asked once per instance, not at every call."""
        value = self.__dict__.get(name, _UNSET)
        if value is _UNSET:
            value = compute(self)
            object.__setattr__(self, name, value)
        return value

    def __getstate__(self) -> dict[str, Any]:
        # the fields only: string hashes are salted per process, so a remembered hash
        # must not travel to a worker
        return {"text": self.text, "node": self.node}

    def casadi(self, t: Any, lits: Any = None) -> Any:
        """Evaluate with CasADi operations on a symbol or number ``t``.

        Parameters
        ----------
        t : casadi.SX or float
            Time.
        lits : casadi.SX or MX vector, optional
            Values for the literals, in the order of :meth:`literals`: the expression
            then depends on them instead of on its own numbers (runtime parameters).
        """
        if lits is None:
            return _eval(self.node, t, _CASADI)
        if lits.numel() != len(self.literals()):
            raise ExpressionError(
                f"{self.text!r}: {lits.numel()} literal values for {len(self.literals())} literals"
            )
        return _eval(self.node, t, _CASADI, iter([lits[k] for k in range(lits.numel())]))

    def literals(self) -> tuple[float, ...]:
        """The numbers of the expression in walk order, except literal exponents of ``**``.

        These are the expression's runtime parameters; what remains (:meth:`template`)
        is its structure. Exponents stay structure so ``t**2`` keeps CasADi's integer power.
        """
        return self._kept("_literals", _literals_of)

    def template(self) -> str:
        """The expression's structure: its tree with every literal written ``#``."""
        return self._kept("_template", _template_of)

    def numpy(self, t: Any) -> Any:
        """Evaluate with numpy on a float or array ``t`` (overflow gives inf/nan, no warning).

        Parameters
        ----------
        t : float or ndarray
            Time(s).
        """
        with np.errstate(all="ignore"):
            return self._kept("_numpy", _numpy_function)(np.asarray(t, dtype=float))

    def breakpoints(self) -> tuple[float, ...]:
        """Times t > 0 where the expression jumps or kinks, when the location is affine in t.

        ``step(x)`` and ``abs(x)`` at x = 0, ``sat(x)`` at x = ±1, ``min``/``max``
        where the arguments cross. Used to split an integration at known
        discontinuities; a non-affine argument contributes nothing.
        """
        return self._kept("_breakpoints", _breakpoints_of)

    def is_constant(self) -> bool:
        """True when the expression does not mention ``t``."""
        return not visit(self.node, _MENTIONS_T)


@MEMO.memoize("expression-literals", 1024)
def _literals_of(e: Expr) -> tuple[float, ...]:
    """:meth:`Expr.literals`, remembered (asked for at every binding of a study's sample to
    its compiled library). These caches are keyed by the whole :class:`Expr`, its text
    too: a tree alone would not tell 0.0 from -0.0, which Python's equality identifies."""
    walk = _Literals()
    visit(e.node, walk)
    return tuple(walk.out)


@MEMO.memoize("expression-templates", 1024)
def _template_of(e: Expr) -> str:
    """:meth:`Expr.template`, remembered (part of every structure key)."""
    return visit(e.node, _TEMPLATE)


@MEMO.memoize("expression-breakpoints", 1024)
def _breakpoints_of(e: Expr) -> tuple[float, ...]:
    """:meth:`Expr.breakpoints`, remembered: a scenario asks for the same expressions'
    breakpoints several times, and a study's samples share most trees."""
    walk = _Breaks()
    visit(e.node, walk)
    return tuple(sorted(set(walk.out)))


def parse_expression(text: Any, *, where: str = "expression") -> Expr:
    """Parse ``text`` into an :class:`Expr` through the whitelist.

    Parameters
    ----------
    text : str or number
        The expression; a bare number is accepted as a constant.
    where : str
        ``"file: key"`` used in error messages.

    Raises
    ------
    ExpressionError
        Naming ``where`` and the offending token.
    """
    if isinstance(text, bool):
        raise ExpressionError(
            f"{where}: a boolean is not an expression of t (expected e.g. '2*cos(t)')"
        )
    if isinstance(text, int | float):
        try:
            value = float(text)
        except OverflowError:  # an integer beyond the float range
            value = math.inf
        if not math.isfinite(value):
            raise ExpressionError(
                f"{where}: non-finite number {_short(str(text))} (expected a finite value)"
            )
        return Expr(repr(value), Num(value))
    if not isinstance(text, str):
        raise ExpressionError(
            f"{where}: {type(text).__name__} is not an expression "
            "(expected a string such as '2*cos(t)')"
        )
    if len(text) > MAX_LENGTH:
        raise ExpressionError(
            f"{where}: expression longer than {MAX_LENGTH} characters (expected a short formula)"
        )
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(
            f"{where}: cannot parse {_short(text)}: {exc.msg} "
            "(expected an expression of t such as '2*cos(t)')"
        ) from None
    except (ValueError, RecursionError, MemoryError):  # e.g. a NUL byte, absurd nesting
        raise ExpressionError(
            f"{where}: cannot parse {_short(text)} (expected an expression of t such as '2*cos(t)')"
        ) from None
    node = _convert(tree.body, text, where, 0)
    return Expr(text.strip(), node)


def _short(text: str) -> str:
    """``repr`` of the expression text, shortened so a message stays one readable line."""
    return repr(text if len(text) <= 80 else text[:77] + "...")


def _reject(where: str, text: str, token: str) -> ExpressionError:
    allowed = ", ".join(sorted(FUNCTIONS))
    return ExpressionError(
        f"{where}: {_short(text)}: token {token!r} is not allowed "
        f"(allowed: numbers, t, pi, + - * / **, and {allowed})"
    )


def _convert(n: ast.AST, text: str, where: str, depth: int) -> Node:
    if depth > MAX_DEPTH:
        raise ExpressionError(f"{where}: expression nested deeper than {MAX_DEPTH} levels")
    d = depth + 1
    if isinstance(n, ast.Constant):
        if isinstance(n.value, bool) or not isinstance(n.value, int | float):
            raise _reject(where, text, repr(n.value))
        try:
            v = float(n.value)
        except OverflowError:  # an integer literal beyond the float range
            v = math.inf
        if not math.isfinite(v):
            raise ExpressionError(
                f"{where}: {_short(text)}: number {_snippet(text, n)!r} is too large "
                "(expected a finite float)"
            )
        return Num(v)
    if isinstance(n, ast.Name):
        if n.id == "t":
            return Time()
        if n.id in CONSTANTS:
            return Num(CONSTANTS[n.id])
        raise _reject(where, text, n.id)
    if isinstance(n, ast.UnaryOp) and isinstance(n.op, ast.USub | ast.UAdd):
        inner = _convert(n.operand, text, where, d)
        if isinstance(n.op, ast.UAdd):
            return inner
        # A negative number is one literal, not structure: scenarios that differ only in
        # the sign of a number then share a compiled library.
        return Num(-inner.value) if isinstance(inner, Num) else Neg(inner)
    if isinstance(n, ast.BinOp) and type(n.op) in _BINOPS:
        return BinOp(
            _BINOPS[type(n.op)],
            _convert(n.left, text, where, d),
            _convert(n.right, text, where, d),
        )
    if isinstance(n, ast.Call):
        if not isinstance(n.func, ast.Name):
            raise _reject(where, text, _token(n.func, text))
        name = n.func.id
        if name not in FUNCTIONS:
            raise _reject(where, text, name)
        if n.keywords:
            raise _reject(where, text, n.keywords[0].arg or "**")
        if len(n.args) not in FUNCTIONS[name]:
            raise ExpressionError(
                f"{where}: {_short(text)}: {name} takes {FUNCTIONS[name][0]} argument(s), "
                f"got {len(n.args)} (expected e.g. {name}({', '.join(['t'] * FUNCTIONS[name][0])}))"
            )
        return Call(name, tuple(_convert(a, text, where, d) for a in n.args))
    raise _reject(where, text, _token(n, text))


_OP_TEXT = {
    ast.Mod: "%",
    ast.FloorDiv: "//",
    ast.MatMult: "@",
    ast.LShift: "<<",
    ast.RShift: ">>",
    ast.BitOr: "|",
    ast.BitXor: "^",
    ast.BitAnd: "&",
    ast.Not: "not",
    ast.Invert: "~",
}
_NODE_TEXT = {
    ast.Lambda: "lambda",
    ast.ListComp: "comprehension",
    ast.SetComp: "comprehension",
    ast.DictComp: "comprehension",
    ast.GeneratorExp: "comprehension",
    ast.IfExp: "if-else",
    ast.Compare: "comparison",
    ast.BoolOp: "and/or",
    ast.Subscript: "subscript [...]",
    ast.NamedExpr: ":=",
    ast.Starred: "*",
    ast.JoinedStr: "f-string",
}


def _token(n: ast.AST, text: str) -> str:
    """A short name for a rejected node: the operator or construct, never the whole text."""
    if isinstance(n, ast.Attribute):
        return "." + n.attr
    if isinstance(n, ast.BinOp | ast.UnaryOp):
        return _OP_TEXT.get(type(n.op), type(n.op).__name__)
    if type(n) in _NODE_TEXT:
        return _NODE_TEXT[type(n)]
    return _snippet(text, n) or type(n).__name__


def _snippet(text: str, n: ast.AST) -> str:
    seg = ast.get_source_segment(text.strip(), n) or ""
    return seg if len(seg) <= 30 else seg[:27] + "..."


class _MentionsT(Search):
    """Whether the tree mentions ``t`` (stops at the first ``t``)."""

    def time(self, node: Time) -> bool:
        return True


_MENTIONS_T = _MentionsT()


def _hermite(s: Any) -> Any:
    """3s² − 2s³: from 0 at s = 0 to 1 at s = 1 with zero slope at both ends."""
    return s * s * (3.0 - 2.0 * s)


def _critical(s: Any, exp: Callable[[Any], Any]) -> Any:
    """1 − (1 + s)e^(−s) for s ≥ 0: the unit step response of 1/(1 + D)² (D = d/ds).

    A critically damped second-order prefilter with time constant 1; zero value and
    slope at s = 0, slope s e^(−s) ≤ 1/e, approaching 1 without overshoot.
    """
    return 1.0 - (1.0 + s) * exp(-s)


class _Backend:
    def __init__(self, **ops: Any) -> None:
        self.__dict__.update(ops)


_CASADI = _Backend(
    sin=ca.sin,
    cos=ca.cos,
    tan=ca.tan,
    exp=ca.exp,
    log=ca.log,
    sqrt=ca.sqrt,
    abs=ca.fabs,
    tanh=ca.tanh,
    atan2=ca.atan2,
    min=ca.fmin,
    max=ca.fmax,
    step=lambda x: ca.if_else(x >= 0, 1.0, 0.0),
    sat=lambda x: ca.fmin(ca.fmax(x, -1.0), 1.0),
    smoothstep=lambda x: _hermite(ca.fmin(ca.fmax(x, 0.0), 1.0)),
    prefilter=lambda x: _critical(ca.fmax(x, 0.0), ca.exp),
    mod=ca.fmod,
)
_NUMPY = _Backend(
    sin=np.sin,
    cos=np.cos,
    tan=np.tan,
    exp=np.exp,
    log=np.log,
    sqrt=np.sqrt,
    abs=np.abs,
    tanh=np.tanh,
    atan2=np.arctan2,
    min=np.minimum,
    max=np.maximum,
    step=lambda x: np.where(np.asarray(x) >= 0, 1.0, 0.0),
    sat=lambda x: np.clip(x, -1.0, 1.0),
    smoothstep=lambda x: _hermite(np.clip(x, 0.0, 1.0)),
    prefilter=lambda x: _critical(np.maximum(x, 0.0), np.exp),
    mod=np.fmod,
)


def _literal_exponent(node: BinOp) -> float | None:
    """The number of ``x ** number`` (structure, not a literal), else None."""
    return node.right.value if node.op == "**" and isinstance(node.right, Num) else None


class _Literals(Walker):
    """Collects the numbers in walk order into ``out``, skipping literal exponents."""

    def __init__(self) -> None:
        self.out: list[float] = []

    def num(self, node: Num) -> None:
        self.out.append(node.value)

    def binop(self, node: BinOp) -> None:
        visit(node.left, self)
        if _literal_exponent(node) is None:
            visit(node.right, self)


class _Template(Visitor[str]):
    """The tree as text with every literal written ``#`` (literal exponents stay numbers)."""

    def num(self, node: Num) -> str:
        return "#"

    def time(self, node: Time) -> str:
        return "t"

    def neg(self, node: Neg) -> str:
        return f"(-{visit(node.arg, self)})"

    def binop(self, node: BinOp) -> str:
        e = _literal_exponent(node)
        right = visit(node.right, self) if e is None else repr(e)
        return f"({visit(node.left, self)}{node.op}{right})"

    def call(self, node: Call) -> str:
        return f"{node.name}({','.join(visit(a, self) for a in node.args)})"


_TEMPLATE = _Template()


class _Eval(Visitor[Any]):
    """The tree's value at ``t`` with the operations of backend ``be``; ``lits`` (an
    iterator) supplies the literals in walk order (left operand before right)."""

    def __init__(self, t: Any, be: _Backend, lits: Any = None) -> None:
        self.t, self.be, self.lits = t, be, lits

    def num(self, node: Num) -> Any:
        if self.lits is not None:
            return next(self.lits)
        return node.value + 0 * self.t if self.be is _NUMPY else node.value

    def time(self, node: Time) -> Any:
        return self.t

    def neg(self, node: Neg) -> Any:
        return -visit(node.arg, self)

    def binop(self, node: BinOp) -> Any:
        a = visit(node.left, self)
        e = _literal_exponent(node)
        b = visit(node.right, self) if e is None else e
        op = node.op
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        if op == "/":
            return a / b
        return a**b

    def call(self, node: Call) -> Any:
        args = [visit(a, self) for a in node.args]
        return getattr(self.be, node.name)(*args)


def _eval(node: Node, t: Any, be: _Backend, lits: Any = None) -> Any:
    """Evaluate ``node``; ``lits`` (an iterator) supplies the literals in walk order."""
    return visit(node, _Eval(t, be, lits))


@MEMO.memoize("expression-numpy", 1024)
def _numpy_function(e: Expr) -> Callable[[Any], Any]:
    """``e`` as nested numpy closures: the operations of :func:`_eval` with its numpy
    backend, in the same order (identical values), without walking the tree per call."""
    return visit(e.node, _CLOSURE)


class _Closure(Visitor[Callable[[Any], Any]]):
    """The tree as nested numpy closures of ``t`` (the operations of :class:`_Eval`)."""

    def num(self, node: Num) -> Callable[[Any], Any]:
        v = node.value
        return lambda t: v + 0 * t

    def time(self, node: Time) -> Callable[[Any], Any]:
        return lambda t: t

    def neg(self, node: Neg) -> Callable[[Any], Any]:
        f = visit(node.arg, self)
        return lambda t: -f(t)

    def binop(self, node: BinOp) -> Callable[[Any], Any]:
        fa = visit(node.left, self)
        e = _literal_exponent(node)
        if e is not None:
            return lambda t: fa(t) ** e
        return _BIN_CLOSURES[node.op](fa, visit(node.right, self))

    def call(self, node: Call) -> Callable[[Any], Any]:
        fn = getattr(_NUMPY, node.name)
        args = tuple(visit(a, self) for a in node.args)
        return lambda t: fn(*[g(t) for g in args])


_CLOSURE = _Closure()

_BIN_CLOSURES = {
    "+": lambda fa, fb: lambda t: fa(t) + fb(t),
    "-": lambda fa, fb: lambda t: fa(t) - fb(t),
    "*": lambda fa, fb: lambda t: fa(t) * fb(t),
    "/": lambda fa, fb: lambda t: fa(t) / fb(t),
    "**": lambda fa, fb: lambda t: fa(t) ** fb(t),
}


class _Breaks(Walker):
    """Collects into ``out`` the times t > 0 where a call jumps or kinks (affine locations)."""

    def __init__(self) -> None:
        self.out: list[float] = []

    def call(self, node: Call) -> None:
        super().call(node)  # the arguments' own breakpoints first
        name, args = node.name, node.args
        cand: list[Node]
        if name in ("step", "abs", "prefilter"):  # jump / kink / curvature jump where it is 0
            cand = [args[0]]
        elif name == "smoothstep":  # curvature jumps where the argument is 0 and 1
            cand = [args[0], BinOp("-", args[0], Num(1.0))]
        elif name == "sat":  # kinks where the argument is -1 and +1
            cand = [BinOp("-", args[0], Num(1.0)), BinOp("+", args[0], Num(1.0))]
        elif name in ("min", "max"):  # kink where the arguments cross
            cand = [BinOp("-", args[0], args[1])]
        else:
            cand = []
        for a in cand:
            root = _affine_root(a)
            if root is not None and root > 0:
                self.out.append(root)


def _affine_root(node: Node) -> float | None:
    """Zero of ``node`` if it is affine in t (checked at three points), else None."""
    try:
        with np.errstate(all="ignore"):
            f0, f1, f2 = (float(_eval(node, np.asarray(x), _NUMPY)) for x in (0.0, 1.0, 2.0))
    except (ValueError, ZeroDivisionError, OverflowError):
        return None
    slope = f1 - f0
    if not all(map(math.isfinite, (f0, f1, f2))) or abs(slope) < 1e-14:
        return None
    if abs((f2 - f1) - slope) > 1e-9 * max(1.0, abs(slope)):
        return None
    return -f0 / slope
