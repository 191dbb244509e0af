"""The closed loop stepped live: the operator's numbers change between integrator calls.

:class:`LoopBase` keeps what the operator asked for (u0, each follower's health g_i
and added bias, the cut links), what the loop currently integrates with, the
simulated clock and the record of every change with its time. A change asked for
between two integrator calls takes effect at the *end* of the next call, a multiple
of the quantum ``h`` (one frame of latency): inside that call the new value enters
through a step at its last time, ``a + (b − a)·step(t − t_end)``, exactly as the
replay's held trace, health table and bias faults (right-continuous steps) bring it
in, so the integrator evaluates the same right-hand side at every point in both runs;
the next call starts there (a restart, as at a breakpoint of the replay).

:class:`LiveLoop` integrates the compiled closed loop, whose numbers are a runtime
vector ``p`` (``symbolic.parameters``): the console scenario writes u0_k and g_i as
``a + d*step(t - c)`` and each f_ir as ``(f_ir) + a + d*step(t - c)``, and the console
sets their literals (a, d, c); a link's weight is in ``graph`` (it switches between
two calls). Nothing is regenerated or recompiled while the console runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from console.protocol import Limits
from core.errors import BuildError


@dataclass(frozen=True)
class Change:
    """One change the operator made, at simulated time ``t``.

    Attributes
    ----------
    t : float
        When it took effect (a multiple of the quantum).
    kind : str
        ``u0``, ``health``, ``bias`` or ``link``.
    follower : int or None
        0-based follower (``health``, ``bias``, ``link``).
    neighbour : int or None
        ``link``: 0-based neighbour, -1 for the leader.
    values : tuple of float
        ``u0``: the command; ``health``: (g,); ``bias``: the n components; ``link``:
        (weight,) after the change (0 for a cut).
    """

    t: float
    kind: str
    follower: int | None = None
    neighbour: int | None = None
    values: tuple[float, ...] = ()


@dataclass
class Advance:
    """What one integrator call produced.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Output times reached (possibly fewer than asked, on a failure).
    x : ndarray, shape (K, nx)
        States at those times.
    failure : str
        Empty when every time was reached, else the integrator's reason.
    steps : int
        Integrator steps taken.
    """

    t: np.ndarray
    x: np.ndarray
    failure: str = ""
    steps: int = 0


@dataclass
class Settings:
    """The operator's current numbers (what the parameter vector carries)."""

    u0: np.ndarray
    health: np.ndarray
    bias: np.ndarray  # N x n
    weights: dict[tuple[int, int], float] = field(default_factory=dict)  # (i, j) -> a_ij / a_i0

    def copy(self) -> Settings:
        """An independent copy."""
        return Settings(self.u0.copy(), self.health.copy(), self.bias.copy(), dict(self.weights))


