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
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from core import methods
from core.errors import ExpressionError, ScenarioError, ToolkitError
from core.expressions import Expr
from core.faults import (
    FAULT,
    FAULT_TYPES,
    MAX_SWITCHES,
    SLOT_COUNT,
    Fault,
    fault_times,
    faulted_bias,
    faulted_health,
    pulse_count,
    slotted_bias,
    slotted_health,
)
from core.files import FileRefused, read_regular_file  # noqa: F401
from core.graph import (
    Switch,
    Topology,
    base_gauge,
    iter_topologies,
    switch_times,
    topology_violation,
    unreachable_followers,
)
from core.hold import shaped_breakpoints, shaped_hold
from core.output_budget import (  # noqa: F401
    DEFAULT_OUTPUT_BUDGET,
    OUTPUT_BUDGET_ENV,
    OUTPUT_BYTES_PER_VALUE,
    check_output_size,
    output_budget,
    output_columns,
    output_rows,
)
from core.reading import Dims, ReadingContext, frozen_array
from core.rules import RULES, Problem, Rule  # noqa: F401
from core.settings import (
    EITHER,
    NONNEG,
    OFF,
    POSITIVE,
    REQUIRED,
    SYNTH,
    WHOLE,
    Check,
    Derived,
    Setting,
    brief,
    declare,
    required_keys,
    setting,
    settings_of,
    zeros,
)
from core.shaping import DEFAULT_SHAPE, SHAPES, default_rise, shaped_steps
from core.suprema import expression_sup, sample_times
from core.traces import MAX_TRACE_BYTES, MAX_TRACE_ROWS, load_trace  # noqa: F401

SIGN_MODES = ("exact", "sat", "tanh")
GHAT_LAWS = ("paper", "sigma", "projection", "sigma+projection")
DERIVATIVES = ("oracle", "filtered")
METHODS = methods.METHODS  # the live list of core.methods (integration.method's choices)
START_MODES = ("given", "formation")
MAX_TABLE_ROWS = 1000  # rows of a piecewise g_i table
MAX_FAULTS = 100  # [[followers.faults]] tables of one follower
MAX_GRAPH_SWITCHES = 1000  # [[graph.switches]] tables (each topology is an N×N copy)


MAX_SCENARIO_BYTES = 64 * 2**20  # size of a scenario file (read whole)
MAX_HORIZON = 1e6  # s; far beyond any study here, and keeps time arithmetic finite

# range checks beyond the sign, with the messages the loader has always given
_G_MIN_RANGE = Check("≤ 1", lambda x: x <= 1.0, "{v} is outside (0, 1]", "0 < g_min <= 1")
_BELOW_ONE = Check("< 1", lambda x: x < 1.0, "{v} >= 1", "a relative tolerance < 1")
_HORIZON_RANGE = Check(
    "≤ 1e6",
    lambda x: x <= MAX_HORIZON,
    "{v:g} s is beyond " + f"{MAX_HORIZON:g} s",
    f"a horizon in seconds <= {MAX_HORIZON:g}",
)


# --------------------------------------------------------------------------- types
@dataclass(frozen=True)
class Leader:
    """The human-in-the-loop leader, eq. (3): η̇0 = A0 η0 + B0 u0(t), y0 = C0 η0."""

    A0: np.ndarray  # m×m
    B0: np.ndarray  # m×p
    C0: np.ndarray  # n×m
    eta0: np.ndarray  # m
    u0: tuple[Expr, ...] | None  # p expressions of t, or None when a CSV trace is used
    u0_trace: np.ndarray | None  # (K, 1+p): columns t, u0_1..u0_p (piecewise linear)
    alpha: float  # ‖u0‖ ≤ α
    u0_hold: bool = False  # the trace is held constant from each row to the next (zero-order hold)
    u0_rise: float = 0.0  # the steps of u0 (or a held trace's jumps) are shaped over this many s
    u0_shape: str = DEFAULT_SHAPE  # how (core/shaping.py: smoothstep, prefilter or ramp)

    @property
    def m(self) -> int:
        return self.A0.shape[0]

    def u0_numpy(self, t: Any) -> np.ndarray:
        """u0 at time(s) ``t`` with numpy: shape (p,) for a scalar t, (p, len(t)) for an array.

        Expressions are evaluated directly; a CSV trace is interpolated linearly, or
        held from each row to the next with ``u0_hold`` (the meaning the closed loop
        gives it).

        Parameters
        ----------
        t : float or ndarray
            Time(s).
        """
        ts = np.asarray(t, dtype=float)
        if self.u0 is not None:
            return np.array([np.broadcast_to(e.numpy(ts), ts.shape) for e in self.u0])
        tr = self.u0_trace
        assert tr is not None
        if self.u0_hold and self.u0_rise > 0:  # each jump a smoothstep ramp (core/hold.py)
            cols = [shaped_hold(tr[:, 0], tr[:, 1 + k], self.u0_rise, ts)[0] for k in range(self.p)]
            return np.array(cols)
        if self.u0_hold:  # right-continuous: row j's value from its time t_j on
            j = np.clip(np.searchsorted(tr[:, 0], ts, side="right") - 1, 0, len(tr) - 1)
            return np.moveaxis(tr[j, 1:], -1, 0)
        return np.array([np.interp(ts, tr[:, 0], tr[:, 1 + k]) for k in range(tr.shape[1] - 1)])

    @property
    def p(self) -> int:
        return self.B0.shape[1]

    @property
    def n(self) -> int:
        return self.C0.shape[0]


