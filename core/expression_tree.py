"""The tree of a parsed expression of t: five small node classes and one visitor.

:func:`core.expressions.parse_expression` turns text into a tree of :data:`Node`:
:class:`Num` (a number), :class:`Time` (the name ``t``), :class:`Neg` (unary minus),
:class:`BinOp` (``+ - * / **``) and :class:`Call` (a function of
:data:`core.expressions.FUNCTIONS`). The fault library, the step shaping and the
piecewise health tables build such trees directly.

The nodes are frozen dataclasses: immutable, equal when their fields are equal, hashable
and picklable, so a tree (inside an :class:`~core.expressions.Expr`) is a memo key and
travels to worker processes. Equality is Python's on the numbers, so ``Num(0.0) ==
Num(-0.0)``; whoever keys a cache by a tree keys it by the expression's text too.

Every walk over a tree is a :class:`Visitor` subclass, one method per node class, run by
:func:`visit`. A method walks the children itself (``visit(node.left, self)``), so each
walk keeps its own order of evaluation and may stop early. Three bases give the common
walks their defaults: a :class:`Walker` visits every child left to right and returns
nothing (collectors override the nodes they collect), a :class:`Search` asks whether
some node matches and stops at the first (tests override the nodes that can match), a
:class:`Transformer` rebuilds the tree (rewrites override the nodes they change).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Generic, TypeAlias, TypeVar


@dataclass(frozen=True, slots=True)
class Num:
    """A number (a literal, or the constant ``pi``)."""

    value: float


@dataclass(frozen=True, slots=True)
class Time:
    """The time ``t``."""


@dataclass(frozen=True, slots=True)
class Neg:
    """``-arg`` (a negative number is a :class:`Num` of its own, not a ``Neg``)."""

    arg: Node


@dataclass(frozen=True, slots=True)
class BinOp:
    """``left op right`` with ``op`` one of ``+ - * / **``."""

    op: str
    left: Node
    right: Node


@dataclass(frozen=True, slots=True)
class Call:
    """``name(*args)``: a function of :data:`core.expressions.FUNCTIONS`."""

    name: str
    args: tuple[Node, ...]


#: a node of an expression tree
Node: TypeAlias = Num | Time | Neg | BinOp | Call

R = TypeVar("R")


class Visitor(ABC, Generic[R]):
    """One walk over an expression tree: a method per node class, each giving the result.

    A subclass implements all five methods (an incomplete one cannot be instantiated)
    and recurses by calling :func:`visit` on the children it wants, in the order it wants.
    """

    @abstractmethod
    def num(self, node: Num) -> R:
        """The result for a number.

        Parameters
        ----------
        node : Num
        """

    @abstractmethod
    def time(self, node: Time) -> R:
        """The result for ``t``.

        Parameters
        ----------
        node : Time
        """

    @abstractmethod
    def neg(self, node: Neg) -> R:
        """The result for ``-arg``.

        Parameters
        ----------
        node : Neg
        """

    @abstractmethod
    def binop(self, node: BinOp) -> R:
        """The result for ``left op right``.

        Parameters
        ----------
        node : BinOp
        """

    @abstractmethod
    def call(self, node: Call) -> R:
        """The result for ``name(*args)``.

        Parameters
        ----------
        node : Call
        """


#: the visitor method of each node class
METHODS: dict[type, str] = {Num: "num", Time: "time", Neg: "neg", BinOp: "binop", Call: "call"}


def visit(node: Node, visitor: Visitor[R]) -> R:
    """``visitor``'s method for the class of ``node``, applied to ``node``.

    Parameters
    ----------
    node : Node
        A tree (or subtree).
    visitor : Visitor
        The walk.

    Raises
    ------
    TypeError
        When ``node`` is not one of the node classes.
    """
    try:
        method = METHODS[type(node)]
    except KeyError:
        raise TypeError(
            f"{type(node).__name__} is not an expression node "
            f"(expected one of {', '.join(c.__name__ for c in METHODS)})"
        ) from None
    return getattr(visitor, method)(node)


class Walker(Visitor[None]):
    """A walk over every node, children left to right, returning nothing.

    Collectors subclass it and override the methods of the nodes they act on (calling
    the base method where the children are still to be walked).
    """

    def num(self, node: Num) -> None:
        """Nothing to walk.

        Parameters
        ----------
        node : Num
        """

    def time(self, node: Time) -> None:
        """Nothing to walk.

        Parameters
        ----------
        node : Time
        """

    def neg(self, node: Neg) -> None:
        """Walk the argument.

        Parameters
        ----------
        node : Neg
        """
        visit(node.arg, self)

    def binop(self, node: BinOp) -> None:
        """Walk the left operand, then the right.

        Parameters
        ----------
        node : BinOp
        """
        visit(node.left, self)
        visit(node.right, self)

    def call(self, node: Call) -> None:
        """Walk the arguments in order.

        Parameters
        ----------
        node : Call
        """
        for a in node.args:
            visit(a, self)


class Search(Visitor[bool]):
    """Whether some node of the tree matches, children left to right, stopping at the first.

    Tests subclass it and override the methods of the nodes that can match (calling the
    base method to search their children); no leaf matches by default.
    """

    def num(self, node: Num) -> bool:
        """No match.

        Parameters
        ----------
        node : Num
        """
        return False

    def time(self, node: Time) -> bool:
        """No match.

        Parameters
        ----------
        node : Time
        """
        return False

    def neg(self, node: Neg) -> bool:
        """Whether the argument matches.

        Parameters
        ----------
        node : Neg
        """
        return visit(node.arg, self)

    def binop(self, node: BinOp) -> bool:
        """Whether the left operand matches, else the right.

        Parameters
        ----------
        node : BinOp
        """
        return visit(node.left, self) or visit(node.right, self)

    def call(self, node: Call) -> bool:
        """Whether some argument matches, in order.

        Parameters
        ----------
        node : Call
        """
        return any(visit(a, self) for a in node.args)


class Transformer(Visitor[Node]):
    """A walk that rebuilds the tree: every node with its children transformed.

    Rewrites subclass it and override the methods of the nodes they change; the others
    come back as they were (leaves) or rebuilt from their transformed children.
    """

    def num(self, node: Num) -> Node:
        """The number itself.

        Parameters
        ----------
        node : Num
        """
        return node

    def time(self, node: Time) -> Node:
        """``t`` itself.

        Parameters
        ----------
        node : Time
        """
        return node

    def neg(self, node: Neg) -> Node:
        """``-arg`` of the transformed argument.

        Parameters
        ----------
        node : Neg
        """
        return Neg(visit(node.arg, self))

    def binop(self, node: BinOp) -> Node:
        """The operation on the transformed operands (left first).

        Parameters
        ----------
        node : BinOp
        """
        return BinOp(node.op, visit(node.left, self), visit(node.right, self))

    def call(self, node: Call) -> Node:
        """The call on the transformed arguments (in order).

        Parameters
        ----------
        node : Call
        """
        return Call(node.name, tuple(visit(a, self) for a in node.args))
