"""The scenario file's schema and the loaders of its sections (everything but the leader).

The schema tables (:data:`TOP`, :data:`LEADER`, :data:`GRAPH`, :data:`FOLLOWER`) and the
declared sections read key by key (:func:`read_section`, :func:`read_key`); the graph with
its switches and the followers with their health, disturbances and faults.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

from core.errors import ToolkitError
from core.expression_tree import BinOp, Call, Node, Num, Time
from core.expressions import Expr
from core.faults import (
    FAULT,
    FAULT_TYPES,
    MAX_SWITCHES,
    Fault,
    fault_times,
    faulted_bias,
    faulted_health,
    pulse_count,
    slotted_bias,
    slotted_health,
)
from core.graph import (
    DEFAULT_LINK_FADE,
    Switch,
    base_gauge,
    iter_topologies,
    topology_violation,
    unreachable_followers,
)
from core.model import (
    MAX_FAULTS,
    MAX_GRAPH_SWITCHES,
    MAX_TABLE_ROWS,
    OPTIONAL_SECTIONS,
    SECTIONS,
    Controller,
    Follower,
    Graph,
    Health,
)
from core.reading import Dims, ReadingContext, frozen_array
from core.rules import RULES
from core.settings import (
    EITHER,
    NONNEG,
    POSITIVE,
    REQUIRED,
    SYNTH,
    Check,
    Derived,
    Setting,
    brief,
    declare,
    required_keys,
    settings_of,
    zeros,
)
from core.shaping import DEFAULT_SHAPE, SHAPES
from core.suprema import expression_sup, sample_times

# --------------------------------------------------------------------------- schema
# The tables read key by key (their values set the sizes, or need expressions,
# g tables or CSV traces): each key declared once, with its default, shape and checks.

#: the top-level keys
TOP: dict[str, Setting] = {
    "name": declare(Derived("file name without `.toml`"), "string"),
    "description": declare("", "string"),
    "leader": declare(REQUIRED, "table"),
    "graph": declare(REQUIRED, "table"),
    "followers": declare(REQUIRED, "tables"),
    **{section: declare(Derived("all defaults"), "table") for section in SECTIONS},
    "design": declare(Derived("none"), "table"),
}
#: ``[leader]``, eq. (3); A0 sets m, B0 sets p, C0 sets n
LEADER: dict[str, Setting] = {
    "A0": declare(REQUIRED, "matrix", dims=("m", "m")),
    "B0": declare(REQUIRED, "matrix", dims=("m", "p")),
    "C0": declare(REQUIRED, "matrix", dims=("n", "m")),
    "eta0": declare(zeros("m"), "vector", dims=("m", "")),
    "u0": declare(EITHER, "expressions", dims=("p", "")),
    "u0_csv": declare(EITHER, "string"),
    "u0_hold": declare(False, "boolean"),
    "u0_rise": declare(
        Derived("2 s if u0 has a step, else 0 (`core.shaping.DEFAULT_RISE`)"), "number", NONNEG
    ),
    "u0_shape": Setting(DEFAULT_SHAPE, "choice", options=SHAPES),
    "alpha": declare(REQUIRED, "number", POSITIVE),
}
#: ``[graph]``; adjacency sets N
GRAPH: dict[str, Setting] = {
    "adjacency": declare(REQUIRED, "matrix", dims=("N", "N")),
    "pinning": declare(REQUIRED, "vector", NONNEG, dims=("N", "")),
    "switches": declare(Derived("none"), "tables"),
    "link_fade": declare(DEFAULT_LINK_FADE, "number", NONNEG),
}
#: one ``[[followers]]`` table, eq. (2)
FOLLOWER: dict[str, Setting] = {
    "model": declare(REQUIRED, "string"),
    "params": declare(Derived("the model's defaults", lambda sizes: {}), "numbers_table"),
    "p0": declare(REQUIRED, "vector", dims=("n", "")),
    "q0": declare(zeros("n"), "vector", dims=("n", "")),
    "b0": declare(REQUIRED, "vector", dims=("n", "")),
    "g": declare(1.0, "health"),
    "f": declare(0.0, "expression_or_list", dims=("n", "")),
    "d": declare(Derived("sup |f_ir| on [0, horizon]"), "vector", NONNEG, dims=("n", "")),
    "faults": declare(Derived("none"), "tables"),
}
#: the tables above by their name in docs/scenario-format.md
TABLES: dict[str, dict[str, Setting]] = {
    "top": TOP,
    "leader": LEADER,
    "graph": GRAPH,
    "followers": FOLLOWER,
}


def type_text(section: str, name: str) -> str:
    """The documented type of ``[section].name``: its shape, checks and rules.

    Parameters
    ----------
    section : str
        A key of :data:`SECTIONS` (``"observer"``) or of :data:`TABLES` (``"leader"``).
    name : str
        The setting (``"delta1_hat"``).
    """
    if section in TABLES:
        return TABLES[section][name].type_text()
    words = tuple(r.text for r in RULES if r.key == f"{section}.{name}" and r.text)
    return settings_of({**SECTIONS, **OPTIONAL_SECTIONS}[section])[name].type_text(words)


# --------------------------------------------------------------------------- declared sections
_Section = TypeVar("_Section")  # one of the dataclasses of SECTIONS


def read_section(
    ctx: ReadingContext, cls: type[_Section], raw: Any, key: str, dims: Dims | None
) -> _Section:
    """A table of a declared section: every field read with its :class:`Setting`.

    Unknown keys are refused; an omitted key takes the field's default.
    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    raw : object
        The TOML table (or value) as read.
    key : str
        Its key in errors (``followers[1].p0``).
    dims : object
    """
    declared = settings_of(cls)
    table = ctx.table(raw, key, set(declared))
    sizes = dims._asdict() if dims is not None else None
    values = {
        name: read_setting(ctx, s, table.get(name, s.default), f"{key}.{name}", sizes)
        for name, s in declared.items()
    }
    return cls(**values)


def read_setting(
    ctx: ReadingContext, s: Setting, v: Any, key: str, dims: Mapping[str, int] | None
) -> Any:
    """One TOML value read as setting ``s`` says (``"synthesize"``, ``"none"`` -> None where allowed).

    ``dims`` holds the sizes known so far by symbol (:class:`Dims` or a part of it);
    a matrix or vector dimension not yet known is not checked.
    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    s : Setting
    v : object
        The TOML value.
    key : str
        Its key in errors (``followers[1].p0``).
    dims : object
    """
    if s.keyword and isinstance(v, str):
        if v == s.keyword:
            return None
        raise ctx.err(key, f"{brief(v)} is not a value", f"a value or {s.keyword!r}")
    if s.shape in ("number", "integer"):
        x = ctx.number(v, key, s.checks)
        return int(x) if s.shape == "integer" else x
    if s.shape == "boolean":
        return ctx.boolean(v, key)
    if s.shape == "choice":
        return ctx.choice(v, key, s.options)
    assert dims is not None, f"{key} needs the scenario's dimensions"
    if s.shape == "matrix":
        return ctx.matrix(v, key, (dims.get(s.dims[0]), dims.get(s.dims[1])))
    if s.shape == "vector":
        return ctx.vector(v, key, dims.get(s.dims[0]), s.checks)
    if s.shape == "per_follower":
        return ctx.per_agent(v, key, dims["N"], s.checks)
    if s.shape == "per_coordinate":
        return ctx.per_agent_comp(v, key, dims["N"], dims["n"], s.checks)
    k = dims["m"] if s.shape == "rows_m" else dims["n"]
    return _rows(ctx, v, key, dims["N"], k, s.checks)


def read_key(
    ctx: ReadingContext,
    table: Mapping[str, Setting],
    raw: dict,
    prefix: str,
    name: str,
    dims: Mapping,
) -> Any:
    """Key ``name`` of a table read key by key: its value, or its declared default, read.

    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    table : mapping of str to Setting
        The schema table.
    raw : object
        The TOML table (or value) as read.
    prefix : str
        The table's key in errors (``leader``).
    name : str
        The key.
    dims : object
    """
    s = table[name]
    v = raw[name] if name in raw else s.default_for(dims)
    return read_setting(ctx, s, v, f"{prefix}.{name}", dims)


def read_controller(ctx: ReadingContext, raw: Any, dims: Dims) -> Controller:
    """The [controller] table: every gain is given (none can be synthesised).

    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    raw : object
        The TOML table (or value) as read.
    dims : object
    """
    if isinstance(raw, dict):
        for k, v in raw.items():
            if v == SYNTH:
                raise ctx.err(
                    f"controller.{k}",
                    "cannot be synthesised (the paper gives no design procedure for it)",
                    "a number",
                )
    return read_section(ctx, Controller, raw, "controller", dims)


def read_graph(ctx: ReadingContext, raw: Any, horizon: float) -> Graph:
    """The [graph] table; every follower must be reachable from the leader (Assumption 1).

    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    raw : object
        The TOML table (or value) as read.
    horizon : float
        The run's horizon.
    """
    G = ctx.table(raw, "graph", set(GRAPH), required_keys(GRAPH))
    A = read_key(ctx, GRAPH, G, "graph", "adjacency", {})
    N = A.shape[0]
    if A.shape[1] != N:
        raise ctx.err(
            "graph.adjacency", f"has shape {A.shape[0]}x{A.shape[1]}", "a square N x N matrix"
        )
    if np.any(np.diag(A) != 0):
        raise ctx.err("graph.adjacency", "has a non-zero diagonal (self-loop)", "a_ii = 0")
    pin = read_key(ctx, GRAPH, G, "graph", "pinning", {"N": N})
    unreachable = unreachable_followers(A, pin)
    if unreachable:
        names = ", ".join(str(i + 1) for i in unreachable)
        raise ctx.err(
            "graph",
            f"follower(s) {names} cannot be reached from the leader (Assumption 1)",
            "a directed spanning tree rooted at the leader: add a pinning a_i0 > 0 "
            "or an edge a_ij != 0 from a reachable agent",
        )
    switches = _switches(ctx, G.get("switches", []), A, pin, horizon)
    fade = float(read_key(ctx, GRAPH, G, "graph", "link_fade", {}))
    return Graph(adjacency=A, pinning=pin, switches=switches, link_fade=fade)


def _switches(
    ctx: ReadingContext, raw: Any, A: np.ndarray, pin: np.ndarray, horizon: float
) -> tuple[Switch, ...]:
    """``[[graph.switches]]``: each event checked, then every topology it makes (Assumption 1)."""
    if not isinstance(raw, list) or not all(isinstance(x, dict) for x in raw):
        raise ctx.err(
            "graph.switches",
            "is not an array of tables",
            "[[graph.switches]] tables with time, follower, neighbour, weight",
        )
    if len(raw) > MAX_GRAPH_SWITCHES:
        raise ctx.err("graph.switches", f"has {len(raw)} switches", f"at most {MAX_GRAPH_SWITCHES}")
    try:
        h = base_gauge(A, pin)
    except ToolkitError:  # an unbalanced base graph: synthesis names its cycle
        h = None
    out: list[Switch] = []
    for k, sw in enumerate(raw):
        s = _switch(ctx, sw, f"graph.switches[{k + 1}]", A.shape[0], horizon, h)
        for j, o in enumerate(out):
            if (o.time, o.follower, o.neighbour) == (s.time, s.follower, s.neighbour):
                raise ctx.err(
                    f"graph.switches[{k + 1}]",
                    f"sets {s.link} at t = {s.time:g} s again (graph.switches[{j + 1}] does)",
                    "one switch per link and time",
                )
        out.append(s)
    switches = tuple(out)
    for top in list(iter_topologies(A, pin, switches))[1:]:
        why = topology_violation(top.adjacency, top.pinning, h)
        if why is not None:
            k = next(k for k, s in enumerate(switches) if s.time == top.t_start)
            raise ctx.err(
                f"graph.switches[{k + 1}].weight",
                f"from t = {top.t_start:g} s {why}",
                "every topology keeps a directed spanning tree rooted at the leader "
                "(restore a link or add one from a reachable agent at the same time)",
            )
    return switches


def _switch(
    ctx: ReadingContext, raw: dict, key: str, N: int, horizon: float, h: np.ndarray | None
) -> Switch:
    """One switch table: time in (0, horizon), 1-based indices, a finite weight of a valid sign."""
    names = ("time", "follower", "neighbour", "weight")
    ctx.table(raw, key, set(names), set(names))
    t = ctx.number(raw["time"], f"{key}.time")
    if not 0.0 < t < horizon:
        raise ctx.err(
            f"{key}.time", f"{t:g} is outside (0, {horizon:g})", "0 < time < integration.horizon"
        )
    i = _index(ctx, raw["follower"], f"{key}.follower", 1, N, "a follower 1..N")
    j = _index(ctx, raw["neighbour"], f"{key}.neighbour", 0, N, "0 (the leader) or a follower 1..N")
    if j == i:
        raise ctx.err(f"{key}.neighbour", f"{j} is the follower itself", "a different agent")
    w = ctx.number(raw["weight"], f"{key}.weight")
    if j == 0 and w < 0:
        raise ctx.err(f"{key}.weight", f"pinning gain {w:g} is negative", "a_i0 >= 0")
    if j > 0 and w != 0 and h is not None and np.sign(w) != h[i - 1] * h[j - 1]:
        raise ctx.err(
            f"{key}.weight",
            f"{w:g} has the sign opposite to h_{i} h_{j} = {h[i - 1] * h[j - 1]:+g} of the "
            "graph's gauge (it would change the gauge the gains are certified for)",
            f"a weight of sign {h[i - 1] * h[j - 1]:+g}, or 0 to remove the link",
        )
    return Switch(time=t, follower=i - 1, neighbour=None if j == 0 else j - 1, weight=w)


def _index(ctx: ReadingContext, v: Any, key: str, lo: int, hi: int, expected: str) -> int:
    """A whole number in [lo, hi] (1-based agents, 0 for the leader)."""
    x = ctx.number(v, key)
    if x != int(x) or not lo <= x <= hi:
        raise ctx.err(key, f"{brief(v)} is not an agent", expected)
    return int(x)


def read_followers(
    ctx: ReadingContext, F: Any, n: int, N: int, tgrid: np.ndarray, slots: int | None = None
) -> tuple[Follower, ...]:
    """The [[followers]] tables, one per row of the adjacency matrix (``slots``: fault_slots).

    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    F : object
        The ``[[followers]]`` array.
    n : int
        Coordinates per follower.
    N : int
        Number of followers.
    tgrid : ndarray
        The time grid.
    slots : int or None
        ``options.fault_slots``.
    """
    if not isinstance(F, list) or not all(isinstance(x, dict) for x in F):
        raise ctx.err(
            "followers", "is not an array of tables", "[[followers]] tables, one per follower"
        )
    if len(F) != N:
        raise ctx.err(
            "followers",
            f"has {len(F)} followers but graph.adjacency is {N}x{N}",
            "one [[followers]] table per row of the adjacency matrix",
        )
    return tuple(_follower(ctx, fo, i, n, tgrid, slots) for i, fo in enumerate(F))


def _follower(
    ctx: ReadingContext, fo: dict, i: int, n: int, tgrid: np.ndarray, slots: int | None = None
) -> Follower:
    """One [[followers]] table (0-based ``i``; messages say ``followers[i+1]``)."""
    key = f"followers[{i + 1}]"
    ctx.table(fo, key, set(FOLLOWER), required_keys(FOLLOWER))
    sizes = {"n": n}
    model, params = _model(ctx, fo, key, n)
    faults = _faults(ctx, fo.get("faults", []), key, n, float(tgrid[-1]))
    if slots is not None and len(faults) > slots:
        raise ctx.err(
            f"{key}.faults",
            f"has {len(faults)} faults but options.fault_slots = {slots}",
            f"at most {slots} faults per follower, or options.fault_slots >= {len(faults)}",
        )
    health = _health(ctx, fo.get("g", FOLLOWER["g"].default), f"{key}.g", tgrid)
    health = _faulted(ctx, health, faults, key, tgrid, slots)
    f, d = _disturbance(ctx, fo, key, n, tgrid, faults, slots)
    return Follower(
        model=model,
        params=params,
        p0=read_key(ctx, FOLLOWER, fo, key, "p0", sizes),
        q0=read_key(ctx, FOLLOWER, fo, key, "q0", sizes),
        b0=read_key(ctx, FOLLOWER, fo, key, "b0", sizes),
        g=health,
        f=f,
        d=d,
        faults=faults,
    )


def _model(ctx: ReadingContext, fo: dict, key: str, n: int) -> tuple[str, dict[str, float]]:
    """A follower's ``model`` (a registered one with n coordinates) and its ``params``."""
    from core.models import REGISTRY

    model = fo["model"]
    if not isinstance(model, str) or model not in REGISTRY:
        raise ctx.err(
            f"{key}.model",
            f"{model!r} is not a known model",
            "one of " + ", ".join(sorted(REGISTRY)),
        )
    spec = REGISTRY[model]
    if spec.n != n:
        raise ctx.err(
            f"{key}.model",
            f"{model!r} has n = {spec.n} coordinates but leader.C0 has {n} rows",
            f"a model with n = {n}, or a C0 with {spec.n} rows",
        )
    given = fo["params"] if "params" in fo else FOLLOWER["params"].default_for({"n": n})
    prm = ctx.table(given, f"{key}.params", set(spec.defaults))
    params = {
        k: ctx.number(
            prm.get(k, v),
            f"{key}.params.{k}",
            (NONNEG,) if k in spec.nonnegative else (POSITIVE,),
        )
        for k, v in spec.defaults.items()
    }
    return model, params


