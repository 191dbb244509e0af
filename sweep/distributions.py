"""Distributions over a scenario value, as a study file writes them.

A study's ``[params]``, operator parameters, link losses and fault keys each name one
distribution (``{ uniform = [15.0, 25.0] }``); :func:`distribution` reads and checks it,
:func:`sweep.sampler.draw` draws from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from sweep.study_fields import StudyError, join_key, read_integer, read_number, read_table

#: the distributions and the number of arguments each takes
KINDS = {"uniform": 2, "normal": 2, "choice": None, "integers": 2}


@dataclass(frozen=True)
class Distribution:
    """One distribution over a scenario value.

    Attributes
    ----------
    kind : str
        ``uniform`` (lo, hi), ``normal`` (mean, std), ``choice`` (values) or
        ``integers`` (lo, hi, both included).
    args : tuple
        The arguments of ``kind``.
    size : int or None
        None: one value; k: a list of k independent draws (e.g. a vector ``p0``).
    truncate : tuple of float or None
        ``normal`` only: draws restricted to [lo, hi].
    """

    kind: str
    args: tuple
    size: int | None = None
    truncate: tuple[float, float] | None = None


def distribution(f: str, spec: Any, where: str) -> Distribution:
    """Read one distribution table, e.g. ``{ uniform = [15.0, 25.0] }``.

    Parameters
    ----------
    f : str
        The study file (for messages).
    spec : Any
        The table from the file.
    where : str
        Its dotted key (for messages).

    Returns
    -------
    Distribution

    Raises
    ------
    StudyError
        Unknown or missing kind, wrong arguments, or an impossible distribution
        (lo > hi, std < 0, an empty choice, an empty truncation interval).
    """
    spec = read_table(f, spec, where, {*KINDS, "size", "truncate"})
    kinds = [k for k in spec if k in KINDS]
    if len(kinds) != 1:
        raise StudyError(
            f, where, f"names {len(kinds)} distributions", "exactly one of " + ", ".join(KINDS)
        )
    kind = kinds[0]
    key = join_key(where, kind)
    args = spec[kind]
    if not isinstance(args, list):
        raise StudyError(f, key, f"{args!r} is not a list", "a list of arguments")
    size = spec.get("size")
    if size is not None:
        size = read_integer(f, size, join_key(where, "size"), 1, 10_000)
    if kind == "choice":
        if not args:
            raise StudyError(f, key, "is empty", "at least one value to choose from")
        return Distribution(kind, tuple(args), size)
    if len(args) != 2:
        raise StudyError(f, key, f"has {len(args)} arguments", f"2 arguments: {_ARGS[kind]}")
    dist = _two_args(f, kind, key, args, size)
    if "truncate" in spec:
        return _truncated(f, dist, spec["truncate"], join_key(where, "truncate"))
    return dist


_ARGS = {"uniform": "[lo, hi]", "normal": "[mean, std]", "integers": "[lo, hi]"}


def _two_args(f: str, kind: str, key: str, args: list, size: int | None) -> Distribution:
    if kind == "integers":
        lo, hi = (read_integer(f, a, key, -(2**62), 2**62) for a in args)
    else:
        lo, hi = (read_number(f, a, key) for a in args)
    if kind == "normal" and hi < 0:
        raise StudyError(f, key, f"std = {hi:g} is negative", "std >= 0")
    if kind != "normal" and lo > hi:
        raise StudyError(f, key, f"lo = {lo:g} > hi = {hi:g}", "lo <= hi")
    if kind == "uniform" and not math.isfinite(hi - lo):
        raise StudyError(f, key, "hi - lo overflows to inf", "bounds whose difference is finite")
    return Distribution(kind, (lo, hi), size)


def _truncated(f: str, dist: Distribution, raw: Any, key: str) -> Distribution:
    if dist.kind != "normal":
        raise StudyError(f, key, f"applies to normal, not {dist.kind}", "truncate only on normal")
    if not isinstance(raw, list) or len(raw) != 2:
        raise StudyError(f, key, f"{raw!r} is not [lo, hi]", "a list [lo, hi]")
    lo, hi = (read_number(f, a, key) for a in raw)
    if not lo < hi:
        raise StudyError(f, key, f"lo = {lo:g} >= hi = {hi:g}", "lo < hi")
    if dist.args[1] == 0:
        raise StudyError(f, key, "std = 0 cannot be truncated", "std > 0, or no truncate")
    mean, std = dist.args
    if not all(math.isfinite((x - mean) / std) for x in (lo, hi)):
        raise StudyError(
            f, key, "(bound - mean) / std overflows to inf", "bounds within a finite number of std"
        )
    return Distribution(dist.kind, dist.args, dist.size, (lo, hi))


def scalar_distribution(f: str, raw: Any, key: str) -> Distribution:
    """A distribution of one number (no ``size``).

    Parameters
    ----------
    f : str
        The study file (for messages).
    raw : Any
        The table from the file.
    key : str
        Its dotted key (for messages).
    """
    d = distribution(f, raw, key)
    if d.size is not None:
        raise StudyError(f, join_key(key, "size"), "is given", "one number per draw (no size)")
    return d


def representative(d: Distribution) -> Any:
    """One value ``d`` can produce (lo, mean or the first choice); a list when sized.

    Parameters
    ----------
    d : Distribution
        The distribution.
    """
    v = d.args[0]
    if d.truncate is not None:
        v = min(max(v, d.truncate[0]), d.truncate[1])
    return v if d.size is None else [v] * d.size