@dataclass(frozen=True)
class Graph:
    """Follower graph: ``adjacency[i, j] = a_ij`` (i hears j; signed allowed), ``pinning[i] = a_i0``."""

    adjacency: np.ndarray  # N×N
    pinning: np.ndarray  # N
    switches: tuple[Switch, ...] = ()  # [[graph.switches]], in file order

    @property
    def N(self) -> int:
        return self.adjacency.shape[0]

    def topologies(self) -> tuple[Topology, ...]:
        """The piecewise-constant graph: ``(t_start, adjacency, pinning)``, base graph first.

        ``t_start`` = 0 for the base graph, then one entry per distinct switching time
        (all switches at that time applied together); each holds until the next.
        """
        return tuple(iter_topologies(self.adjacency, self.pinning, self.switches))

    @property
    def signed(self) -> bool:
        return bool((self.adjacency < 0).any())


@dataclass(frozen=True)
class Health:
    """Actuator health g_i(t) ∈ (0, 1]: a constant, a piecewise-constant table or an expression."""

    expr: Expr  # always available (constants and tables are turned into expressions)
    breakpoints: tuple[float, ...]
    minimum: float  # smallest value over the horizon (checked on load)


@dataclass(frozen=True)
class Follower:
    """One follower, eq. (2), with its fault and formation offset."""

    model: str
    params: dict[str, float]
    p0: np.ndarray  # n
    q0: np.ndarray  # n
    b0: np.ndarray  # n, constant formation offset b_i0
    g: Health
    f: tuple[Expr, ...]  # n expressions of t, the bias/disturbance f_i(t)
    d: np.ndarray  # n, bound |f_ir| ≤ d_ir (given or sampled over the horizon)
    faults: tuple[Fault, ...] = ()  # [[followers.faults]], already composed into g and f


@dataclass(frozen=True, kw_only=True)
class Observer:
    """Distributed observer (9) and UIO (6)–(8) gains; ``None`` means ``"synthesize"``."""

    lambda1: float | None = setting(SYNTH, "number", POSITIVE, synth=True)
    lambda2: float | None = setting(SYNTH, "number", POSITIVE, synth=True)
    Q: np.ndarray | None = setting(SYNTH, "matrix", dims=("p", "m"), synth=True)
    Theta: np.ndarray | None = setting(SYNTH, "matrix", dims=("m", "n"), synth=True)
    alpha1: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N
    alpha1_bar: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N
    phi0: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N, φ_i(0) > 0
    phi_min: float = setting(0.0, "number", NONNEG)  # floor of φ_i (0 = the paper's law)
    lambda_bar1: float = setting(1.0, "number", POSITIVE)  # LMI (15)
    delta1: float = setting(0.5, "number", POSITIVE)  # LMI (15)
    delta2: float = setting(1.0, "number", POSITIVE)  # LMI (16)
    # 0 < δ̂1 < δ1 (k1 and the supported decay rate), 0 < δ̂2 < δ2
    delta1_hat: float = setting(0.25, "number", POSITIVE)
    delta2_hat: float = setting(0.5, "number", POSITIVE)
    # relative margin for λ1 > λ̄1/w and λ2 ≥ α when synthesised
    margin: float = setting(0.05, "number", NONNEG)