def _disturbance(
    ctx: ReadingContext,
    fo: dict,
    key: str,
    n: int,
    tgrid: np.ndarray,
    faults: tuple[Fault, ...] = (),
    slots: int | None = None,
) -> tuple[tuple[Expr, ...], np.ndarray]:
    """A follower's ``f`` (n expressions, plus its bias ``faults``) and its bound ``d``.

    ``d`` is given and checked, or sampled.
    """
    f_raw = fo.get("f", FOLLOWER["f"].default)
    if not isinstance(f_raw, list):
        f_raw = [f_raw] * n  # one expression for every component
    if len(f_raw) != n:
        raise ctx.err(
            f"{key}.f",
            f"has {len(f_raw)} components",
            f"one expression of t, or a list of {n} (one per coordinate)",
        )
    f = tuple(ctx.expr(e, f"{key}.f[{r}]") for r, e in enumerate(f_raw))
    f = faulted_bias(f, faults) if slots is None else slotted_bias(f, faults, slots)
    worst = np.array([expression_sup("abs", (e,), sample_times(e, tgrid)) for e in f])
    for r, w in enumerate(worst):
        if not math.isfinite(w):
            raise ctx.err(
                f"{key}.f[{r}]",
                "is not finite somewhere on [0, horizon]",
                "a bounded disturbance (Assumption 3)",
            )
    if "d" not in fo:  # the declared default: the sampled supremum
        return f, frozen_array(worst)
    d = read_key(ctx, FOLLOWER, fo, key, "d", {"n": n})
    if np.any(worst > d * (1 + 1e-9)):
        r = int(np.argmax(worst - d))
        raise ctx.err(
            f"{key}.d",
            f"|f[{r}]| reaches {worst[r]:.4g} > d = {d[r]:.4g}",
            "d_ir >= sup |f_ir(t)| (Assumption 3)",
        )
    return f, d


