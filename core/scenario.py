"""Scenario files: one TOML file fully describes one run.

:func:`load_scenario` reads a file with :mod:`tomllib`, validates every field
on load and returns a frozen :class:`Scenario`. Every problem is a
:class:`~core.errors.ScenarioError` naming the file, the key, what is wrong
and what is expected. Every key, its type, default and meaning is documented
in ``docs/scenario-format.md``; ``scenarios/paper.toml`` is the paper's Table 2.

The sections with defaults (``[observer]``, ``[controller]``, ``[options]``,
``[initial]``, ``[integration]``) declare each key once, on its dataclass field
(:func:`core.settings.setting`: default, shape, range checks); the loader walks
those fields. Rules between keys live in :data:`RULES` and are checked by
:meth:`Scenario.validate`, which runs whenever a :class:`Scenario` is made,
including through :func:`dataclasses.replace`.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import ExpressionError, ScenarioError
from core.expressions import Expr
from core.files import FileRefused, read_regular_file  # noqa: F401
from core.model import (  # noqa: F401  (the data model, re-exported)
    DERIVATIVES,
    GHAT_LAWS,
    MAX_FAULTS,
    MAX_GRAPH_SWITCHES,
    MAX_HORIZON,
    MAX_SCENARIO_BYTES,
    MAX_TABLE_ROWS,
    METHODS,
    OPTIONAL_SECTIONS,
    SECTIONS,
    SIGN_MODES,
    START_MODES,
    Controller,
    Design,
    Follower,
    Graph,
    Health,
    Initial,
    Integration,
    Leader,
    Observer,
    Options,
    Scenario,
)
from core.output_budget import (  # noqa: F401
    DEFAULT_OUTPUT_BUDGET,
    OUTPUT_BUDGET_ENV,
    OUTPUT_BYTES_PER_VALUE,
    check_output_size,
    output_budget,
    output_columns,
    output_rows,
)
from core.reading import Dims, ReadingContext
from core.rules import RULES, Problem, Rule  # noqa: F401
from core.sections import (  # noqa: F401  (the schema, re-exported)
    FOLLOWER,
    GRAPH,
    LEADER,
    TABLES,
    TOP,
    read_controller,
    read_followers,
    read_graph,
    read_key,
    read_section,
    read_setting,
    type_text,
)
from core.settings import (
    brief,
    required_keys,
)
from core.shaping import default_rise, shaped_steps
from core.suprema import expression_sup, sample_times
from core.traces import MAX_TRACE_BYTES, MAX_TRACE_ROWS, load_trace  # noqa: F401


# --------------------------------------------------------------------------- loader
def load_scenario(path: str | Path) -> Scenario:
    """Load and completely validate a scenario file.

    Parameters
    ----------
    path : str or Path
        The TOML file.

    Returns
    -------
    Scenario
        Frozen, typed, validated.

    Raises
    ------
    ScenarioError
        One line naming the file, the key, the problem and what is expected.
    """
    path = Path(path)
    ctx = ReadingContext(str(path))
    try:
        raw = read_regular_file(path, MAX_SCENARIO_BYTES)
    except OSError as exc:
        raise ctx.err(
            "(file)", f"cannot be read: {exc.strerror}", "an existing TOML file"
        ) from None
    except FileRefused as exc:
        raise ctx.err(
            "(file)", str(exc), f"a regular TOML file of at most {MAX_SCENARIO_BYTES >> 20} MiB"
        ) from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ctx.err("(file)", "is not UTF-8 text", "a UTF-8 TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ctx.err("(file)", f"malformed TOML: {exc}", "valid TOML") from None
    except (RecursionError, MemoryError):  # absurdly nested arrays or inline tables
        raise ctx.err("(file)", "nested too deeply", "a scenario file as documented") from None
    except ValueError as exc:  # e.g. an integer literal with more than 4300 digits
        raise ctx.err("(file)", f"unreadable value: {exc}", "numbers of ordinary size") from None
    return scenario_from_dict(data, path=path, sha256=hashlib.sha256(raw).hexdigest())


def scenario_from_dict(data: dict[str, Any], *, path: str | Path, sha256: str) -> Scenario:
    """Validate an already-parsed scenario table exactly like a file.

    Used for programmatic variants (e.g. the ablation run): the caller edits the
    table read from a file and validates it here, so a variant can never skip a
    check a file would get.

    Parameters
    ----------
    data : dict
        The table as :func:`tomllib.loads` returns it.
    path : str or Path
        The file it came from (for messages and relative CSV paths).
    sha256 : str
        The identity recorded in the scenario (and downstream artifacts).

    Returns
    -------
    Scenario
        Frozen, typed, validated.
    """
    path = Path(path)
    ctx = ReadingContext(str(path))
    try:
        return _build(ctx, data, path, sha256)
    except (ScenarioError, ExpressionError):
        raise
    except RecursionError:
        raise ctx.err("(file)", "nested too deeply", "a flat scenario table") from None


def _build(ctx: ReadingContext, data: dict, path: Path, sha: str) -> Scenario:
    """Read every table of ``data`` in dependency order; :class:`Scenario` checks the rules."""
    ctx.table(data, "", set(TOP), required_keys(TOP))
    name, desc = scenario_name(ctx, data, path), _description(ctx, data)
    # integration first: u0, g_i and f_i are checked over [0, horizon]
    integ = read_section(ctx, Integration, data.get("integration", {}), "integration", None)
    tgrid = np.linspace(0.0, integ.horizon, 4001)
    leader = _leader(ctx, data["leader"], path, integ.horizon, tgrid)
    graph = read_graph(ctx, data["graph"], integ.horizon)
    dims = Dims(N=graph.N, n=leader.n, m=leader.m, p=leader.p)
    check_output_size(ctx, integ, dims.N, dims.n, dims.m)
    options = read_section(ctx, Options, data.get("options", {}), "options", dims)
    followers = read_followers(ctx, data["followers"], dims.n, dims.N, tgrid, options.fault_slots)
    return Scenario(
        name=name,
        path=str(path),
        sha256=sha,
        description=desc,
        leader=leader,
        graph=graph,
        followers=followers,
        observer=read_section(ctx, Observer, data.get("observer", {}), "observer", dims),
        controller=read_controller(ctx, data.get("controller", {}), dims),
        options=options,
        initial=read_section(ctx, Initial, data.get("initial", {}), "initial", dims),
        integration=integ,
        design=read_section(ctx, Design, data["design"], "design", dims)
        if "design" in data
        else None,
    )


def scenario_name(ctx: ReadingContext, data: dict, path: Path) -> str:
    """``name``, by default the file's stem made into a plain folder name.

    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    data : dict
        The parsed TOML table.
    path : Path
        The scenario file.
    """
    stem = "".join(c if c.isascii() and (c.isalnum() or c in "-_.") else "_" for c in path.stem)
    name = data.get("name", stem.lstrip(".")[:100] or "scenario")
    if (
        not isinstance(name, str)
        or not name
        or name.startswith(".")
        or len(name) > 100
        or not all(c.isascii() and (c.isalnum() or c in "-_.") for c in name)
    ):
        raise ctx.err(
            "name",
            f"{brief(name)} is not a plain name (it names the output folder out/<name>/)",
            "ASCII letters, digits, '-', '_' or '.', not starting with '.'",
        )
    return name


def _description(ctx: ReadingContext, data: dict) -> str:
    desc = data.get("description", TOP["description"].default)
    if not isinstance(desc, str):
        raise ctx.err("description", "is not a string", "a string")
    return desc


# --------------------------------------------------------------------------- leader, graph
def _leader(ctx: ReadingContext, raw: Any, path: Path, horizon: float, tgrid: np.ndarray) -> Leader:
    """The [leader] table, eq. (3); ‖u0‖ ≤ α is checked on [0, horizon]."""
    L = ctx.table(raw, "leader", set(LEADER), required_keys(LEADER))
    sizes: dict[str, int] = {}
    A0 = read_key(ctx, LEADER, L, "leader", "A0", sizes)
    m = sizes["m"] = A0.shape[0]
    if A0.shape[1] != m:
        raise ctx.err(
            "leader.A0", f"has shape {A0.shape[0]}x{A0.shape[1]}", "a square matrix m x m"
        )
    B0 = read_key(ctx, LEADER, L, "leader", "B0", sizes)
    C0 = read_key(ctx, LEADER, L, "leader", "C0", sizes)
    sizes.update(p=B0.shape[1], n=C0.shape[0])
    eta0 = read_key(ctx, LEADER, L, "leader", "eta0", sizes)
    alpha = read_key(ctx, LEADER, L, "leader", "alpha", sizes)
    if ("u0" in L) == ("u0_csv" in L):
        raise ctx.err(
            "leader.u0",
            "give exactly one of u0 and u0_csv",
            "u0 = [expressions of t] or u0_csv = 'file.csv'",
        )
    p = sizes["p"]
    rise = read_key(ctx, LEADER, L, "leader", "u0_rise", sizes) if "u0_rise" in L else None
    shape = read_key(ctx, LEADER, L, "leader", "u0_shape", sizes)
    held = L.get("u0_hold") is True  # a held trace's jumps are shaped too (core/hold.py)
    for key, given in (("u0_rise", bool(rise) and not held), ("u0_shape", "u0_shape" in L)):
        if given and "u0" not in L:
            raise ctx.err(f"leader.{key}", "applies to u0 expressions only", f"u0, or no {key}")
    if "u0" in L:
        u0, trace = _u0_expressions(ctx, L["u0"], p), None
        rise = default_rise(u0) if rise is None else rise
        u0 = tuple(shaped_steps(e, rise, shape) for e in u0) if rise > 0 else u0
        u_peak = _u0_peak(ctx, u0, tgrid)
        where_u = "leader.u0"
    else:
        u0, trace = None, load_trace(ctx, path, L["u0_csv"], p, horizon)
        # piecewise linear: the norm peaks at a sample (convexity)
        u_peak = float(np.sqrt((trace[:, 1:] ** 2).sum(axis=1)).max())
        where_u = "leader.u0_csv"
    if u_peak > alpha * (1 + 1e-9):
        raise ctx.err(
            "leader.alpha",
            f"{where_u} reaches ||u0|| = {u_peak:.6g} > alpha = {alpha:.6g}",
            "alpha >= sup ||u0(t)|| on [0, horizon] (the bound the followers design for)",
        )
    hold = read_key(ctx, LEADER, L, "leader", "u0_hold", sizes)
    if hold and trace is None:
        raise ctx.err("leader.u0_hold", "applies to u0_csv only", "u0_csv, or no u0_hold")
    return Leader(
        A0=A0,
        B0=B0,
        C0=C0,
        eta0=eta0,
        u0=u0,
        u0_trace=trace,
        alpha=alpha,
        u0_hold=hold,
        u0_rise=rise or 0.0,
        u0_shape=shape,
    )


def _u0_expressions(ctx: ReadingContext, raw: Any, p: int) -> tuple[Expr, ...]:
    """``leader.u0``: p expressions of t."""
    if not isinstance(raw, list) or len(raw) != p:
        got = f"has {len(raw)} entries" if isinstance(raw, list) else "is not a list"
        raise ctx.err("leader.u0", got, f"a list of {p} expressions of t (p = columns of B0)")
    return tuple(ctx.expr(e, f"leader.u0[{k}]") for k, e in enumerate(raw))


def _u0_peak(ctx: ReadingContext, u0: tuple[Expr, ...], tgrid: np.ndarray) -> float:
    """sup ‖u0(t)‖ on [0, horizon]; refused when not finite."""
    ts = np.unique(np.concatenate([sample_times(e, tgrid) for e in u0]))
    u_peak = expression_sup("norm", u0, ts)
    if not math.isfinite(u_peak):
        raise ctx.err(
            "leader.u0", "is not finite somewhere on [0, horizon]", "a bounded operator input"
        )
    return u_peak
