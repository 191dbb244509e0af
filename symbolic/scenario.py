"""Scenario files: one TOML file fully describes one run.

:func:`load_scenario` reads a file with :mod:`tomllib`, validates every field
on load and returns a frozen :class:`Scenario`. Every problem is a
:class:`~symbolic.errors.ScenarioError` naming the file, the key, what is wrong
and what is expected. The key names are documented in the README
("Scenario files"); ``scenarios/paper.toml`` is the paper's Table 2.
"""

from __future__ import annotations

import csv
import hashlib
import math
import tomllib
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from symbolic.errors import ExpressionError, ScenarioError
from symbolic.expressions import Expr, parse_expression

SYNTH = "synthesize"
SIGN_MODES = ("exact", "sat", "tanh")
GHAT_LAWS = ("paper", "sigma", "projection", "sigma+projection")
DERIVATIVES = ("oracle", "filtered")
METHODS = ("cvodes", "idas", "fixed")
START_MODES = ("given", "formation")


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

    @property
    def m(self) -> int:
        return self.A0.shape[0]

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

    @property
    def N(self) -> int:
        return self.adjacency.shape[0]

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


@dataclass(frozen=True)
class Observer:
    """Distributed observer (9) and UIO (6)–(8) gains; ``None`` means ``"synthesize"``."""

    lambda1: float | None
    lambda2: float | None
    Q: np.ndarray | None  # p×m
    Theta: np.ndarray | None  # m×n
    alpha1: np.ndarray  # N
    alpha1_bar: np.ndarray  # N
    phi0: np.ndarray  # N, φ_i(0) > 0
    phi_min: float  # floor of φ_i (0 = the paper's law)
    lambda_bar1: float  # LMI (15)
    delta1: float  # LMI (15)
    delta2: float  # LMI (16)
    delta1_hat: float  # 0 < δ̂1 < δ1 (k1 and the supported decay rate)
    delta2_hat: float  # 0 < δ̂2 < δ2
    margin: float  # relative margin for λ1 > λ̄1/w and λ2 ≥ α when synthesised


@dataclass(frozen=True)
class Controller:
    """Fault-tolerant controller (29)–(30) gains, per agent and component."""

    Lambda: np.ndarray  # N×n, λ_ir
    k1: np.ndarray  # N×n, K_i = diag(k1ir)
    k2: np.ndarray  # N, k2i
    gamma: np.ndarray  # N, adaptation gain of ĝ (1 = the paper's law)
    sigma: np.ndarray  # N, σ-modification (used by ghat_law 'sigma*')
    ghat_ref: np.ndarray  # N, ĝ0 of the σ-modification
    g_min: float  # designer's worst health: projection onto [1, 1/g_min]


@dataclass(frozen=True)
class Options:
    """Controller and model options."""

    sign: str  # exact | sat | tanh
    sign_width: float  # ε of sat(χ/ε), tanh(χ/ε)
    ghat_law: str  # paper | sigma | projection | sigma+projection
    feedforward: bool  # include ḃ, b̈ in (28)–(29) (False = eq. (29) as printed)
    ablation: bool  # eq. (42): u = Ψ (no ĝ)
    derivatives: str  # oracle | filtered
    filter_bandwidth: float  # rad/s, filtered derivatives
    tau_threshold: float  # ‖η̇_i‖ below which the formation angle τ_i is faded out


@dataclass(frozen=True)
class Initial:
    """Initial estimator states."""

    eta: np.ndarray  # N×m, η_i(0)
    mu: np.ndarray  # N×m, μ_i(0)
    theta_hat: np.ndarray  # N×n
    ghat: np.ndarray  # N
    start: str  # given | formation


@dataclass(frozen=True)
class Integration:
    """Integration settings."""

    method: str  # cvodes | idas | fixed
    rtol: float
    atol: float
    horizon: float
    output_step: float
    fixed_step: float  # step of the fixed-step method
    max_steps: int


@dataclass(frozen=True)
class Scenario:
    """A fully validated scenario."""

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
        """Known discontinuities in time inside (0, horizon): faults, steps in inputs."""
        times: set[float] = set()
        for fo in self.followers:
            times.update(fo.g.breakpoints)
            for e in fo.f:
                times.update(e.breakpoints())
        if self.leader.u0 is not None:
            for e in self.leader.u0:
                times.update(e.breakpoints())
        H = self.integration.horizon
        return tuple(sorted(t for t in times if 0.0 < t < H))