def _rows(
    ctx: ReadingContext, v: Any, key: str, N: int, k: int, checks: tuple[Check, ...] = ()
) -> np.ndarray:
    """Scalar (all entries), one k-vector (every agent) or N k-vectors -> N×k."""
    if isinstance(v, list) and v and not isinstance(v[0], list):
        row = ctx.vector(v, key, k, checks)
        return frozen_array(np.tile(row, (N, 1)))
    return ctx.per_agent_comp(v, key, N, k, checks)


def _health(ctx: ReadingContext, v: Any, key: str, tgrid: np.ndarray) -> Health:
    """g_i(t): constant, table [[t_start, value], ...] or expression; checked in (0, 1]."""
    if isinstance(v, list):
        if not v or not all(isinstance(r, list) and len(r) == 2 for r in v):
            raise ctx.err(
                key, "is not a table of [t_start, value] pairs", "e.g. [[0.0, 1.0], [5.0, 0.6]]"
            )
        if len(v) > MAX_TABLE_ROWS:
            raise ctx.err(key, f"has {len(v)} rows", f"at most {MAX_TABLE_ROWS} rows")
        rows = [
            (ctx.number(a, f"{key}[{k}][0]", (NONNEG,)), ctx.number(b, f"{key}[{k}][1]"))
            for k, (a, b) in enumerate(v)
        ]
        if rows[0][0] != 0.0:
            raise ctx.err(f"{key}[0][0]", f"first segment starts at {rows[0][0]}", "0.0")
        for k in range(1, len(rows)):
            if rows[k][0] <= rows[k - 1][0]:
                raise ctx.err(
                    f"{key}[{k}][0]",
                    f"t_start {rows[k][0]} does not follow {rows[k - 1][0]}",
                    "strictly increasing t_start",
                )
        for k, (_, b) in enumerate(rows):
            if not 0.0 < b <= 1.0:
                raise ctx.err(
                    f"{key}[{k}][1]",
                    f"actuator health {b:.4g} is outside (0, 1]",
                    "0 < g_i <= 1 (1 = healthy)",
                )
        vals = [b for _, b in rows]
        # g(t) = g_0 + Σ_k (g_k − g_{k−1}) step(t − t_k), built as a node tree (no text parsing)
        terms: list[Node] = [Num(vals[0])] + [
            BinOp("*", Num(b - a), Call("step", (BinOp("-", Time(), Num(t0)),)))
            for (t0, b), a in zip(rows[1:], vals, strict=False)
        ]
        text = repr(vals[0]) + "".join(
            f" + ({b - a!r})*step(t - {t0!r})" for (t0, b), a in zip(rows[1:], vals, strict=False)
        )
        expr = Expr(text, _balanced_sum(terms))
        breaks = tuple(t0 for t0, _ in rows[1:])
        lo = min(vals)
    else:
        expr = ctx.expr(v, key)
        ts = sample_times(expr, tgrid)
        lo = -expression_sup("neg", (expr,), ts)
        hi = expression_sup("pos", (expr,), ts)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ctx.err(key, "is not finite somewhere on [0, horizon]", "a value in (0, 1]")
        if not (lo > 0.0 and hi <= 1.0 + 1e-12):
            bad = lo if lo <= 0 else hi
            raise ctx.err(
                key,
                f"actuator health reaches {bad:.4g}, outside (0, 1]",
                "0 < g_i <= 1 (1 = healthy)",
            )
        breaks = expr.breakpoints()
    return Health(expr=expr, breakpoints=breaks, minimum=float(lo))


