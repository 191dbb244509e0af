"""The one-line error of a study file and its typed values: tables, strings, numbers.

Every reader takes the file and the value's dotted key and raises :class:`StudyError`
naming both, the problem and the fix; the study, distribution and family readers are
built from them (:mod:`sweep.study`, :mod:`sweep.distributions`, :mod:`sweep.families`).
"""

from __future__ import annotations

import math
import re
from typing import Any

from core.errors import ScenarioError


class StudyError(ScenarioError):
    """A study file is malformed or asks for something impossible.

    Same one-line form as a scenario error: ``file: key: problem (expected fix)``.

    Parameters
    ----------
    file : str
        Path of the study file.
    key : str
        Dotted key of the offending field, e.g. ``params."controller.k1".uniform``.
    problem : str
        What is wrong.
    expected : str
        What is expected instead (the fix).
    """


def read_table(
    f: str, obj: Any, key: str, allowed: set[str], required: set[str] = frozenset()
) -> dict:
    """``obj`` as a table with only ``allowed`` keys and every ``required`` one.

    Parameters
    ----------
    f : str
        The study file (for messages).
    obj : Any
        The value read from the file.
    key : str
        Its dotted key ("" for the file's top table).
    allowed : set of str
        The keys the table may have.
    required : set of str
        The keys it must have.
    """
    if not isinstance(obj, dict):
        raise StudyError(f, key, f"is a {type(obj).__name__}", "a table")
    for k in obj:
        if k not in allowed:
            raise StudyError(
                f, join_key(key, k), "unknown key", "one of " + ", ".join(sorted(allowed))
            )
    for k in sorted(required):
        if k not in obj:
            raise StudyError(f, join_key(key, k), "missing", "a value")
    return obj


def join_key(key: str, k: str) -> str:
    """Dotted key ``key.k``; a sub-key that is itself dotted is quoted as in TOML.

    Parameters
    ----------
    key : str
        The parent's dotted key ("" at the top).
    k : str
        The sub-key.
    """
    sub = k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else f'"{k}"'
    return f"{key}.{sub}" if key else sub


def read_string(f: str, v: Any, key: str) -> str:
    """``v`` as a string.

    Parameters
    ----------
    f : str
        The study file (for messages).
    v : Any
        The value read from the file.
    key : str
        Its dotted key (for messages).
    """
    if not isinstance(v, str):
        raise StudyError(f, key, f"{v!r} is not a string", "a string")
    return v


def read_integer(f: str, v: Any, key: str, lo: int, hi: int) -> int:
    """``v`` as an integer in [lo, hi] (a boolean is not one).

    Parameters
    ----------
    f : str
        The study file (for messages).
    v : Any
        The value read from the file.
    key : str
        Its dotted key (for messages).
    lo, hi : int
        The range, both included.
    """
    if isinstance(v, bool) or not isinstance(v, int):
        raise StudyError(f, key, f"{v!r} is not an integer", f"an integer in [{lo}, {hi}]")
    if not lo <= v <= hi:
        raise StudyError(f, key, f"{v} is out of range", f"an integer in [{lo}, {hi}]")
    return v


def read_number(f: str, v: Any, key: str) -> float:
    """``v`` as a finite float (an integer is one, a boolean is not).

    Parameters
    ----------
    f : str
        The study file (for messages).
    v : Any
        The value read from the file.
    key : str
        Its dotted key (for messages).
    """
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(float(v)):
        raise StudyError(f, key, f"{v!r} is not a finite number", "a finite number")
    return float(v)
