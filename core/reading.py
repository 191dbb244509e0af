"""The reading context of a scenario or study file: values checked as they are read.

:class:`ReadingContext` carries the file name into every error (one line naming the key
and the fix) and reads tables, numbers, vectors, matrices and expressions with their
checks; :class:`Dims` holds the sizes lists are checked against.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from core.errors import ExpressionError, ScenarioError
from core.expressions import Expr, parse_expression
from core.settings import (
    Check,
    brief,
)


class Dims(NamedTuple):
    """Sizes every list is checked against: followers, coordinates, leader states, inputs."""

    N: int
    n: int
    m: int
    p: int


class ReadingContext:
    """Carries the file name into every error."""

    def __init__(self, file: str) -> None:
        """A context for reading ``file``.

        Parameters
        ----------
        file : str
            The file named in errors.
        """
        self.file = file

    def err(self, key: str, problem: str, expected: str = "") -> ScenarioError:
        """The one-line error naming ``key``, what is wrong and what is expected.

        Parameters
        ----------
        key : str
            Its key in errors (``followers[1].p0``).
        problem : str
        expected : str
        """
        return ScenarioError(self.file, key, problem, expected)

    # -- structure
    def table(
        self, obj: Any, key: str, allowed: set[str], required: set[str] = frozenset()
    ) -> dict:
        """``obj`` as a table whose keys are ``allowed`` and include ``required``.

        Parameters
        ----------
        obj : object
        key : str
            Its key in errors (``followers[1].p0``).
        allowed : set of str
        required : set of str
        """
        if not isinstance(obj, dict):
            raise self.err(key, f"is a {type(obj).__name__}", "a table")
        for k in obj:
            if k not in allowed:
                raise self.err(
                    f"{key}.{k}" if key else k,
                    "unknown key",
                    "one of " + ", ".join(sorted(allowed)),
                )
        for k in sorted(required):
            if k not in obj:
                raise self.err(f"{key}.{k}" if key else k, "missing", "a value")
        return obj

    # -- numbers
    def number(self, v: Any, key: str, checks: tuple[Check, ...] = ()) -> float:
        """A finite number passing ``checks``.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        checks : tuple of Check
            Range rules, in order.
        """
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.err(key, f"{brief(v)} is not a number", "a finite number")
        try:
            x = float(v)
        except OverflowError:  # TOML integers are unbounded in tomllib
            x = math.inf
        if not math.isfinite(x):
            raise self.err(key, f"{brief(v)} is not finite", "a finite number")
        for c in checks:
            if not c.ok(x):
                raise self.err(key, *c.error(x))
        return x

    def matrix(self, v: Any, key: str, shape: tuple[int | None, int | None]) -> np.ndarray:
        """A finite matrix of ``shape``.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        shape : tuple of int or None
            Expected rows and columns (None: any).
        """
        want = f"a matrix of shape {_shape_txt(shape)}"
        if not isinstance(v, list) or not v or not all(isinstance(r, list) for r in v):
            raise self.err(key, "is not a list of rows", want)
        ncols = {len(r) for r in v}
        if len(ncols) != 1:
            raise self.err(key, "rows have different lengths", want)
        if 0 in ncols:
            raise self.err(key, "has empty rows", want)
        arr = np.array(
            [[self.number(x, f"{key}[{i}][{j}]") for j, x in enumerate(r)] for i, r in enumerate(v)]
        )
        for ax, size in enumerate(shape):
            if size is not None and arr.shape[ax] != size:
                raise self.err(
                    key, f"has shape {arr.shape[0]}x{arr.shape[1]}", f"shape {_shape_txt(shape)}"
                )
        arr.setflags(write=False)
        return arr

    def vector(
        self, v: Any, key: str, length: int | None, checks: tuple[Check, ...] = ()
    ) -> np.ndarray:
        """A finite vector (of ``length`` entries when given) passing ``checks``.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        length : int or None
        checks : tuple of Check
            Range rules, in order.
        """
        if not isinstance(v, list):
            raise self.err(
                key,
                f"{brief(v)} is not a list",
                f"a list of {length if length else 'some'} numbers",
            )
        if length is not None and len(v) != length:
            raise self.err(key, f"has {len(v)} entries", f"{length} entries")
        arr = np.array([self.number(x, f"{key}[{i}]", checks) for i, x in enumerate(v)])
        arr.setflags(write=False)
        return arr

    def per_agent(self, v: Any, key: str, N: int, checks: tuple[Check, ...] = ()) -> np.ndarray:
        """A scalar broadcast to N agents, or a list of N numbers.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        N : int
            Number of followers.
        checks : tuple of Check
            Range rules, in order.
        """
        if isinstance(v, list):
            return self.vector(v, key, N, checks)
        arr = np.full(N, self.number(v, key, checks))
        arr.setflags(write=False)
        return arr

    def per_agent_comp(
        self, v: Any, key: str, N: int, n: int, checks: tuple[Check, ...] = ()
    ) -> np.ndarray:
        """Scalar, list of N scalars, or list of N lists of n numbers -> N×n.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        N : int
            Number of followers.
        n : int
            Coordinates per follower.
        checks : tuple of Check
            Range rules, in order.
        """
        if not isinstance(v, list):
            arr = np.full((N, n), self.number(v, key, checks))
        else:
            if len(v) != N:
                raise self.err(
                    key, f"has {len(v)} entries", f"a scalar or {N} entries (one per follower)"
                )
            rows = []
            for i, x in enumerate(v):
                if isinstance(x, list):
                    rows.append(self.vector(x, f"{key}[{i}]", n, checks))
                else:
                    rows.append(np.full(n, self.number(x, f"{key}[{i}]", checks)))
            arr = np.array(rows)
        arr.setflags(write=False)
        return arr

    def choice(self, v: Any, key: str, options: tuple[str, ...]) -> str:
        """One of ``options``.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        options : tuple of str
        """
        if not isinstance(v, str) or v not in options:
            raise self.err(key, f"{brief(v)} is not allowed", "one of " + ", ".join(options))
        return v

    def boolean(self, v: Any, key: str) -> bool:
        """A TOML boolean.

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        """
        if not isinstance(v, bool):
            raise self.err(key, f"{brief(v)} is not a boolean", "true or false")
        return v

    def expr(self, v: Any, key: str) -> Expr:
        """An expression of t (core/expressions.py).

        Parameters
        ----------
        v : object
            The TOML value.
        key : str
            Its key in errors (``followers[1].p0``).
        """
        try:
            return parse_expression(v, where=f"{self.file}: {key}")
        except ExpressionError:
            raise
        except (ValueError, TypeError, RecursionError, MemoryError) as exc:  # never a traceback
            raise self.err(
                key, f"cannot parse expression ({type(exc).__name__})", "an expression of t"
            ) from None


def _shape_txt(shape: tuple[int | None, int | None]) -> str:
    return "x".join("?" if s is None else str(s) for s in shape)


def frozen_array(a: np.ndarray) -> np.ndarray:
    """A read-only copy of ``a`` (the scenario is immutable).

    Parameters
    ----------
    a : ndarray
    """
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a