def _faults(ctx: ReadingContext, raw: Any, key: str, n: int, horizon: float) -> tuple[Fault, ...]:
    """A follower's ``[[followers.faults]]`` tables (docs/scenario-format.md, 'Faults')."""
    if not isinstance(raw, list) or not all(isinstance(x, dict) for x in raw):
        raise ctx.err(
            f"{key}.faults",
            "is not an array of tables",
            '[[followers.faults]] tables, each with a type such as "abrupt"',
        )
    if len(raw) > MAX_FAULTS:
        raise ctx.err(f"{key}.faults", f"has {len(raw)} faults", f"at most {MAX_FAULTS}")
    return tuple(_fault(ctx, fa, f"{key}.faults[{k + 1}]", n, horizon) for k, fa in enumerate(raw))


def _fault(ctx: ReadingContext, raw: dict, key: str, n: int, horizon: float) -> Fault:
    """One fault table: its type, then exactly the keys of that type, each checked."""
    kind = raw.get("type")
    if not isinstance(kind, str) or kind not in FAULT_TYPES:
        problem = "missing" if "type" not in raw else f"{brief(kind)} is not a fault type"
        raise ctx.err(f"{key}.type", problem, "one of " + ", ".join(map(repr, FAULT_TYPES)))
    names = FAULT_TYPES[kind]
    for k in raw:
        if k not in names:
            expected = f"the keys of a {kind!r} fault: " + ", ".join(names)
            raise ctx.err(f"{key}.{k}", f"unknown key for a {kind!r} fault", expected)
    ctx.table(raw, key, set(names), set(names))
    values = {k: read_setting(ctx, FAULT[k], raw[k], f"{key}.{k}", {"n": n}) for k in names[1:]}
    if values["onset"] > horizon:
        raise ctx.err(
            f"{key}.onset",
            f"{values['onset']:g} is beyond the horizon {horizon:g} s",
            "a time in [0, integration.horizon]",
        )
    if kind == "intermittent":
        count = pulse_count(values["onset"], values["period"], horizon)
        if 2 * count > MAX_SWITCHES:
            raise ctx.err(
                f"{key}.period",
                f"{values['period']:g} s gives {2 * count} on/off switches before the horizon",
                f"at most {MAX_SWITCHES}: a longer period or a later onset",
            )
    if "amplitude" in values:
        values["amplitude"] = tuple(float(a) for a in values["amplitude"])
    return Fault(type=kind, **values)


