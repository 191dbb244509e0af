"""Study files: a base scenario, distributions over its fields, random graphs and operator inputs.

:func:`load_study` reads and completely validates a study file (docs/studies.md); every
problem is one line naming the file, the key and the fix (:class:`StudyError`).
"""

from __future__ import annotations

import copy
import hashlib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import ExpressionError, ScenarioError
from core.expressions import CONSTANTS, FUNCTIONS, parse_expression
from core.faults import FAULT_TYPES
from core.files import FileRefused, read_regular_file
from core.reading import ReadingContext
from core.scenario import MAX_SCENARIO_BYTES, load_scenario, scenario_from_dict, scenario_name
from generated.overrides import set_path
from sweep.graphs import random_graph, resize_followers

#: largest study file read (bytes)
MAX_STUDY_BYTES = 1 << 20
#: deepest nesting of tables and arrays in a study file (``[set.a.b]`` is depth 3)
MAX_DEPTH = 32
#: longest study name: sample names ``<name>-<id>`` stay within the scenario's 100
MAX_NAME = 40
#: most samples a study may ask for
MAX_COUNT = 1_000_000
#: largest random graph (the adjacency is written densely into each sample's file)
MAX_GRAPH_N = 500
#: the distributions and the number of arguments each takes
KINDS = {"uniform": 2, "normal": 2, "choice": None, "integers": 2}
TOP_KEYS = {
    "name",
    "description",
    "base",
    "count",
    "seed",
    "set",
    "params",
    "graph",
    "operator",
    "faults",
}
GRAPH_KEYS = {"N", "edge_probability", "weight", "losses"}
LOSS_KEYS = {"count", "time", "recovery", "pinning"}
#: the keys of [faults]: which, how many, and a distribution per fault key
FAULT_KEYS = {"count", "followers", "types", "onset", "severity", "duration", "period", "duty"}
FAULT_KEYS |= {"amplitude"}
#: most faults or link losses drawn per sample
MAX_DRAWN = 100
OPERATOR_KEYS = {"u0", "params", "traces"}
#: a ``--set`` key: dotted names, each with an optional 1-based [index]
KEY_PATTERN = r"[A-Za-z_]\w*(\[\d+\])?(\.[A-Za-z_]\w*(\[\d+\])?)*"
#: names an operator parameter may not take: the parser's own
RESERVED = {"t", *CONSTANTS, *FUNCTIONS}


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
    """

    count: tuple[int, int]
    time: Distribution
    recovery: Distribution | None
    pinning: bool = True


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


@dataclass(frozen=True)
class Study:
    """A validated study file.

    Attributes
    ----------
    name : str
        The study's name (default: the file's stem); samples are ``<name>-<id>``.
    path : str
        The study file.
    description : str
        Free text.
    base : str
        Absolute path of the base scenario.
    base_data : dict
        The base scenario's table (relative trace paths made absolute); not to be mutated.
    count : int
        Number of samples (ids 0 .. count - 1).
    seed : int
        The study's seed; sample k draws from a generator seeded by (seed, k).
    fixed : dict
        ``--set`` key -> value given to every sample (``[set]``), before any draw.
    params : dict
        ``--set`` key -> :class:`Distribution`, in file order.
    graph : GraphFamily or None
        Random graphs replacing the base's [graph], or None to keep it.
    operator : OperatorFamily or None
        The operator input family, or None to keep the base's u0.
    faults : FaultFamily or None
        Random faults added to the followers, or None.
    """

    name: str
    path: str
    description: str
    base: str
    base_data: dict
    count: int
    seed: int
    params: dict[str, Distribution]
    graph: GraphFamily | None
    operator: OperatorFamily | None
    fixed: dict[str, Any] = field(default_factory=dict)
    faults: FaultFamily | None = None


# --------------------------------------------------------------------------- reading
def load_study(path: str | Path) -> Study:
    """Load and completely validate a study file.

    Parameters
    ----------
    path : str or Path
        The study TOML file.

    Returns
    -------
    Study
        Frozen and validated: every distribution is possible, the graph family has
        spanning trees, the base scenario loads and every ``--set`` key applies to it.

    Raises
    ------
    StudyError
        One line naming the file, the key, the problem and the fix.
    """
    path = Path(path)
    data = _read_toml(path)
    f = str(path)
    _table(f, data, "", TOP_KEYS, {"base", "count", "seed"})
    base, base_data = _base(f, path, data["base"])
    study = Study(
        name=_name(f, data, path),
        path=f,
        description=_string(f, data.get("description", ""), "description"),
        base=base,
        base_data=base_data,
        count=_integer(f, data["count"], "count", 1, MAX_COUNT),
        seed=_integer(f, data["seed"], "seed", 0, 2**63 - 1),
        params=_params(f, data.get("params", {})),
        graph=_graph(f, data["graph"]) if "graph" in data else None,
        operator=_operator(f, path, data["operator"]) if "operator" in data else None,
        fixed=_fixed(f, data.get("set", {})),
        faults=_faults(f, data["faults"]) if "faults" in data else None,
    )
    _check_keys_apply(study)
    return study


def _read_toml(path: Path) -> dict:
    """The study file's table: a regular file of at most :data:`MAX_STUDY_BYTES`, UTF-8
    TOML nested at most :data:`MAX_DEPTH` deep."""
    f = str(path)
    try:
        raw = read_regular_file(path, MAX_STUDY_BYTES)
    except OSError as exc:
        raise StudyError(
            f, "(file)", f"cannot be read: {exc.strerror}", "an existing TOML file"
        ) from None
    except FileRefused as exc:
        raise StudyError(f, "(file)", str(exc), "a regular study file of at most 1 MiB") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, ValueError, RecursionError) as exc:
        raise StudyError(f, "(file)", f"malformed TOML: {exc}", "a valid TOML file") from None
    if _depth(data) > MAX_DEPTH:
        raise StudyError(
            f, "(file)", f"nests tables or arrays more than {MAX_DEPTH} deep", "a flatter file"
        )
    return data


def _depth(table: dict) -> int:
    """Nesting depth of the tables and arrays in ``table`` (``[set.a.b]`` is 3), without
    recursion."""
    deepest, stack = 0, [(v, 1) for v in table.values()]
    while stack:
        v, d = stack.pop()
        items = v.values() if isinstance(v, dict) else v if isinstance(v, list) else None
        if items is not None:
            deepest = max(deepest, d)
            stack.extend((x, d + 1) for x in items)
    return deepest


def _table(f: str, obj: Any, key: str, allowed: set[str], required: set[str] = frozenset()) -> dict:
    """``obj`` as a table with only ``allowed`` keys and every ``required`` one."""
    if not isinstance(obj, dict):
        raise StudyError(f, key, f"is a {type(obj).__name__}", "a table")
    for k in obj:
        if k not in allowed:
            raise StudyError(
                f, _join(key, k), "unknown key", "one of " + ", ".join(sorted(allowed))
            )
    for k in sorted(required):
        if k not in obj:
            raise StudyError(f, _join(key, k), "missing", "a value")
    return obj


def _join(key: str, k: str) -> str:
    """Dotted key ``key.k``; a sub-key that is itself dotted is quoted as in TOML."""
    sub = k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else f'"{k}"'
    return f"{key}.{sub}" if key else sub


def _string(f: str, v: Any, key: str) -> str:
    if not isinstance(v, str):
        raise StudyError(f, key, f"{v!r} is not a string", "a string")
    return v


def _integer(f: str, v: Any, key: str, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise StudyError(f, key, f"{v!r} is not an integer", f"an integer in [{lo}, {hi}]")
    if not lo <= v <= hi:
        raise StudyError(f, key, f"{v} is out of range", f"an integer in [{lo}, {hi}]")
    return v


def _number(f: str, v: Any, key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(float(v)):
        raise StudyError(f, key, f"{v!r} is not a finite number", "a finite number")
    return float(v)


def _name(f: str, data: dict, path: Path) -> str:
    """``name`` (default the file's stem): the scenario loader's rule for names, since it
    names the folder ``out/<name>/``, and at most :data:`MAX_NAME` characters."""
    name = data.get("name", path.stem)
    try:
        scenario_name(ReadingContext(f), {"name": name}, path)
    except ScenarioError as exc:
        raise StudyError(f, "name", exc.problem, exc.expected) from None
    if len(name) > MAX_NAME:
        raise StudyError(f, "name", f"has {len(name)} characters", f"at most {MAX_NAME}")
    return name


def _base(f: str, path: Path, v: Any) -> tuple[str, dict]:
    """The base scenario: must load; its relative trace path is made absolute."""
    rel = _string(f, v, "base")
    base = (path.parent / rel).resolve()
    if not base.exists():
        raise StudyError(
            f, "base", f"{rel} does not exist", "a scenario file relative to the study"
        )
    try:
        raw = read_regular_file(base, MAX_SCENARIO_BYTES)
    except (OSError, FileRefused) as exc:
        why = exc.strerror if isinstance(exc, OSError) else str(exc)
        raise StudyError(
            f, "base", f"{rel} {why}", "a scenario file relative to the study"
        ) from None
    try:
        load_scenario(base)
    except (ScenarioError, ExpressionError) as exc:
        raise StudyError(f, "base", f"the scenario is refused: {exc}", "a valid scenario") from None
    data = tomllib.loads(raw.decode("utf-8"))
    leader = data.get("leader", {})
    if "u0_csv" in leader:
        leader["u0_csv"] = str((base.parent / leader["u0_csv"]).resolve())
    return str(base), data


# --------------------------------------------------------------------------- distributions
def _params(f: str, raw: Any) -> dict[str, Distribution]:
    table = _table(f, raw, "params", set(raw) if isinstance(raw, dict) else set())
    out = {}
    for key, spec in table.items():
        where = _join("params", key)
        if not re.fullmatch(KEY_PATTERN, key):
            raise StudyError(f, where, "is not a dotted key", 'a --set key, e.g. "followers[2].p0"')
        out[key] = distribution(f, spec, where)
    return out


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
    spec = _table(f, spec, where, {*KINDS, "size", "truncate"})
    kinds = [k for k in spec if k in KINDS]
    if len(kinds) != 1:
        raise StudyError(
            f, where, f"names {len(kinds)} distributions", "exactly one of " + ", ".join(KINDS)
        )
    kind = kinds[0]
    key = _join(where, kind)
    args = spec[kind]
    if not isinstance(args, list):
        raise StudyError(f, key, f"{args!r} is not a list", "a list of arguments")
    size = spec.get("size")
    if size is not None:
        size = _integer(f, size, _join(where, "size"), 1, 10_000)
    if kind == "choice":
        if not args:
            raise StudyError(f, key, "is empty", "at least one value to choose from")
        return Distribution(kind, tuple(args), size)
    if len(args) != 2:
        raise StudyError(f, key, f"has {len(args)} arguments", f"2 arguments: {_ARGS[kind]}")
    dist = _two_args(f, kind, key, args, size)
    if "truncate" in spec:
        return _truncated(f, dist, spec["truncate"], _join(where, "truncate"))
    return dist


_ARGS = {"uniform": "[lo, hi]", "normal": "[mean, std]", "integers": "[lo, hi]"}


def _two_args(f: str, kind: str, key: str, args: list, size: int | None) -> Distribution:
    if kind == "integers":
        lo, hi = (_integer(f, a, key, -(2**62), 2**62) for a in args)
    else:
        lo, hi = (_number(f, a, key) for a in args)
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
    lo, hi = (_number(f, a, key) for a in raw)
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


# --------------------------------------------------------------------------- graph, operator
def _graph(f: str, raw: Any) -> GraphFamily:
    g = _table(f, raw, "graph", GRAPH_KEYS, {"N", "edge_probability"})
    N = g["N"]
    if isinstance(N, list):
        if len(N) != 2:
            raise StudyError(f, "graph.N", f"{N!r} is not [lo, hi]", "an integer or [lo, hi]")
        lo, hi = (_integer(f, n, "graph.N", 1, MAX_GRAPH_N) for n in N)
    else:
        lo = hi = _integer(f, N, "graph.N", 1, MAX_GRAPH_N)
    if lo > hi:
        raise StudyError(f, "graph.N", f"lo = {lo} > hi = {hi}", "lo <= hi")
    p = _number(f, g["edge_probability"], "graph.edge_probability")
    if not 0 <= p <= 1:
        raise StudyError(f, "graph.edge_probability", f"{p:g} is outside [0, 1]", "a probability")
    w = _number(f, g.get("weight", 1.0), "graph.weight")
    if w <= 0:
        raise StudyError(f, "graph.weight", f"{w:g} is not positive", "a weight > 0")
    losses = _losses(f, g["losses"]) if "losses" in g else None
    return GraphFamily((lo, hi), p, w, losses)


def _count_range(f: str, v: Any, key: str) -> tuple[int, int]:
    """``count``: an integer or ``[lo, hi]`` in [0, MAX_DRAWN]."""
    if isinstance(v, list):
        if len(v) != 2:
            raise StudyError(f, key, f"{v!r} is not [lo, hi]", "an integer or [lo, hi]")
        lo, hi = (_integer(f, n, key, 0, MAX_DRAWN) for n in v)
    else:
        lo = hi = _integer(f, v, key, 0, MAX_DRAWN)
    if lo > hi:
        raise StudyError(f, key, f"lo = {lo} > hi = {hi}", "lo <= hi")
    return lo, hi


def _scalar_distribution(f: str, raw: Any, key: str) -> Distribution:
    """A distribution of one number (no ``size``)."""
    d = distribution(f, raw, key)
    if d.size is not None:
        raise StudyError(f, _join(key, "size"), "is given", "one number per draw (no size)")
    return d


def _losses(f: str, raw: Any) -> LinkLosses:
    t = _table(f, raw, "graph.losses", LOSS_KEYS, {"time"})
    pinning = t.get("pinning", True)
    if not isinstance(pinning, bool):
        raise StudyError(f, "graph.losses.pinning", f"{pinning!r} is not a boolean", "true/false")
    rec = t.get("recovery")
    return LinkLosses(
        count=_count_range(f, t.get("count", 1), "graph.losses.count"),
        time=_scalar_distribution(f, t["time"], "graph.losses.time"),
        recovery=None if rec is None else _scalar_distribution(f, rec, "graph.losses.recovery"),
        pinning=pinning,
    )


# --------------------------------------------------------------------------- set, faults
def _fixed(f: str, raw: Any) -> dict[str, Any]:
    """``[set]``: dotted ``--set`` key -> the value every sample gets."""
    table = _table(f, raw, "set", set(raw) if isinstance(raw, dict) else set())
    for key in table:
        if not re.fullmatch(KEY_PATTERN, key):
            raise StudyError(
                f, _join("set", key), "is not a dotted key", 'a --set key, e.g. "options.sign"'
            )
    return dict(table)


def _faults(f: str, raw: Any) -> FaultFamily:
    t = _table(f, raw, "faults", FAULT_KEYS, {"onset"})
    followers = None
    if "followers" in t:
        v = t["followers"]
        if not isinstance(v, list) or not v:
            raise StudyError(f, "faults.followers", f"{v!r} is not a list", "1-based followers")
        followers = tuple(_integer(f, x, "faults.followers", 1, MAX_GRAPH_N) for x in v)
    types = t.get("types", list(FAULT_TYPES))
    if not isinstance(types, list) or not types or not all(x in FAULT_TYPES for x in types):
        raise StudyError(
            f, "faults.types", f"{types!r} is not a list of fault types", ", ".join(FAULT_TYPES)
        )
    keys = {}
    for k in sorted(FAULT_KEYS - {"count", "followers", "types"}):
        if k in t:
            where = _join("faults", k)
            keys[k] = (distribution if k == "amplitude" else _scalar_distribution)(f, t[k], where)
    used = {k for ty in types for k in FAULT_TYPES[ty]}
    for k in keys:
        if k not in used:
            raise StudyError(f, _join("faults", k), f"no type of {types} takes it", "remove it")
    for ty in types:
        for k in FAULT_TYPES[ty]:
            if k != "type" and k not in keys:
                raise StudyError(
                    f, _join("faults", k), f"missing (a {ty} fault takes it)", "a distribution"
                )
    count = _count_range(f, t.get("count", 1), "faults.count")
    return FaultFamily(count, followers, tuple(dict.fromkeys(types)), keys)


def _operator(f: str, path: Path, raw: Any) -> OperatorFamily:
    op = _table(f, raw, "operator", OPERATOR_KEYS)
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
    for name, spec in _table(
        f, op.get("params", {}), "operator.params", set(op.get("params", {}))
    ).items():
        where = _join("operator.params", name)
        if not re.fullmatch(r"[A-Za-z_]\w*", name) or name in RESERVED:
            raise StudyError(
                f, where, "is not a parameter name", "an identifier other than t, pi and functions"
            )
        if not any(re.search(rf"\b{name}\b", e) for e in u0):
            raise StudyError(f, where, "is not used in operator.u0", "a name the expressions use")
        params[name] = distribution(f, spec, where)
        if params[name].size is not None:
            raise StudyError(f, _join(where, "size"), "is given", "one number per parameter")
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


# --------------------------------------------------------------------------- keys apply
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


def _check_keys_apply(study: Study) -> None:
    """Every ``[set]`` and ``[params]`` key applies to the base (resized to the smallest N)
    and names a field; every fault type of ``[faults]`` is accepted with representative values.

    Other refusals of the loader depend on the drawn values and are reported per sample.
    """
    data = copy.deepcopy(study.base_data)
    if study.graph is not None:
        A, b = random_graph(
            study.graph.n_range[0], 0.0, study.graph.weight, np.random.default_rng(0)
        )
        data["graph"] = {"adjacency": A.tolist(), "pinning": b.tolist()}
        resize_followers(data, study.graph.n_range[0])
    _apply(study, data, "set", study.fixed)
    fixed = copy.deepcopy(data)
    _apply(study, data, "params", {k: representative(d) for k, d in study.params.items()})
    _check_unknown(study, data)
    if study.faults is not None:
        _check_faults(study, fixed)


def _apply(study: Study, data: dict, table: str, values: dict[str, Any]) -> None:
    """``set_path`` of each value; a key that does not apply is refused naming ``table``."""
    for key, v in values.items():
        try:
            set_path(data, study.path, key, v)
        except ScenarioError as exc:
            raise StudyError(study.path, _join(table, key), exc.problem, exc.expected) from None


def _validate(study: Study, data: dict) -> None:
    scenario_from_dict(data, path=study.path, sha256=hashlib.sha256(b"").hexdigest())


def _check_unknown(study: Study, data: dict) -> None:
    """A key of ``[set]`` or ``[params]`` the scenario loader does not know is refused."""
    try:
        _validate(study, data)
    except ScenarioError as exc:
        if exc.problem == "unknown key":
            bare = re.sub(r"\[\d+\]", "", exc.key)
            for table, keys in (("set", study.fixed), ("params", study.params)):
                for key in keys:
                    if re.sub(r"\[\d+\]", "", key) == bare:
                        raise StudyError(
                            study.path, _join(table, key), "names no scenario field", exc.expected
                        ) from None
    except ExpressionError:
        pass


def _check_faults(study: Study, data: dict) -> None:
    """Each fault type, with representative values, on the first follower it may hit."""
    fam = study.faults
    N = len(data["followers"])
    if fam.followers is not None and max(fam.followers) > N:
        raise StudyError(
            study.path,
            "faults.followers",
            f"follower {max(fam.followers)} > N = {N} (the smallest graph)",
            f"followers in 1..{N}",
        )
    i = (fam.followers or (1,))[0] - 1
    for ty in fam.types:
        trial = copy.deepcopy(data)
        fault = {"type": ty, **{k: representative(fam.keys[k]) for k in FAULT_TYPES[ty][1:]}}
        trial["followers"][i]["faults"] = [*trial["followers"][i].get("faults", []), fault]
        try:
            _validate(study, trial)
        except ScenarioError as exc:
            m = re.search(r"faults\[\d+\]\.(\w+)$", exc.key)
            if m and m.group(1) in FAULT_KEYS:
                raise StudyError(
                    study.path,
                    _join("faults", m.group(1)),
                    f"a {ty} fault: {exc.problem}",
                    exc.expected,
                ) from None
        except ExpressionError:
            pass
