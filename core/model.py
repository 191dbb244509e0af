"""The scenario data model: frozen dataclasses of every section, validated on construction.

:class:`Scenario` holds a run completely (leader, graph, followers, observer, controller,
options, initial states, integration); :meth:`Scenario.validate` checks the rules between
settings (core/rules.py) on every construction. The loader is :mod:`core.scenario`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from core import methods
from core.errors import ScenarioError
from core.expressions import Expr
from core.faults import (
    SLOT_COUNT,
    Fault,
    fault_times,
)
from core.graph import (
    DEFAULT_LINK_FADE,
    Switch,
    Topology,
    iter_topologies,
    switch_times,
)
from core.hold import shaped_breakpoints, shaped_hold
from core.rules import RULES
from core.settings import (
    NONNEG,
    OFF,
    POSITIVE,
    SYNTH,
    WHOLE,
    Check,
    setting,
    settings_of,
)
from core.shaping import DEFAULT_SHAPE

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
_AT_LEAST_ONE = Check("≥ 1", lambda x: x >= 1.0, "{v} is below 1", "a factor >= 1")
_ABOVE_ONE = Check("> 1", lambda x: x > 1.0, "{v} is not above 1", "a factor > 1")
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
    link_fade: float = DEFAULT_LINK_FADE  # s a switched link's weight fades over (0: raw)

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
    """Integration settings (``generated.values.IntegratorSettings`` takes these defaults)."""

    method: str = setting("cvodes", "choice", options=METHODS)
    rtol: float = setting(1e-6, "number", POSITIVE, _BELOW_ONE)
    atol: float = setting(1e-8, "number", POSITIVE)
    horizon: float = setting(20.0, "number", POSITIVE, _HORIZON_RANGE)
    output_step: float = setting(0.01, "number", POSITIVE)
    fixed_step: float = setting(1e-3, "number", POSITIVE)  # step of the fixed-step method
    max_steps: int = setting(200000, "integer", POSITIVE, WHOLE)


@dataclass(frozen=True, kw_only=True)
class Design:
    """What designed gains must tolerate and respect (``[design]``, docs/synthesis.md, 'Design').

    Absent, a scenario is run with its own gains (``Scenario.design`` is None). Every
    per-follower entry may be one number for every follower.
    """

    # tolerate: g_i in [g_min_i, 1] (the ĝ projection interval [1, 1/g_min] follows)
    g_min: np.ndarray = setting(0.5, "per_follower", POSITIVE, _G_MIN_RANGE)  # N
    # |f_ir| <= d_ir; "none" = each follower's own d (given or sup |f_ir|)
    d: np.ndarray | None = setting(OFF, "per_coordinate", NONNEG, off=True)  # N×n
    # ‖u0‖ <= alpha; "none" = leader.alpha
    alpha: float | None = setting(OFF, "number", POSITIVE, off=True)
    # respect: peak ‖u_i‖ after the start-up (a rule requires it)
    u_max: np.ndarray | None = setting(OFF, "per_follower", POSITIVE, off=True)  # N
    startup: float = setting(1.0, "number", POSITIVE)  # s: the start-up the budget excludes
    # optional gain-norm caps: ‖Q‖, ‖Θ‖ (spectral), max k1ir; "none" = no cap
    Q_max: float | None = setting(OFF, "number", POSITIVE, off=True)
    Theta_max: float | None = setting(OFF, "number", POSITIVE, off=True)
    k1_max: float | None = setting(OFF, "number", POSITIVE, off=True)
    # the ultimate bound may be this factor above the best one within the budget (time for level)
    bound_slack: float = setting(1.5, "number", _AT_LEAST_ONE)
    # the observer's robust gain lambda2 as a multiple of alpha (phi_min keeps lambda2/phi_min)
    robust_gain: float = setting(2.0, "number", _ABOVE_ONE)


#: the sections declared with :func:`core.settings.setting`, by their table name
SECTIONS: dict[str, type] = {
    "observer": Observer,
    "controller": Controller,
    "options": Options,
    "initial": Initial,
    "integration": Integration,
}
#: declared sections that may be absent (held as None): today's behaviour without them
OPTIONAL_SECTIONS: dict[str, type] = {"design": Design}


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
    design: Design | None = None

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every declared setting and every rule of :data:`RULES`.

        Raises
        ------
        ScenarioError
            The first violation, naming the key (and the 0-based position in a list).
        """
        for section, cls in {**SECTIONS, **OPTIONAL_SECTIONS}.items():
            obj = getattr(self, section)
            if obj is None:  # an optional section that is absent
                continue
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
        if self.graph.link_fade > 0:  # and its fades end (σ'' is continuous there: accuracy)
            exact |= {s + self.graph.link_fade for s in switch_times(self.graph.switches)}
        # a root found numerically in f may differ from a fault's onset by rounding: keep the onset
        times = {t for t in times if not any(_near(t, x) for x in exact)} | exact
        return tuple(sorted(t for t in times if 0.0 < t < H))


def _near(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same time up to rounding (a few ulps), but not equal."""
    return a != b and abs(a - b) <= 1e-12 * max(1.0, abs(b))