def _faulted(
    ctx: ReadingContext,
    base: Health,
    faults: tuple[Fault, ...],
    key: str,
    tgrid: np.ndarray,
    slots: int | None = None,
) -> Health:
    """The health ``base`` times the factors of the loss-of-effectiveness ``faults``.

    With ``slots`` (options.fault_slots) in the generic form, even without faults.
    """
    H = float(tgrid[-1])
    health = tuple(fa for fa in faults if not fa.is_bias)
    if slots is not None:
        expr = slotted_health(base.expr, faults, slots)
        if not health:  # every factor is exactly 1: the values of base
            return Health(expr=expr, breakpoints=base.breakpoints, minimum=base.minimum)
    elif not health:
        return base
    else:
        expr = faulted_health(base.expr, faults, H)
    times = {t for t in fault_times(health, H, slots) if 0.0 < t < H}
    breaks = tuple(sorted(set(base.breakpoints) | times))
    extra = [x for b in breaks for x in (b, b - 1e-9, b + 1e-9)]
    ts = np.unique(np.concatenate([sample_times(expr, tgrid), np.array(extra, dtype=float)]))
    lo = -expression_sup("neg", (expr,), ts[(ts >= 0.0) & (ts <= H)])
    if not (math.isfinite(lo) and lo > 0.0):  # cannot happen with severities < 1
        raise ctx.err(f"{key}.faults", f"actuator health reaches {lo:.4g}", "severities below 1")
    return Health(expr=expr, breakpoints=breaks, minimum=float(lo))


def _balanced_sum(terms: list[Node]) -> Node:
    """A sum as a balanced tree, so long tables stay shallow for the recursive evaluators."""
    if len(terms) == 1:
        return terms[0]
    mid = len(terms) // 2
    return BinOp("+", _balanced_sum(terms[:mid]), _balanced_sum(terms[mid:]))
