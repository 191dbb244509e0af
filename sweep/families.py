"""A study's random families: graphs with link losses, faults, and operator inputs u0.

Each ``[graph]``, ``[faults]`` and ``[operator]`` table of a study file is read into a
frozen family (:func:`graph_family`, :func:`fault_family`, :func:`operator_family`);
:mod:`sweep.sampler` draws each sample's members of them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import ExpressionError
from core.expressions import CONSTANTS, FUNCTIONS, parse_expression
from core.faults import FAULT_TYPES
from sweep.distributions import Distribution, distribution, scalar_distribution
from sweep.study_fields import StudyError, join_key, read_integer, read_number, read_table

#: largest random graph (the adjacency is written densely into each sample's file)
MAX_GRAPH_N = 500
GRAPH_KEYS = {"N", "edge_probability", "weight", "losses"}
LOSS_KEYS = {"count", "time", "recovery", "pinning", "baseline", "reachable", "theorem1"}
#: what a sample's given gains owe its switched topologies (``[graph.losses] theorem1``)
THEOREM1_CHOICES = ("required", "measured")
#: the keys of [faults]: which, how many, and a distribution per fault key
FAULT_KEYS = {"count", "followers", "types", "onset", "severity", "duration", "period", "duty"}
FAULT_KEYS |= {"amplitude"}
#: most faults or link losses drawn per sample
MAX_DRAWN = 100
OPERATOR_KEYS = {"u0", "params", "traces"}
#: names an operator parameter may not take: the parser's own
RESERVED = {"t", *CONSTANTS, *FUNCTIONS}


@dataclass(frozen=True)
class LinkLosses:
    """Links of the drawn graph lost (weight 0) during the run, and perhaps restored.

    Attributes
    ----------
    count : tuple of int
        How many links each sample loses, drawn uniformly from [lo, hi].
    time : Distribution
        When each lost link goes (seconds).
    recovery : Distribution or None
        How long after its loss each link comes back with its weight; None: lost for good.
    pinning : bool
        Whether a leader link a_i0 may be drawn.
    baseline : bool
        Whether each sample is run a second time with its switches made no-ops (same
        compiled library), for the peak |u_i| without losses (:mod:`sweep.links`).
    reachable : bool
        Whether only losses that keep every follower reachable from the leader in every
        topology (Assumption 1) are drawn; otherwise such a sample is refused by the loader.
    theorem1 : str
        ``"required"``: a switched topology on which the sample's given λ1 fails Theorem 1
        refuses its gains (the sample fails), as for ``make sim``; ``"measured"``: the
        gains are certified on the base graph and the condition on every topology is a
        column of the row (:func:`sweep.switched_gains.topology_columns`).
    """

    count: tuple[int, int]
    time: Distribution
    recovery: Distribution | None
    pinning: bool = True
    baseline: bool = False
    reachable: bool = False
    theorem1: str = "required"


@dataclass(frozen=True)
class GraphFamily:
    """Random graphs with a directed spanning tree rooted at the leader.

    Attributes
    ----------
    n_range : tuple of int
        N is drawn uniformly from [lo, hi] (both included).
    edge_probability : float
        Probability of each extra edge j -> i beyond the spanning tree, in [0, 1].
    weight : float
        Weight a_ij of every edge and of the pinning, > 0.
    losses : LinkLosses or None
        Link losses (``[[graph.switches]]``) drawn on each sampled graph.
    """

    n_range: tuple[int, int]
    edge_probability: float
    weight: float = 1.0
    losses: LinkLosses | None = None


@dataclass(frozen=True)
class FaultFamily:
    """Faults of a random type on a random follower (``[[followers.faults]]`` tables).

    Attributes
    ----------
    count : tuple of int
        How many faults each sample gets, drawn uniformly from [lo, hi].
    followers : tuple of int or None
        The 1-based followers a fault may hit (each equally likely); None: every follower
        of the sample.
    types : tuple of str
        The fault types drawn from (each equally likely): ``abrupt``, ``ramp``,
        ``intermittent``, ``bias``.
    keys : dict
        Fault key (``onset``, ``severity``, ``duration``, ``period``, ``duty``,
        ``amplitude``) -> :class:`Distribution`; a fault draws the keys its type takes.
    """

    count: tuple[int, int]
    followers: tuple[int, ...] | None
    types: tuple[str, ...]
    keys: dict[str, Distribution]


@dataclass(frozen=True)
class OperatorFamily:
    """The operator input u0: expressions with sampled parameters, or a recorded trace.

    Attributes
    ----------
    u0 : tuple of str
        One expression per input, naming the parameters (``"A*cos(w*t + phi)"``); empty
        when ``traces`` is given.
    params : dict
        Parameter name -> :class:`Distribution` (one value each).
    traces : tuple of str
        Absolute paths of CSV traces, one chosen uniformly per sample.
    """

    u0: tuple[str, ...]
    params: dict[str, Distribution]
    traces: tuple[str, ...]


def graph_family(f: str, raw: Any) -> GraphFamily:
    """Read ``[graph]``: N or its range, the edge probability, the weight, the losses.

    Parameters
    ----------
    f : str
        The study file (for messages).
    raw : Any
        The ``[graph]`` table.
    """
    g = read_table(f, raw, "graph", GRAPH_KEYS, {"N", "edge_probability"})
    N = g["N"]
    if isinstance(N, list):
        if len(N) != 2:
            raise StudyError(f, "graph.N", f"{N!r} is not [lo, hi]", "an integer or [lo, hi]")
        lo, hi = (read_integer(f, n, "graph.N", 1, MAX_GRAPH_N) for n in N)
    else:
        lo = hi = read_integer(f, N, "graph.N", 1, MAX_GRAPH_N)
    if lo > hi:
        raise StudyError(f, "graph.N", f"lo = {lo} > hi = {hi}", "lo <= hi")
    p = read_number(f, g["edge_probability"], "graph.edge_probability")
    if not 0 <= p <= 1:
        raise StudyError(f, "graph.edge_probability", f"{p:g} is outside [0, 1]", "a probability")
    w = read_number(f, g.get("weight", 1.0), "graph.weight")
    if w <= 0:
        raise StudyError(f, "graph.weight", f"{w:g} is not positive", "a weight > 0")
    losses = _losses(f, g["losses"]) if "losses" in g else None
    return GraphFamily((lo, hi), p, w, losses)


def _count_range(f: str, v: Any, key: str) -> tuple[int, int]:
    """``count``: an integer or ``[lo, hi]`` in [0, MAX_DRAWN]."""
    if isinstance(v, list):
        if len(v) != 2:
            raise StudyError(f, key, f"{v!r} is not [lo, hi]", "an integer or [lo, hi]")
        lo, hi = (read_integer(f, n, key, 0, MAX_DRAWN) for n in v)
    else:
        lo = hi = read_integer(f, v, key, 0, MAX_DRAWN)
    if lo > hi:
        raise StudyError(f, key, f"lo = {lo} > hi = {hi}", "lo <= hi")
    return lo, hi


def _losses(f: str, raw: Any) -> LinkLosses:
    t = read_table(f, raw, "graph.losses", LOSS_KEYS, {"time"})
    pinning, baseline = t.get("pinning", True), t.get("baseline", False)
    reachable = t.get("reachable", False)
    for key, v in (("pinning", pinning), ("baseline", baseline), ("reachable", reachable)):
        if not isinstance(v, bool):
            raise StudyError(f, f"graph.losses.{key}", f"{v!r} is not a boolean", "true/false")
    theorem1 = t.get("theorem1", "required")
    if theorem1 not in THEOREM1_CHOICES:
        raise StudyError(
            f,
            "graph.losses.theorem1",
            f"{theorem1!r} is not a choice",
            " or ".join(THEOREM1_CHOICES),
        )
    rec = t.get("recovery")
    return LinkLosses(
        count=_count_range(f, t.get("count", 1), "graph.losses.count"),
        time=scalar_distribution(f, t["time"], "graph.losses.time"),
        recovery=None if rec is None else scalar_distribution(f, rec, "graph.losses.recovery"),
        pinning=pinning,
        baseline=baseline,
        reachable=reachable,
        theorem1=theorem1,
    )


def fault_family(f: str, raw: Any) -> FaultFamily:
    """Read ``[faults]``: how many, on which followers, of which types, each key's distribution.

    Every key a listed type takes must be given, and only those.

    Parameters
    ----------
    f : str
        The study file (for messages).
    raw : Any
        The ``[faults]`` table.
    """
    t = read_table(f, raw, "faults", FAULT_KEYS, {"onset"})
    followers = None
    if "followers" in t:
        v = t["followers"]
        if not isinstance(v, list) or not v:
            raise StudyError(f, "faults.followers", f"{v!r} is not a list", "1-based followers")
        followers = tuple(read_integer(f, x, "faults.followers", 1, MAX_GRAPH_N) for x in v)
    types = t.get("types", list(FAULT_TYPES))
    if not isinstance(types, list) or not types or not all(x in FAULT_TYPES for x in types):
        raise StudyError(
            f, "faults.types", f"{types!r} is not a list of fault types", ", ".join(FAULT_TYPES)
        )
    keys = {}
    for k in sorted(FAULT_KEYS - {"count", "followers", "types"}):
        if k in t:
            where = join_key("faults", k)
            keys[k] = (distribution if k == "amplitude" else scalar_distribution)(f, t[k], where)
    used = {k for ty in types for k in FAULT_TYPES[ty]}
    for k in keys:
        if k not in used:
            raise StudyError(f, join_key("faults", k), f"no type of {types} takes it", "remove it")
    for ty in types:
        for k in FAULT_TYPES[ty]:
            if k != "type" and k not in keys:
                raise StudyError(
                    f, join_key("faults", k), f"missing (a {ty} fault takes it)", "a distribution"
                )
    count = _count_range(f, t.get("count", 1), "faults.count")
    return FaultFamily(count, followers, tuple(dict.fromkeys(types)), keys)


def operator_family(f: str, path: Path, raw: Any) -> OperatorFamily:
    """Read ``[operator]``: expressions u0 with parameter distributions, or CSV traces.

    Parameters
    ----------
    f : str
        The study file (for messages).
    path : Path
        The study file (traces are relative to its folder).
    raw : Any
        The ``[operator]`` table.
    """
    op = read_table(f, raw, "operator", OPERATOR_KEYS)
    if ("u0" in op) == ("traces" in op):
        raise StudyError(
            f, "operator", "give exactly one of u0 and traces", "u0 = [...] or traces = [...]"
        )
    if "traces" in op:
        return OperatorFamily((), {}, _traces(f, path, op["traces"], "params" in op))
    u0 = op["u0"]
    if not isinstance(u0, list) or not u0 or not all(isinstance(e, str) for e in u0):
        raise StudyError(f, "operator.u0", f"{u0!r} is not a list of strings", "expressions of t")
    params = {}
    for name, spec in read_table(
        f, op.get("params", {}), "operator.params", set(op.get("params", {}))
    ).items():
        where = join_key("operator.params", name)
        if not re.fullmatch(r"[A-Za-z_]\w*", name) or name in RESERVED:
            raise StudyError(
                f, where, "is not a parameter name", "an identifier other than t, pi and functions"
            )
        if not any(re.search(rf"\b{name}\b", e) for e in u0):
            raise StudyError(f, where, "is not used in operator.u0", "a name the expressions use")
        params[name] = distribution(f, spec, where)
        if params[name].size is not None:
            raise StudyError(f, join_key(where, "size"), "is given", "one number per parameter")
    for k, e in enumerate(u0):
        try:  # every parameter replaced by 1: the family must parse
            parse_expression(substitute(e, dict.fromkeys(params, 1.0)), where=f"operator.u0[{k}]")
        except ExpressionError as exc:
            raise StudyError(
                f, f"operator.u0[{k}]", str(exc), "an expression of t and the params"
            ) from None
    return OperatorFamily(tuple(u0), params, ())


def _traces(f: str, path: Path, raw: Any, has_params: bool) -> tuple[str, ...]:
    if has_params:
        raise StudyError(f, "operator.params", "is given with traces", "params only with u0")
    if not isinstance(raw, list) or not raw or not all(isinstance(r, str) for r in raw):
        raise StudyError(f, "operator.traces", f"{raw!r} is not a list of paths", "CSV paths")
    out = []
    for k, rel in enumerate(raw):
        p = (path.parent / rel).resolve()
        if not p.is_file():
            raise StudyError(
                f,
                f"operator.traces[{k}]",
                f"{rel} does not exist",
                "a CSV file relative to the study",
            )
        out.append(str(p))
    return tuple(out)


def substitute(expression: str, values: dict[str, float]) -> str:
    """Write parameter values into an operator expression (``A`` -> ``(1.5)``).

    Parameters
    ----------
    expression : str
        E.g. ``"A*cos(w*t + phi)"``.
    values : dict
        Parameter name -> number.

    Returns
    -------
    str
        The expression with each whole-word name replaced by its value in parentheses.
    """
    for name, v in values.items():
        expression = re.sub(rf"\b{name}\b", f"({float(v)!r})", expression)
    return expression
