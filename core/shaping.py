"""Shaping the operator's command before it reaches the leader (``leader.u0_rise``, ``u0_shape``).

A human's command is piecewise: a key pressed, a stick pushed and released, written
``step(t - t_k)`` in a scenario. The followers' oracle feed-forward (η̈_i, and b̈_i
through η⃛_i) differentiates the leader's input twice along the observer flow, so a
jump in u0 reaches their torques as an impulse scaled by λ2/φ_i (docs/verification.md,
'Operator steps'). A ground station smooths the stick before it drives the vehicle;
here every ``step(x)`` of u0 becomes one of (x = t − t_k, T = ``u0_rise``):

- ``smoothstep``: ``smoothstep(x / T)``, 3s² − 2s³ over T seconds (C¹, slope ≤ 1.5/T);
- ``prefilter``: ``prefilter(x / T)``, 1 − (1 + s)e^(−s): the step through a critically
  damped second-order prefilter 1/(1 + T D)² with time constant T (C¹, slope ≤ 1/(eT));
- ``ramp``: a rate limit, ``(sat(2x/T − 1) + 1)/2``, linear over T seconds (C⁰ only).

Every shaped step is a convex blend of the values it moves between, so ‖u0‖ ≤ α still
holds where it held for the steps (the loader checks it again on the shaped command).

A u0 with a step and no ``u0_rise`` is shaped by :data:`DEFAULT_SHAPE` over
:data:`DEFAULT_RISE` seconds (:func:`default_rise`); a u0 without steps (the paper's
2 cos t) is left as written, and ``u0_rise = 0`` keeps the raw steps.
"""

from __future__ import annotations

from collections.abc import Iterable

from core.expression_tree import (
    BinOp,
    Call,
    Neg,
    Node,
    Num,
    Search,
    Time,
    Transformer,
    Visitor,
    visit,
)
from core.expressions import Expr
from core.faults import node_text

#: the shapes a step of u0 can be given (``leader.u0_shape``)
SHAPES = ("smoothstep", "prefilter", "ramp")
#: the shape of a stepped u0 that names none
DEFAULT_SHAPE = "smoothstep"
#: seconds over which a stepped u0 without ``leader.u0_rise`` is shaped (docs/verification.md,
#: 'Operator steps': the choice and the measurements behind it)
DEFAULT_RISE = 2.0
#: the atoms a shaped step is made of; each starts where its earliest kink is
_STEP_ATOMS = ("step", "smoothstep", "prefilter", "sat")


def has_steps(u0: Iterable[Expr]) -> bool:
    """Whether any component of u0 holds a ``step`` atom.

    Parameters
    ----------
    u0 : iterable of Expr
        The leader's command, one expression per input.
    """
    return any(visit(e.node, _Mentions("step")) for e in u0)


def default_rise(u0: Iterable[Expr]) -> float:
    """The ``leader.u0_rise`` of a u0 that gives none: :data:`DEFAULT_RISE` if it steps, else 0.

    Parameters
    ----------
    u0 : iterable of Expr
        The leader's command as written.
    """
    return DEFAULT_RISE if has_steps(u0) else 0.0


def shaped_steps(e: Expr, rise: float, shape: str = DEFAULT_SHAPE) -> Expr:
    """``e`` with every ``step(x)`` replaced by its shaped form (module docstring).

    Parameters
    ----------
    e : Expr
        An expression of t (one component of u0).
    rise : float
        Rise time (time constant for ``prefilter``) in seconds, > 0, for a step whose
        argument has slope 1 in t.
    shape : str
        One of :data:`SHAPES`.

    Returns
    -------
    Expr
        ``e`` itself when it holds no ``step``, else the shaped expression.
    """
    if shape not in SHAPES:
        raise ValueError(f"shape {shape!r} is not one of {SHAPES}")
    node = visit(e.node, _Shape(float(rise), shape))
    return e if node == e.node else Expr(node_text(node), node)


def step_onsets(u0: Iterable[Expr]) -> list[float]:
    """The times t > 0 at which a step of u0 starts, raw or shaped, sorted and distinct.

    Each ``step``, ``smoothstep``, ``prefilter`` or ``sat`` atom (a shaped step is one of
    them) starts at its earliest kink whose time is affine in t (:meth:`Expr.breakpoints`
    of the atom alone); atoms without such a kink contribute nothing.

    Parameters
    ----------
    u0 : iterable of Expr
        The leader's command (as the loader left it: shaped or not).
    """
    out: set[float] = set()
    for e in u0:
        for atom in visit(e.node, _ATOMS):
            kinks = Expr(node_text(atom), atom).breakpoints()
            if kinks:
                out.add(round(min(kinks), 12))
    return sorted(out)


class _Atoms(Visitor[list[Node]]):
    """The outermost step-like atoms of a tree (a shaped step's inner sat is its own)."""

    def num(self, node: Num) -> list[Node]:
        return []

    def time(self, node: Time) -> list[Node]:
        return []

    def neg(self, node: Neg) -> list[Node]:
        return visit(node.arg, self)

    def binop(self, node: BinOp) -> list[Node]:
        return visit(node.left, self) + visit(node.right, self)

    def call(self, node: Call) -> list[Node]:
        if node.name in _STEP_ATOMS:
            return [node]
        return [a for arg in node.args for a in visit(arg, self)]


_ATOMS = _Atoms()


class _Mentions(Search):
    """Whether a tree calls the function ``name``."""

    def __init__(self, name: str) -> None:
        self.name = name

    def call(self, node: Call) -> bool:
        return node.name == self.name or super().call(node)


class _Shape(Transformer):
    """A tree with every ``step(x)`` replaced by its shaped form over ``rise`` seconds."""

    def __init__(self, rise: float, shape: str) -> None:
        self.rise, self.shape = rise, shape

    def call(self, node: Call) -> Node:
        args = tuple(visit(a, self) for a in node.args)
        if node.name != "step":
            return Call(node.name, args)
        x = BinOp("/", args[0], Num(self.rise))
        if self.shape == "ramp":  # (sat(2x/T − 1) + 1)/2: 0 before, x/T on [0, T], 1 after
            inner = BinOp("-", BinOp("*", Num(2.0), x), Num(1.0))
            return BinOp("*", Num(0.5), BinOp("+", Call("sat", (inner,)), Num(1.0)))
        return Call(self.shape, (x,))