@dataclass(frozen=True, kw_only=True)
class Controller:
    """Fault-tolerant controller (29)–(30) gains, per agent and component."""

    Lambda: np.ndarray = setting(40.0, "per_coordinate", POSITIVE)  # N×n, λ_ir
    k1: np.ndarray = setting(20.0, "per_coordinate", POSITIVE)  # N×n, K_i = diag(k1ir)
    k2: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N, k2i
    gamma: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N, gain of ĝ (1 = paper)
    sigma: np.ndarray = setting(0.0, "per_follower", NONNEG)  # N, σ-modification
    ghat_ref: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N, ĝ0 of the σ-mod.
    # designer's worst health: projection onto [1, 1/g_min]
    g_min: float = setting(0.5, "number", POSITIVE, _G_MIN_RANGE)
    # N, actuator limit |u_ir| <= u_max_i (outside the paper's theory); None = no limit
    u_max: np.ndarray | None = setting(OFF, "per_follower", POSITIVE, off=True)


@dataclass(frozen=True, kw_only=True)
class Options:
    """Controller and model options."""

    sign: str = setting("tanh", "choice", options=SIGN_MODES)
    sign_width: float = setting(0.05, "number", POSITIVE)  # ε of sat(χ/ε), tanh(χ/ε)
    ghat_law: str = setting("paper", "choice", options=GHAT_LAWS)
    # include ḃ, b̈ in (28)–(29) (False = eq. (29) as printed)
    feedforward: bool = setting(True, "boolean")
    ablation: bool = setting(False, "boolean")  # eq. (42): u = Ψ (no ĝ)
    derivatives: str = setting("oracle", "choice", options=DERIVATIVES)
    filter_bandwidth: float = setting(50.0, "number", POSITIVE)  # rad/s, filtered derivatives
    # ‖η̇_i‖ below which the formation angle τ_i is faded out
    tau_threshold: float = setting(1e-3, "number", POSITIVE)
    # g_i, f_i in one generic form with this many fault slots (None: each fault type its own)
    fault_slots: int | None = setting(OFF, "integer", NONNEG, WHOLE, SLOT_COUNT, off=True)


@dataclass(frozen=True, kw_only=True)
class Initial:
    """Initial estimator states."""

    eta: np.ndarray = setting(0.0, "rows_m")  # N×m, η_i(0)
    mu: np.ndarray = setting(0.0, "rows_m")  # N×m, μ_i(0)
    theta_hat: np.ndarray = setting(0.0, "rows_n", NONNEG)  # N×n
    ghat: np.ndarray = setting(1.0, "per_follower", POSITIVE)  # N
    start: str = setting("given", "choice", options=START_MODES)


@dataclass(frozen=True, kw_only=True)
class Integration:
    """Integration settings (``generated.integrate.IntegratorSettings`` takes these defaults)."""

    method: str = setting("cvodes", "choice", options=METHODS)
    rtol: float = setting(1e-6, "number", POSITIVE, _BELOW_ONE)
    atol: float = setting(1e-8, "number", POSITIVE)
    horizon: float = setting(20.0, "number", POSITIVE, _HORIZON_RANGE)
    output_step: float = setting(0.01, "number", POSITIVE)
    fixed_step: float = setting(1e-3, "number", POSITIVE)  # step of the fixed-step method
    max_steps: int = setting(200000, "integer", POSITIVE, WHOLE)


#: the sections declared with :func:`core.settings.setting`, by their table name
SECTIONS: dict[str, type] = {
    "observer": Observer,
    "controller": Controller,
    "options": Options,
    "initial": Initial,
    "integration": Integration,
}