class LoopBase:
    """Clock, operator settings and record of a live loop; subclasses integrate.

    Parameters
    ----------
    limits : Limits
        Sizes and ranges (:class:`console.protocol.Limits`).
    quantum : float
        Simulated seconds between logged states; every change lands on a multiple.
    nominal : Settings
        The settings at t = 0 (and after ``clear`` for a follower).
    x0 : ndarray
        The state at t = 0.
    """

    def __init__(self, limits: Limits, quantum: float, nominal: Settings, x0: np.ndarray) -> None:
        self.limits, self.quantum = limits, float(quantum)
        self.nominal, self.x0 = nominal, np.asarray(x0, dtype=float)
        self.switch_at: float | None = None  # end time of the call that brings in changes
        self.reset()

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to t = 0 with the nominal settings; the record starts again."""
        self.k = 0  # quanta elapsed: t = k * quantum exactly
        self.x = self.x0.copy()
        self.settings = self.nominal.copy()  # what the loop integrates with
        self.target = self.nominal.copy()  # what the operator asked for
        self.changes: list[Change] = []
        self.restarts: list[float] = []  # times an integrator call started (after t = 0)
        self.failure = ""
        self.steps = 0
        self.parameters_changed()

    @property
    def t(self) -> float:
        """Simulated time (s)."""
        return self.k * self.quantum

    # ---------------------------------------------------------------- changes
    def set_u0(self, values: tuple[float, ...]) -> None:
        """Hold the operator's command from the end of the next call on.

        Parameters
        ----------
        values : tuple of float
            u0, p components.
        """
        self.target.u0 = np.array(values, dtype=float)

    def set_health(self, i: int, g: float) -> None:
        """Set a follower's actuator health from the end of the next call on.

        Parameters
        ----------
        i : int
            Follower, 0-based.
        g : float
            Health g_i in (0, 1].
        """
        self.target.health[i] = g

    def set_bias(self, i: int, values: tuple[float, ...]) -> None:
        """Set the bias added to a follower's f_i from the end of the next call on.

        Parameters
        ----------
        i : int
            Follower, 0-based.
        values : tuple of float
            The bias, n components.
        """
        self.target.bias[i] = values

    def set_link(self, i: int, j: int, cut: bool) -> None:
        """Cut (weight 0) or restore an edge from the end of the next call on.

        Parameters
        ----------
        i : int
            Follower that hears, 0-based.
        j : int
            Follower heard, 0-based; -1 for the leader (the pinning a_i0).
        cut : bool
            True: weight 0; False: the scenario's weight.
        """
        self.target.weights[(i, j)] = 0.0 if cut else self.nominal.weights[(i, j)]

    def clear(self, i: int) -> None:
        """Remove every fault of a follower: nominal health, no bias, its links restored.

        Parameters
        ----------
        i : int
            Follower, 0-based.
        """
        self.target.health[i] = self.nominal.health[i]
        self.target.bias[i] = self.nominal.bias[i]
        for ii, j in self.nominal.weights:
            if ii == i:
                self.target.weights[(i, j)] = self.nominal.weights[(i, j)]

    def pending(self, t: float) -> list[Change]:
        """The changes from the current settings to the target.

        Parameters
        ----------
        t : float
            The time they are dated (when they land).
        """
        old, new = self.settings, self.target
        out = []
        if np.any(old.u0 != new.u0):
            out.append(Change(t, "u0", values=tuple(map(float, new.u0))))
        for i in range(self.limits.N):
            if old.health[i] != new.health[i]:
                out.append(Change(t, "health", i, values=(float(new.health[i]),)))
            if np.any(old.bias[i] != new.bias[i]):
                out.append(Change(t, "bias", i, values=tuple(map(float, new.bias[i]))))
        for (i, j), w in sorted(new.weights.items()):
            if old.weights[(i, j)] != w:
                out.append(Change(t, "link", i, j, (float(w),)))
        return out

    def parameters_changed(self) -> None:
        """Hook: the settings or the switch time changed (subclasses rebuild p)."""

    # ---------------------------------------------------------------- time
    def advance(self, quanta: int) -> Advance:
        """Integrate ``quanta`` quanta from the current time; pending changes land at the end.

        Parameters
        ----------
        quanta : int
            Number of quanta (>= 1); the states at each are returned.

        Returns
        -------
        Advance
            On a failure the clock stops at the last time reached and ``failure`` says
            why; further calls return nothing until :meth:`reset`.
        """
        if self.failure or quanta < 1:
            return Advance(np.empty(0), np.empty((0, self.x.size)), self.failure)
        ks = self.k + np.arange(0, quanta + 1)
        t_out = ks * self.quantum
        if self.k > 0:
            self.restarts.append(self.t)
        changes = self.pending(float(t_out[-1]))
        self.switch_at = float(t_out[-1]) if changes else None
        self.parameters_changed()
        res = self.integrate(self.x, t_out)
        reached = len(res.t)  # includes t_out[0]
        if reached > 1:
            self.k = int(ks[reached - 1])
            self.x = np.asarray(res.x[-1], dtype=float).copy()
        self.steps += res.steps
        if res.failure:
            self.failure = res.failure
        elif changes:
            self.settings = self.target.copy()
            self.changes.extend(changes)
        self.switch_at = None
        self.parameters_changed()
        return Advance(res.t[1:], res.x[1:], res.failure, res.steps)

    def integrate(self, x0: np.ndarray, t_out: np.ndarray) -> Advance:
        """States at the output times; subclasses.

        Parameters
        ----------
        x0 : ndarray
            The state at ``t_out[0]`` (now).
        t_out : ndarray
            Output times, the first one now.
        """
        raise NotImplementedError

    def signals(self, x: np.ndarray) -> dict[str, Any]:
        """What the page draws at the current time; subclasses.

        Parameters
        ----------
        x : ndarray
            The state.
        """
        raise NotImplementedError

    def state_columns(self) -> list[str]:
        """Names of :meth:`state_table`'s columns (default ``x1``, ``x2``, ...)."""
        return [f"x{k}" for k in range(1, self.x.size + 1)]

    def state_table(self, X: np.ndarray) -> np.ndarray:
        """Logged states as the columns of :meth:`state_columns`.

        Parameters
        ----------
        X : ndarray, shape (K, nx)
            States, one row per time.
        """
        return X