# --------------------------------------------------------------------------- schema
_TOP = {
    "name",
    "description",
    "leader",
    "graph",
    "followers",
    "observer",
    "controller",
    "options",
    "initial",
    "integration",
}
_LEADER = {"A0", "B0", "C0", "eta0", "u0", "u0_csv", "alpha"}
_GRAPH = {"adjacency", "pinning"}
_FOLLOWER = {"model", "params", "p0", "q0", "b0", "g", "f", "d"}
_OBSERVER = {
    "lambda1", "lambda2", "Q", "Theta", "alpha1", "alpha1_bar", "phi0", "phi_min",
    "lambda_bar1", "delta1", "delta2", "delta1_hat", "delta2_hat", "margin",
}  # fmt: skip
_CONTROLLER = {"Lambda", "k1", "k2", "gamma", "sigma", "ghat_ref", "g_min"}
_OPTIONS = {
    "sign",
    "sign_width",
    "ghat_law",
    "feedforward",
    "ablation",
    "derivatives",
    "filter_bandwidth",
    "tau_threshold",
}
_INITIAL = {"eta", "mu", "theta_hat", "ghat", "start"}
_INTEGRATION = {"method", "rtol", "atol", "horizon", "output_step", "fixed_step", "max_steps"}


class _Ctx:
    """Carries the file name into every error."""

    def __init__(self, file: str) -> None:
        self.file = file

    def err(self, key: str, problem: str, expected: str = "") -> ScenarioError:
        return ScenarioError(self.file, key, problem, expected)

    # -- structure
    def table(
        self, obj: Any, key: str, allowed: set[str], required: set[str] = frozenset()
    ) -> dict:
        if not isinstance(obj, dict):
            raise self.err(key, f"is a {type(obj).__name__}", "a table")
        for k in obj:
            if k not in allowed:
                raise self.err(
                    f"{key}.{k}" if key else k,
                    "unknown key",
                    "one of " + ", ".join(sorted(allowed)),
                )
        for k in required:
            if k not in obj:
                raise self.err(f"{key}.{k}" if key else k, "missing", "a value")
        return obj

    # -- numbers
    def number(self, v: Any, key: str, *, positive: bool = False, nonneg: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.err(key, f"{v!r} is not a number", "a finite number")
        x = float(v)
        if not math.isfinite(x):
            raise self.err(key, f"{v!r} is not finite", "a finite number")
        if positive and x <= 0:
            raise self.err(key, f"{x} is not positive", "a value > 0")
        if nonneg and x < 0:
            raise self.err(key, f"{x} is negative", "a value >= 0")
        return x

    def matrix(self, v: Any, key: str, shape: tuple[int | None, int | None]) -> np.ndarray:
        if not isinstance(v, list) or not v or not all(isinstance(r, list) for r in v):
            raise self.err(key, "is not a list of rows", f"a matrix of shape {_shape_txt(shape)}")
        ncols = {len(r) for r in v}
        if len(ncols) != 1:
            raise self.err(
                key, "rows have different lengths", f"a matrix of shape {_shape_txt(shape)}"
            )
        arr = np.array(
            [[self.number(x, f"{key}[{i}][{j}]") for j, x in enumerate(r)] for i, r in enumerate(v)]
        )
        for ax, want in enumerate(shape):
            if want is not None and arr.shape[ax] != want:
                raise self.err(
                    key, f"has shape {arr.shape[0]}x{arr.shape[1]}", f"shape {_shape_txt(shape)}"
                )
        arr.setflags(write=False)
        return arr

    def vector(self, v: Any, key: str, length: int | None, **kw: bool) -> np.ndarray:
        if not isinstance(v, list):
            raise self.err(
                key, f"{v!r} is not a list", f"a list of {length if length else 'some'} numbers"
            )
        if length is not None and len(v) != length:
            raise self.err(key, f"has {len(v)} entries", f"{length} entries")
        arr = np.array([self.number(x, f"{key}[{i}]", **kw) for i, x in enumerate(v)])
        arr.setflags(write=False)
        return arr

    def per_agent(self, v: Any, key: str, N: int, **kw: bool) -> np.ndarray:
        """A scalar broadcast to N agents, or a list of N numbers."""
        if isinstance(v, list):
            return self.vector(v, key, N, **kw)
        arr = np.full(N, self.number(v, key, **kw))
        arr.setflags(write=False)
        return arr

    def per_agent_comp(self, v: Any, key: str, N: int, n: int, **kw: bool) -> np.ndarray:
        """Scalar, list of N scalars, or list of N lists of n numbers -> N×n."""
        if not isinstance(v, list):
            arr = np.full((N, n), self.number(v, key, **kw))
        else:
            if len(v) != N:
                raise self.err(
                    key, f"has {len(v)} entries", f"a scalar or {N} entries (one per follower)"
                )
            rows = []
            for i, x in enumerate(v):
                if isinstance(x, list):
                    rows.append(self.vector(x, f"{key}[{i}]", n, **kw))
                else:
                    rows.append(np.full(n, self.number(x, f"{key}[{i}]", **kw)))
            arr = np.array(rows)
        arr.setflags(write=False)
        return arr

    def choice(self, v: Any, key: str, options: tuple[str, ...]) -> str:
        if v not in options:
            raise self.err(key, f"{v!r} is not allowed", "one of " + ", ".join(options))
        return v

    def boolean(self, v: Any, key: str) -> bool:
        if not isinstance(v, bool):
            raise self.err(key, f"{v!r} is not a boolean", "true or false")
        return v

    def expr(self, v: Any, key: str) -> Expr:
        try:
            return parse_expression(v, where=f"{self.file}: {key}")
        except ExpressionError:
            raise
        except (
            ValueError,
            TypeError,
            RecursionError,
            MemoryError,
        ) as exc:  # defensive: never a traceback
            raise self.err(
                key, f"cannot parse expression ({type(exc).__name__})", "an expression of t"
            ) from None


def _shape_txt(shape: tuple[int | None, int | None]) -> str:
    return "x".join("?" if s is None else str(s) for s in shape)


def _freeze(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


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
    ctx = _Ctx(str(path))
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ctx.err(
            "(file)", f"cannot be read: {exc.strerror}", "an existing TOML file"
        ) from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ctx.err("(file)", "is not UTF-8 text", "a UTF-8 TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ctx.err("(file)", f"malformed TOML: {exc}", "valid TOML") from None
    try:
        return _build(ctx, data, path, hashlib.sha256(raw).hexdigest())
    except ScenarioError:
        raise
    except ExpressionError:
        raise
    except RecursionError:
        raise ctx.err("(file)", "nested too deeply", "a flat scenario table") from None


def _build(ctx: _Ctx, data: dict, path: Path, sha: str) -> Scenario:
    from symbolic.models import REGISTRY

    ctx.table(data, "", _TOP, {"leader", "graph", "followers"})
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "-_." for c in name):
        raise ctx.err("name", f"{name!r} is not a plain name", "letters, digits, '-', '_' or '.'")
    desc = data.get("description", "")
    if not isinstance(desc, str):
        raise ctx.err("description", "is not a string", "a string")

    # ---- leader
    L = ctx.table(data["leader"], "leader", _LEADER, {"A0", "B0", "C0", "alpha"})
    A0 = ctx.matrix(L["A0"], "leader.A0", (None, None))
    m = A0.shape[0]
    if A0.shape[1] != m:
        raise ctx.err(
            "leader.A0", f"has shape {A0.shape[0]}x{A0.shape[1]}", "a square matrix m x m"
        )
    B0 = ctx.matrix(L["B0"], "leader.B0", (m, None))
    C0 = ctx.matrix(L["C0"], "leader.C0", (None, m))
    p, n = B0.shape[1], C0.shape[0]
    eta0 = ctx.vector(L.get("eta0", [0.0] * m), "leader.eta0", m)
    alpha = ctx.number(L["alpha"], "leader.alpha", positive=True)
    if ("u0" in L) == ("u0_csv" in L):
        raise ctx.err(
            "leader.u0",
            "give exactly one of u0 and u0_csv",
            "u0 = [expressions of t] or u0_csv = 'file.csv'",
        )
    u0: tuple[Expr, ...] | None = None
    trace: np.ndarray | None = None
    if "u0" in L:
        if not isinstance(L["u0"], list) or len(L["u0"]) != p:
            raise ctx.err(
                "leader.u0",
                f"has {len(L['u0']) if isinstance(L['u0'], list) else 'no list of'} entries",
                f"a list of {p} expressions (p = columns of B0)",
            )
        u0 = tuple(ctx.expr(e, f"leader.u0[{k}]") for k, e in enumerate(L["u0"]))
    else:
        trace = _load_trace(ctx, path, L["u0_csv"], p)

    # ---- graph
    G = ctx.table(data["graph"], "graph", _GRAPH, {"adjacency", "pinning"})
    Aadj = ctx.matrix(G["adjacency"], "graph.adjacency", (None, None))
    N = Aadj.shape[0]
    if Aadj.shape[1] != N:
        raise ctx.err(
            "graph.adjacency", f"has shape {Aadj.shape[0]}x{Aadj.shape[1]}", "a square N x N matrix"
        )
    if np.any(np.diag(Aadj) != 0):
        raise ctx.err("graph.adjacency", "has a non-zero diagonal (self-loop)", "a_ii = 0")
    pin = ctx.vector(G["pinning"], "graph.pinning", N, nonneg=True)
    unreachable = _unreachable(Aadj, pin)
    if unreachable:
        names = ", ".join(str(i + 1) for i in unreachable)
        raise ctx.err("graph", f"follower(s) {names} cannot be reached from the leader (Assumption 1)",
                      "a directed spanning tree rooted at the leader: add a pinning a_i0 > 0 or an edge a_ij != 0 from a reachable agent")  # fmt: skip

    # ---- integration (needed to check g_i and f_i over the horizon)
    I = ctx.table(data.get("integration", {}), "integration", _INTEGRATION)
    integ = Integration(
        method=ctx.choice(I.get("method", "cvodes"), "integration.method", METHODS),
        rtol=ctx.number(I.get("rtol", 1e-6), "integration.rtol", positive=True),
        atol=ctx.number(I.get("atol", 1e-8), "integration.atol", positive=True),
        horizon=ctx.number(I.get("horizon", 20.0), "integration.horizon", positive=True),
        output_step=ctx.number(
            I.get("output_step", 0.01), "integration.output_step", positive=True
        ),
        fixed_step=ctx.number(I.get("fixed_step", 1e-3), "integration.fixed_step", positive=True),
        max_steps=int(
            ctx.number(I.get("max_steps", 200000), "integration.max_steps", positive=True)
        ),
    )
    if integ.output_step > integ.horizon:
        raise ctx.err(
            "integration.output_step",
            f"{integ.output_step} exceeds the horizon {integ.horizon}",
            "output_step <= horizon",
        )
    tgrid = np.linspace(0.0, integ.horizon, 4001)

    # ---- followers
    F = data["followers"]
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
    followers = []
    for i, fo in enumerate(F):
        key = f"followers[{i + 1}]"
        ctx.table(fo, key, _FOLLOWER, {"model", "p0", "b0"})
        model = fo["model"]
        if model not in REGISTRY:
            raise ctx.err(
                f"{key}.model",
                f"{model!r} is not a known model",
                "one of " + ", ".join(sorted(REGISTRY)),
            )
        spec = REGISTRY[model]
        if spec.n != n:
            raise ctx.err(
                f"{key}.model",
                f"{model!r} has n = {spec.n} coordinates but C0 has {n} rows",
                f"a model with n = {n}",
            )
        prm = ctx.table(fo.get("params", {}), f"{key}.params", set(spec.defaults))
        params = {
            k: ctx.number(prm.get(k, v), f"{key}.params.{k}") for k, v in spec.defaults.items()
        }
        health = _health(ctx, fo.get("g", 1.0), f"{key}.g", tgrid)
        f_raw = fo.get("f", [0.0] * n)
        if not isinstance(f_raw, list) or len(f_raw) != n:
            raise ctx.err(
                f"{key}.f", "wrong number of components", f"a list of {n} expressions of t"
            )
        f = tuple(ctx.expr(e, f"{key}.f[{r}]") for r, e in enumerate(f_raw))
        fvals = np.array([np.broadcast_to(e.numpy(tgrid), tgrid.shape) for e in f])
        if not np.all(np.isfinite(fvals)):
            raise ctx.err(
                f"{key}.f",
                "is not finite somewhere on [0, horizon]",
                "a bounded disturbance (Assumption 3)",
            )
        if "d" in fo:
            d = ctx.vector(fo["d"], f"{key}.d", n, nonneg=True)
            worst = np.abs(fvals).max(axis=1)
            if np.any(worst > d * (1 + 1e-9)):
                r = int(np.argmax(worst - d))
                raise ctx.err(
                    f"{key}.d",
                    f"|f[{r}]| reaches {worst[r]:.4g} > d = {d[r]:.4g}",
                    "d_ir >= sup |f_ir(t)| (Assumption 3)",
                )
        else:
            d = _freeze(np.abs(fvals).max(axis=1))
        followers.append(
            Follower(
                model=model,
                params=params,
                p0=ctx.vector(fo["p0"], f"{key}.p0", n),
                q0=ctx.vector(fo.get("q0", [0.0] * n), f"{key}.q0", n),
                b0=ctx.vector(fo["b0"], f"{key}.b0", n),
                g=health,
                f=f,
                d=d,
            )
        )

    # ---- observer
    O = ctx.table(data.get("observer", {}), "observer", _OBSERVER)

    def gain(key: str, default: Any, conv):  # noqa: ANN001
        v = O.get(key, default)
        return None if v == SYNTH else conv(v, f"observer.{key}")

    obs = Observer(
        lambda1=gain("lambda1", SYNTH, lambda v, k: ctx.number(v, k, positive=True)),
        lambda2=gain("lambda2", SYNTH, lambda v, k: ctx.number(v, k, positive=True)),
        Q=gain("Q", SYNTH, lambda v, k: ctx.matrix(v, k, (p, m))),
        Theta=gain("Theta", SYNTH, lambda v, k: ctx.matrix(v, k, (m, n))),
        alpha1=ctx.per_agent(O.get("alpha1", 1.0), "observer.alpha1", N, positive=True),
        alpha1_bar=ctx.per_agent(O.get("alpha1_bar", 1.0), "observer.alpha1_bar", N, positive=True),
        phi0=ctx.per_agent(O.get("phi0", 1.0), "observer.phi0", N, positive=True),
        phi_min=ctx.number(O.get("phi_min", 0.0), "observer.phi_min", nonneg=True),
        lambda_bar1=ctx.number(O.get("lambda_bar1", 1.0), "observer.lambda_bar1", positive=True),
        delta1=ctx.number(O.get("delta1", 0.5), "observer.delta1", positive=True),
        delta2=ctx.number(O.get("delta2", 1.0), "observer.delta2", positive=True),
        delta1_hat=ctx.number(O.get("delta1_hat", 0.25), "observer.delta1_hat", positive=True),
        delta2_hat=ctx.number(O.get("delta2_hat", 0.5), "observer.delta2_hat", positive=True),
        margin=ctx.number(O.get("margin", 0.05), "observer.margin", nonneg=True),
    )
    if obs.delta1_hat >= obs.delta1:
        raise ctx.err(
            "observer.delta1_hat",
            f"{obs.delta1_hat} >= delta1 = {obs.delta1}",
            "0 < delta1_hat < delta1",
        )
    if obs.delta2_hat >= obs.delta2:
        raise ctx.err(
            "observer.delta2_hat",
            f"{obs.delta2_hat} >= delta2 = {obs.delta2}",
            "0 < delta2_hat < delta2",
        )
    if np.any(obs.phi0 <= obs.phi_min):
        raise ctx.err(
            "observer.phi0", "phi0 must exceed phi_min", f"phi0 > phi_min = {obs.phi_min}"
        )

    # ---- controller
    Cc = ctx.table(data.get("controller", {}), "controller", _CONTROLLER)
    for k in _CONTROLLER:
        if Cc.get(k) == SYNTH:
            raise ctx.err(
                f"controller.{k}",
                "cannot be synthesised (the paper gives no design procedure for it)",
                "a number",
            )
    ctrl = Controller(
        Lambda=ctx.per_agent_comp(Cc.get("Lambda", 40.0), "controller.Lambda", N, n, positive=True),
        k1=ctx.per_agent_comp(Cc.get("k1", 20.0), "controller.k1", N, n, positive=True),
        k2=ctx.per_agent(Cc.get("k2", 1.0), "controller.k2", N, positive=True),
        gamma=ctx.per_agent(Cc.get("gamma", 1.0), "controller.gamma", N, positive=True),
        sigma=ctx.per_agent(Cc.get("sigma", 0.0), "controller.sigma", N, nonneg=True),
        ghat_ref=ctx.per_agent(Cc.get("ghat_ref", 1.0), "controller.ghat_ref", N, positive=True),
        g_min=ctx.number(Cc.get("g_min", 0.5), "controller.g_min", positive=True),
    )
    if not ctrl.g_min <= 1.0:
        raise ctx.err("controller.g_min", f"{ctrl.g_min} is outside (0, 1]", "0 < g_min <= 1")

    # ---- options
    Op = ctx.table(data.get("options", {}), "options", _OPTIONS)
    opts = Options(
        sign=ctx.choice(Op.get("sign", "tanh"), "options.sign", SIGN_MODES),
        sign_width=ctx.number(Op.get("sign_width", 0.05), "options.sign_width", positive=True),
        ghat_law=ctx.choice(Op.get("ghat_law", "paper"), "options.ghat_law", GHAT_LAWS),
        feedforward=ctx.boolean(Op.get("feedforward", True), "options.feedforward"),
        ablation=ctx.boolean(Op.get("ablation", False), "options.ablation"),
        derivatives=ctx.choice(Op.get("derivatives", "oracle"), "options.derivatives", DERIVATIVES),
        filter_bandwidth=ctx.number(
            Op.get("filter_bandwidth", 50.0), "options.filter_bandwidth", positive=True
        ),
        tau_threshold=ctx.number(
            Op.get("tau_threshold", 1e-3), "options.tau_threshold", positive=True
        ),
    )
    if "sigma" in opts.ghat_law and np.any(ctrl.sigma <= 0):
        raise ctx.err(
            "controller.sigma", f"ghat_law {opts.ghat_law!r} needs sigma > 0", "sigma > 0"
        )
    if opts.sign == "exact" and integ.method != "fixed":
        raise ctx.err(
            "options.sign",
            "'exact' makes variable-step integrators chatter and fail",
            "sign = 'tanh' or 'sat', or integration.method = 'fixed'",
        )

    # ---- initial estimator states
    In = ctx.table(data.get("initial", {}), "initial", _INITIAL)
    init = Initial(
        eta=_rows(ctx, In.get("eta", 0.0), "initial.eta", N, m),
        mu=_rows(ctx, In.get("mu", 0.0), "initial.mu", N, m),
        theta_hat=_rows(ctx, In.get("theta_hat", 0.0), "initial.theta_hat", N, n, nonneg=True),
        ghat=ctx.per_agent(In.get("ghat", 1.0), "initial.ghat", N, positive=True),
        start=ctx.choice(In.get("start", "given"), "initial.start", START_MODES),
    )

    return Scenario(
        name=name,
        path=str(path),
        sha256=sha,
        description=desc,
        leader=Leader(A0=A0, B0=B0, C0=C0, eta0=eta0, u0=u0, u0_trace=trace, alpha=alpha),
        graph=Graph(adjacency=Aadj, pinning=pin),
        followers=tuple(followers),
        observer=obs,
        controller=ctrl,
        options=opts,
        initial=init,
        integration=integ,
    )


def _rows(ctx: _Ctx, v: Any, key: str, N: int, k: int, **kw: bool) -> np.ndarray:
    """Scalar (all entries), one k-vector (every agent) or N k-vectors -> N×k."""
    if isinstance(v, list) and v and not isinstance(v[0], list):
        row = ctx.vector(v, key, k, **kw)
        return _freeze(np.tile(row, (N, 1)))
    return ctx.per_agent_comp(v, key, N, k, **kw)


def _health(ctx: _Ctx, v: Any, key: str, tgrid: np.ndarray) -> Health:
    """g_i(t): constant, table [[t_start, value], ...] or expression; checked in (0, 1]."""
    if isinstance(v, list):
        if not v or not all(isinstance(r, list) and len(r) == 2 for r in v):
            raise ctx.err(
                key, "is not a table of [t_start, value] pairs", "e.g. [[0.0, 1.0], [5.0, 0.6]]"
            )
        rows = [
            (ctx.number(a, f"{key}[{k}][0]", nonneg=True), ctx.number(b, f"{key}[{k}][1]"))
            for k, (a, b) in enumerate(v)
        ]
        if rows[0][0] != 0.0:
            raise ctx.err(f"{key}[0][0]", f"first segment starts at {rows[0][0]}", "0.0")
        if any(b[0] <= a[0] for a, b in zip(rows, rows[1:], strict=False)):
            raise ctx.err(
                key, "segment start times are not increasing", "strictly increasing t_start"
            )
        vals = [b for _, b in rows]
        text = repr(vals[0]) + "".join(
            f" + ({b - a!r})*step(t - {t0!r})" for (t0, b), a in zip(rows[1:], vals, strict=False)
        )
        expr = ctx.expr(text, key)
        breaks = tuple(t0 for t0, _ in rows[1:])
        lo, hi = min(vals), max(vals)
    else:
        expr = ctx.expr(v, key)
        vals_t = np.broadcast_to(expr.numpy(tgrid), tgrid.shape)
        bks = expr.breakpoints()
        extra = np.array([x for b in bks for x in (b, b - 1e-9, b + 1e-9)]) if bks else np.zeros(0)
        if extra.size:
            vals_t = np.concatenate([vals_t, np.broadcast_to(expr.numpy(extra), extra.shape)])
        if not np.all(np.isfinite(vals_t)):
            raise ctx.err(key, "is not finite somewhere on [0, horizon]", "a value in (0, 1]")
        lo, hi = float(vals_t.min()), float(vals_t.max())
        breaks = bks
    if not (lo > 0.0 and hi <= 1.0):
        bad = lo if lo <= 0 else hi
        raise ctx.err(
            key, f"actuator health reaches {bad:.4g}, outside (0, 1]", "0 < g_i <= 1 (1 = healthy)"
        )
    return Health(expr=expr, breakpoints=breaks, minimum=lo)


def _load_trace(ctx: _Ctx, scen_path: Path, rel: Any, p: int) -> np.ndarray:
    key = "leader.u0_csv"
    if not isinstance(rel, str):
        raise ctx.err(key, "is not a path", "a CSV path relative to the scenario file")
    fpath = (scen_path.parent / rel).resolve()
    try:
        with fpath.open(newline="") as fh:
            rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
    except OSError as exc:
        raise ctx.err(key, f"cannot read {fpath}: {exc.strerror}", "an existing CSV file") from None
    if rows and not _is_float(rows[0][0]):
        rows = rows[1:]  # header
    if len(rows) < 2:
        raise ctx.err(
            key,
            f"{fpath} has fewer than two data rows",
            "columns t, u0_1..u0_p with at least two rows",
        )
    data = []
    for k, r in enumerate(rows):
        if len(r) != 1 + p:
            raise ctx.err(
                key,
                f"{fpath} row {k + 1} has {len(r)} columns",
                f"{1 + p} columns: t and {p} inputs",
            )
        try:
            vals = [float(x) for x in r]
        except ValueError:
            raise ctx.err(key, f"{fpath} row {k + 1} is not numeric", "numbers") from None
        if not all(map(math.isfinite, vals)):
            raise ctx.err(key, f"{fpath} row {k + 1} is not finite", "finite numbers")
        data.append(vals)
    arr = np.array(data)
    if np.any(np.diff(arr[:, 0]) <= 0):
        k = int(np.argmax(np.diff(arr[:, 0]) <= 0)) + 2
        raise ctx.err(
            key, f"{fpath}: time is not strictly increasing at row {k}", "a trace monotone in time"
        )
    return _freeze(arr)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _unreachable(A: np.ndarray, pin: np.ndarray) -> list[int]:
    """Followers not reachable from the leader along edges j -> i with a_ij != 0."""
    N = len(pin)
    seen = [bool(pin[i] > 0) for i in range(N)]
    queue = deque(i for i in range(N) if seen[i])
    while queue:
        j = queue.popleft()
        for i in range(N):
            if not seen[i] and A[i, j] != 0:
                seen[i] = True
                queue.append(i)
    return [i for i in range(N) if not seen[i]]