@dataclass(frozen=True)
class Scenario:
    """A fully validated scenario.

    Making one (directly, by the loader or by :func:`dataclasses.replace`) runs
    :meth:`validate`, so a scenario held in memory always satisfies every check.
    """

    name: str
    path: str
    sha256: str
    description: str
    leader: Leader
    graph: Graph
    followers: tuple[Follower, ...]
    observer: Observer
    controller: Controller
    options: Options
    initial: Initial
    integration: Integration

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every declared setting and every rule of :data:`RULES`.

        Raises
        ------
        ScenarioError
            The first violation, naming the key (and the 0-based position in a list).
        """
        for section, cls in SECTIONS.items():
            obj = getattr(self, section)
            for name, s in settings_of(cls).items():
                bad = s.violation(getattr(obj, name))
                if bad is not None:
                    where, problem, expected = bad
                    raise ScenarioError(self.path, f"{section}.{name}{where}", problem, expected)
        for rule in RULES:
            broken = rule.broken(self)
            if broken is not None:
                raise ScenarioError(self.path, rule.key, *broken)

    @property
    def N(self) -> int:
        return self.graph.N

    @property
    def n(self) -> int:
        return self.leader.n

    @property
    def m(self) -> int:
        return self.leader.m

    @property
    def p(self) -> int:
        return self.leader.p

    def breakpoints(self) -> tuple[float, ...]:
        """Known discontinuities in time inside (0, horizon): faults, steps in inputs, graph switches."""
        H = self.integration.horizon
        times: set[float] = set()
        slots = self.options.fault_slots
        exact = {t for fo in self.followers for t in fault_times(fo.faults, H, slots)}
        for fo in self.followers:
            times.update(fo.g.breakpoints)
            for e in fo.f:
                times.update(e.breakpoints())
        if self.leader.u0 is not None:
            for e in self.leader.u0:
                times.update(e.breakpoints())
        elif self.leader.u0_hold and self.leader.u0_rise > 0:  # rows and rows + rise
            times.update(shaped_breakpoints(self.leader.u0_trace, self.leader.u0_rise))
        elif self.leader.u0_hold:  # each row of a held trace is a jump
            times.update(float(t) for t in self.leader.u0_trace[:, 0])
        exact |= set(switch_times(self.graph.switches))  # the graph switches exactly then
        # a root found numerically in f may differ from a fault's onset by rounding: keep the onset
        times = {t for t in times if not any(_near(t, x) for x in exact)} | exact
        return tuple(sorted(t for t in times if 0.0 < t < H))


def _near(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same time up to rounding (a few ulps), but not equal."""
    return a != b and abs(a - b) <= 1e-12 * max(1.0, abs(b))


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
    return settings_of(SECTIONS[section])[name].type_text(words)


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
    integ = _section(ctx, Integration, data.get("integration", {}), "integration", None)
    tgrid = np.linspace(0.0, integ.horizon, 4001)
    leader = _leader(ctx, data["leader"], path, integ.horizon, tgrid)
    graph = _graph(ctx, data["graph"], integ.horizon)
    dims = Dims(N=graph.N, n=leader.n, m=leader.m, p=leader.p)
    check_output_size(ctx, integ, dims.N, dims.n, dims.m)
    options = _section(ctx, Options, data.get("options", {}), "options", dims)
    followers = _followers(ctx, data["followers"], dims.n, dims.N, tgrid, options.fault_slots)
    return Scenario(
        name=name,
        path=str(path),
        sha256=sha,
        description=desc,
        leader=leader,
        graph=graph,
        followers=followers,
        observer=_section(ctx, Observer, data.get("observer", {}), "observer", dims),
        controller=_controller(ctx, data.get("controller", {}), dims),
        options=options,
        initial=_section(ctx, Initial, data.get("initial", {}), "initial", dims),
        integration=integ,
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


# --------------------------------------------------------------------------- declared sections
_Section = TypeVar("_Section")  # one of the dataclasses of SECTIONS


def _section(
    ctx: ReadingContext, cls: type[_Section], raw: Any, key: str, dims: Dims | None
) -> _Section:
    """A table of a declared section: every field read with its :class:`Setting`.

    Unknown keys are refused; an omitted key takes the field's default.
    """
    declared = settings_of(cls)
    table = ctx.table(raw, key, set(declared))
    sizes = dims._asdict() if dims is not None else None
    values = {
        name: _read(ctx, s, table.get(name, s.default), f"{key}.{name}", sizes)
        for name, s in declared.items()
    }
    return cls(**values)


def _read(ctx: ReadingContext, s: Setting, v: Any, key: str, dims: Mapping[str, int] | None) -> Any:
    """One TOML value read as setting ``s`` says (``"synthesize"``, ``"none"`` -> None where allowed).

    ``dims`` holds the sizes known so far by symbol (:class:`Dims` or a part of it);
    a matrix or vector dimension not yet known is not checked.
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


def _key(
    ctx: ReadingContext,
    table: Mapping[str, Setting],
    raw: dict,
    prefix: str,
    name: str,
    dims: Mapping,
) -> Any:
    """Key ``name`` of a table read key by key: its value, or its declared default, read."""
    s = table[name]
    v = raw[name] if name in raw else s.default_for(dims)
    return _read(ctx, s, v, f"{prefix}.{name}", dims)


def _controller(ctx: ReadingContext, raw: Any, dims: Dims) -> Controller:
    """The [controller] table: every gain is given (none can be synthesised)."""
    if isinstance(raw, dict):
        for k, v in raw.items():
            if v == SYNTH:
                raise ctx.err(
                    f"controller.{k}",
                    "cannot be synthesised (the paper gives no design procedure for it)",
                    "a number",
                )
    return _section(ctx, Controller, raw, "controller", dims)


# --------------------------------------------------------------------------- leader, graph
def _leader(ctx: ReadingContext, raw: Any, path: Path, horizon: float, tgrid: np.ndarray) -> Leader:
    """The [leader] table, eq. (3); ‖u0‖ ≤ α is checked on [0, horizon]."""
    L = ctx.table(raw, "leader", set(LEADER), required_keys(LEADER))
    sizes: dict[str, int] = {}
    A0 = _key(ctx, LEADER, L, "leader", "A0", sizes)
    m = sizes["m"] = A0.shape[0]
    if A0.shape[1] != m:
        raise ctx.err(
            "leader.A0", f"has shape {A0.shape[0]}x{A0.shape[1]}", "a square matrix m x m"
        )
    B0 = _key(ctx, LEADER, L, "leader", "B0", sizes)
    C0 = _key(ctx, LEADER, L, "leader", "C0", sizes)
    sizes.update(p=B0.shape[1], n=C0.shape[0])
    eta0 = _key(ctx, LEADER, L, "leader", "eta0", sizes)
    alpha = _key(ctx, LEADER, L, "leader", "alpha", sizes)
    if ("u0" in L) == ("u0_csv" in L):
        raise ctx.err(
            "leader.u0",
            "give exactly one of u0 and u0_csv",
            "u0 = [expressions of t] or u0_csv = 'file.csv'",
        )
    p = sizes["p"]
    rise = _key(ctx, LEADER, L, "leader", "u0_rise", sizes) if "u0_rise" in L else None
    shape = _key(ctx, LEADER, L, "leader", "u0_shape", sizes)
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
    hold = _key(ctx, LEADER, L, "leader", "u0_hold", sizes)
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


def _graph(ctx: ReadingContext, raw: Any, horizon: float) -> Graph:
    """The [graph] table; every follower must be reachable from the leader (Assumption 1)."""
    G = ctx.table(raw, "graph", set(GRAPH), required_keys(GRAPH))
    A = _key(ctx, GRAPH, G, "graph", "adjacency", {})
    N = A.shape[0]
    if A.shape[1] != N:
        raise ctx.err(
            "graph.adjacency", f"has shape {A.shape[0]}x{A.shape[1]}", "a square N x N matrix"
        )
    if np.any(np.diag(A) != 0):
        raise ctx.err("graph.adjacency", "has a non-zero diagonal (self-loop)", "a_ii = 0")
    pin = _key(ctx, GRAPH, G, "graph", "pinning", {"N": N})
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
    return Graph(adjacency=A, pinning=pin, switches=switches)


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


def _followers(
    ctx: ReadingContext, F: Any, n: int, N: int, tgrid: np.ndarray, slots: int | None = None
) -> tuple[Follower, ...]:
    """The [[followers]] tables, one per row of the adjacency matrix (``slots``: fault_slots)."""
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
        p0=_key(ctx, FOLLOWER, fo, key, "p0", sizes),
        q0=_key(ctx, FOLLOWER, fo, key, "q0", sizes),
        b0=_key(ctx, FOLLOWER, fo, key, "b0", sizes),
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
    d = _key(ctx, FOLLOWER, fo, key, "d", {"n": n})
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
        terms = [("num", vals[0])] + [
            ("bin", "*", ("num", b - a), ("call", "step", (("bin", "-", ("t",), ("num", t0)),)))
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
    values = {k: _read(ctx, FAULT[k], raw[k], f"{key}.{k}", {"n": n}) for k in names[1:]}
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


def _balanced_sum(terms: list[tuple]) -> tuple:
    """A sum as a balanced tree, so long tables stay shallow for the recursive evaluators."""
    if len(terms) == 1:
        return terms[0]
    mid = len(terms) // 2
    return ("bin", "+", _balanced_sum(terms[:mid]), _balanced_sum(terms[mid:]))