def desired_formation(y0: np.ndarray, eta0dot: np.ndarray, b0: np.ndarray) -> np.ndarray:
    """The paper's formation slots y0 + R(τ0) b_i0, τ0 the heading of the leader's η̇0.

    R(τ) is the planar rotation; where η̇0 has no heading (its first two components are
    zero) or n ≠ 2, the slots are y0 + b_i0.

    Parameters
    ----------
    y0 : ndarray, shape (n,)
        The leader's output.
    eta0dot : ndarray, shape (m,)
        The leader's η̇0 (its first two components set τ0).
    b0 : ndarray, shape (N, n)
        The formation vectors b_i0.
    """
    b0 = np.asarray(b0, dtype=float)
    if b0.shape[1] != 2 or eta0dot.size < 2 or math.hypot(eta0dot[0], eta0dot[1]) == 0.0:
        return y0 + b0
    tau = math.atan2(eta0dot[1], eta0dot[0])
    c, s = math.cos(tau), math.sin(tau)
    R = np.array([[c, -s], [s, c]])
    return y0 + b0 @ R.T


# --------------------------------------------------------------------------- the real loop
#: the state columns of trajectory.csv, per follower, in order (generated.trajectory_file)
AGENT_COLUMNS = (("p", "n"), ("q", "n"), ("eta", "m"), ("mu", "m"), ("phi", ""))
AGENT_COLUMNS += (("thetahat", "n"), ("ghat", ""))


class LiveLoop(LoopBase):
    """The compiled closed loop of a console scenario, stepped with runtime parameters.

    Parameters
    ----------
    sc : Scenario
        The console scenario (:func:`console.scenario.console_scenario`): u0, g_i and the
        bias slot of every f_ir are plain literals.
    gains : Gains
        Its certified gains.
    built : Built
        Its compiled closed loop (:func:`generated.api.build`), whose library takes p.
    bias_max : float
        Largest bias component accepted (the scenario's d already includes it).
    """

    def __init__(self, sc: Any, gains: Any, built: Any, bias_max: float) -> None:
        from generated import api
        from symbolic.parameters import layout_of

        if built.outputs_p is None or built.dag is not None:
            raise BuildError(
                f"{sc.path}: the console needs a library that takes runtime parameters; "
                "the graph-ordered native build (above 20 followers) does not "
                '(set integration.method = "cvodes")'
            )
        self.sc, self.gains, self.built = sc, gains, built
        self.settings_int = api.integrator_settings(sc)
        self.p0 = np.asarray(built.p, dtype=float)
        lay = layout_of(sc)
        # the literals (a, d, c) of a + d*step(t - c): the last three of each expression
        self.idx_u0 = [lay.slices[f"expr:leader.u0[{k}]"].stop - 3 for k in range(sc.p)]
        self.idx_g = [lay.slices[f"expr:followers[{i}].g"].stop - 3 for i in range(sc.N)]
        self.idx_f = [
            [lay.slices[f"expr:followers[{i}].f[{r}]"].stop - 3 for r in range(sc.n)]
            for i in range(sc.N)
        ]
        self.graph_slice, self.times_slice = lay.slices["graph"], lay.slices["graph_times"]
        if self.times_slice.stop - self.times_slice.start != 1:
            raise BuildError(f"{sc.path}: graph: the console scenario needs exactly one switch")
        A = np.asarray(sc.graph.adjacency, dtype=float)
        a0 = np.asarray(sc.graph.pinning, dtype=float)
        self.h = np.diag(np.atleast_2d(gains.H)).astype(float)
        weights = {(int(i), int(j)): float(A[i, j]) for i, j in zip(*np.nonzero(A), strict=True)}
        weights |= {(int(i), -1): float(a0[i]) for i in np.flatnonzero(a0)}
        edges = frozenset((i + 1, j + 1) for i, j in weights)
        limits = Limits(
            N=sc.N,
            n=sc.n,
            p=sc.p,
            u_max=float(sc.leader.alpha) / math.sqrt(sc.p),
            g_min=float(sc.controller.g_min),
            bias_max=float(bias_max),
            edges=edges,
        )
        nominal = Settings(
            u0=self.p0[self.idx_u0].copy(),
            health=self.p0[self.idx_g].copy(),
            bias=np.zeros((sc.N, sc.n)),
            weights=weights,
        )
        self.layout = built.closed_loop.layout
        self._bound: Any = None
        super().__init__(limits, sc.integration.output_step, nominal, built.closed_loop.x0)

    # ---------------------------------------------------------------- parameters
    def parameters_changed(self) -> None:
        """Drop the bound build; the next integrator call binds the new p."""
        self._bound = None

    def param_vector(self) -> np.ndarray:
        """The runtime parameter vector p: the settings, switching to the target at
        :attr:`switch_at` (the end of the call) when changes are pending."""
        old, new, c = self.settings, self.target, self.switch_at
        p = self.p0.copy()

        def put(k: int, a: float, b: float) -> None:  # a + (b − a) step(t − c)
            p[k : k + 3] = (a, 0.0, 0.0) if c is None else (a, b - a, c)

        for k, idx in enumerate(self.idx_u0):
            put(idx, old.u0[k], new.u0[k])
        for i, idx in enumerate(self.idx_g):
            put(idx, old.health[i], new.health[i])
            for r, k in enumerate(self.idx_f[i]):
                put(k, old.bias[i, r], new.bias[i, r])
        # the graph as two topologies, old then new from c on (the replay's graph switches)
        p[self.graph_slice] = np.concatenate([self._graph(old), self._graph(new)])
        p[self.times_slice] = 0.0 if c is None else c
        return p

    def _graph(self, st: Settings) -> np.ndarray:
        """The ``graph`` weights of one topology: the links of ``st`` on the compiled pattern."""
        from symbolic.parameters import graph_values

        A = np.zeros((self.sc.N, self.sc.N))
        a0 = np.zeros(self.sc.N)
        for (i, j), w in st.weights.items():
            if j < 0:
                a0[i] = w
            else:
                A[i, j] = w
        return graph_values(self.sc, self.h, A, a0)

    def bound(self) -> Any:
        """The build with the current p (the library is the same; only p changes)."""
        if self._bound is None:
            import dataclasses

            from generated.api import fix_parameters

            p = self.param_vector()
            b = dataclasses.replace(self.built, p=p)
            if self.sc.integration.method != "native":  # CasADi's integrators call dyn
                b = dataclasses.replace(b, dyn=fix_parameters(self.built.dyn_p, p))
            self._bound = b
        return self._bound

    # ---------------------------------------------------------------- time
    def integrate(self, x0: np.ndarray, t_out: np.ndarray) -> Advance:
        """The compiled loop from ``x0`` at ``t_out[0]`` (a restart, as at a breakpoint).

        Parameters
        ----------
        x0 : ndarray
            The state at ``t_out[0]``.
        t_out : ndarray
            Output times (multiples of the quantum).
        """
        from generated.api import integrate_built

        traj = integrate_built(self.bound(), x0, t_out, self.settings_int, [])
        fail = "" if traj.complete else traj.message
        return Advance(traj.t, traj.x, fail, int(traj.stats.get("steps", 0) or 0))

    def signals(self, x: np.ndarray) -> dict[str, Any]:
        """Leader output, followers, formation slots, error norms, ĝ_i and |u_i|.

        Parameters
        ----------
        x : ndarray
            The state (at the current time).
        """
        b = self.bound()
        out = b.outputs_p.call({"t": self.t, "x": x, "p": b.p})
        o = {k: np.asarray(v, dtype=float) for k, v in out.items()}
        L = self.sc.leader
        eta0 = x[self.layout.slices["eta0"]]
        y0 = o["y0"].ravel()
        eta0dot = L.A0 @ eta0 + L.B0 @ self.settings.u0
        P = np.array([x[self.layout.slices[("p", i)]] for i in range(self.sc.N)])
        b0 = np.array([fo.b0 for fo in self.sc.followers])
        norm = lambda a: np.linalg.norm(a.reshape(self.sc.N, -1), axis=1).tolist()  # noqa: E731
        return {
            "y0": y0.tolist(),
            "p": P.tolist(),
            "slots": desired_formation(y0, eta0dot, b0).tolist(),
            "et": norm(o["et"]),
            "est": norm(o["ebar"]),
            "ghat": o["ghat"].ravel().tolist(),
            "unorm": norm(o["u"]),
        }

    # ---------------------------------------------------------------- log
    def state_columns(self) -> list[str]:
        """Names of :meth:`state_table`'s columns (those of trajectory.csv)."""
        m, n = self.sc.m, self.sc.n
        size = {"m": m, "n": n, "": 1}
        cols = [f"eta0_{k}" for k in range(1, m + 1)]
        for i in range(1, self.sc.N + 1):
            for name, dim in AGENT_COLUMNS:
                k = size[dim]
                cols += [f"{name}{i}"] if dim == "" else [f"{name}{i}_{r}" for r in range(1, k + 1)]
        return cols

    def state_table(self, X: np.ndarray) -> np.ndarray:
        """Logged states as :meth:`state_columns`'s columns.

        Parameters
        ----------
        X : ndarray, shape (K, nx)
            States, one row per time.
        """
        sl = self.layout.slices
        blocks = [X[:, sl["eta0"]]]
        for i in range(self.sc.N):
            blocks += [X[:, sl[(name, i)]] for name, _ in AGENT_COLUMNS]
        return np.hstack(blocks)
