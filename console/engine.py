"""The closed loop stepped live: the operator's numbers change between integrator calls.

:class:`LoopBase` keeps what the operator asked for (u0, each follower's health g_i
and added bias, the cut links), what the loop currently integrates with, the
simulated clock and the record of every change with its time. A change asked for
between two integrator calls takes effect at the *end* of the next call, a multiple
of the quantum ``h`` (one frame of latency), and the next call starts there: every
change is a restart point of the integrator (as at a breakpoint of the replay).

**u0 is shaped.** A change of the operator's command from u to u' at time c is not a
jump: it enters as the C¹ ramp (u' − u)·S((t − c)/r), S the smoothstep 3x² − 2x³ of
``leader.u0_rise`` (core/shaping.py) and r the rise time
(:data:`CONSOLE_RISE` = :data:`core.shaping.DEFAULT_RISE`, chosen for a reversal of 2α) unless the console is given another. Ramps that
overlap add up; the command is then a convex blend of the values held
(core/hold.py), so ‖u0‖ ≤ α holds for every command the protocol accepts. At most
:data:`RAMP_SLOTS` ramps run at once (the compiled loop has that many); a change
asked for while all run waits for the oldest to end. The end of a ramp (c + r, where
its curvature jumps) is a breakpoint of the call that crosses it.

Health, bias and links enter as steps: at the end of the call, through
``a + (b − a)·step(t − t_end)``, exactly as the replay's health table, bias faults
and graph switches (right-continuous steps) bring them in.

**Failures.** When the integrator stops inside a call, the loop restarts it from the
last state reached with a smaller first step (:meth:`LoopBase.integrate`'s
``attempt``), up to :data:`MAX_ATTEMPTS` times; each failure is an :class:`Event`
(the session's log, the record's ``events.csv``, the page). If every attempt fails the
loop is *held* at the last good state (``failure`` says why); ``resume`` tries again
from there and :meth:`LoopBase.reset` goes back to t = 0. Nothing is ever retried in
a loop without the clock advancing or the loop being held.

:class:`LiveLoop` integrates the compiled closed loop, whose numbers are a runtime
vector ``p`` (``symbolic.parameters``): the console scenario writes u0_k as
``a + Σ_j d_j*smoothstep((t - c_j)/r_j)`` (:data:`RAMP_SLOTS` terms), g_i as
``a + d*step(t - c)`` and each f_ir as ``(f_ir) + a + d*step(t - c)``, and the console
sets their literals; a link's weight is in ``graph`` (it switches between two calls).
Nothing is regenerated or recompiled while the console runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from console.protocol import Limits
from core.errors import BuildError
from core.shaping import DEFAULT_RISE

#: rise time (s) of the console's shaped changes of u0: the scenarios' default. It was
#: chosen for the worst change an operator can make within α, a reversal from −α to +α
#: (docs/verification.md, 'Operator steps'), which is also the largest console change
#: (docs/console.md, 'Shaped commands')
CONSOLE_RISE = DEFAULT_RISE
#: ramps of u0 that may run at once (terms of the console scenario's u0 expressions)
RAMP_SLOTS = 12
#: integrator attempts per call before the loop is held (the first one and the restarts)
MAX_ATTEMPTS = 4
#: first step (s) of the first restart after a failure; each further restart takes 1/100 of it
FIRST_STEP = 1e-6


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


@dataclass(frozen=True)
class Event:
    """Something the integrator did that the operator is told about.

    Attributes
    ----------
    t : float
        Simulated time it happened at (the last good state's).
    kind : str
        ``failure`` (an attempt stopped; the loop restarts), ``recovered`` (a restart
        reached the end of the call), ``held`` (every attempt failed) or ``resumed``.
    text : str
        One line: the integrator's reason, or what was done.
    """

    t: float
    kind: str
    text: str


@dataclass(frozen=True)
class Ramp:
    """One shaped change of u0: ``d · S((t − c)/r)``.

    Attributes
    ----------
    c : float
        Its start (the time the change landed).
    d : ndarray, shape (p,)
        The change.
    r : float
        Its rise time (s).
    """

    c: float
    d: np.ndarray
    r: float

    @property
    def end(self) -> float:
        """Where it reaches its full size (its curvature jumps)."""
        return self.c + self.r


def smoothstep(x: np.ndarray | float) -> np.ndarray:
    """3x² − 2x³ on [0, 1], 0 below, 1 above (core.expressions' ``smoothstep``).

    Parameters
    ----------
    x : float or ndarray
    """
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


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
    rise : float
        Rise time (s) of the shaped changes of u0 (> 0).
    """

    def __init__(
        self,
        limits: Limits,
        quantum: float,
        nominal: Settings,
        x0: np.ndarray,
        rise: float = CONSOLE_RISE,
    ) -> None:
        if not (math.isfinite(rise) and rise > 0):
            raise BuildError(f"--rise: {rise:g} (expected a rise time in seconds > 0)")
        self.limits, self.quantum, self.rise = limits, float(quantum), float(rise)
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
        self.u0_base = self.nominal.u0.copy()  # u0 with every finished ramp added
        self.ramps: list[Ramp] = []  # running ramps, oldest first
        self.events: list[Event] = []
        self.failure = ""  # non-empty: the loop is held (every attempt failed), and why
        self.steps = 0
        self.parameters_changed()

    def resume(self) -> None:
        """Release a held loop: the next call tries again from the last good state."""
        if self.failure:
            self.events.append(Event(self.t, "resumed", "restart from the last good state"))
            self.failure = ""

    # ---------------------------------------------------------------- u0
    def u0_at(self, t: float | np.ndarray) -> np.ndarray:
        """The shaped command at time(s) ``t`` >= the current call's start.

        Parameters
        ----------
        t : float or ndarray
            Time(s); shape (p,) for a scalar, (len(t), p) for an array.
        """
        t = np.asarray(t, dtype=float)
        u = np.broadcast_to(self.u0_base, (*t.shape, self.u0_base.size)).copy()
        for rp in self.ramps:
            u = u + smoothstep((t - rp.c) / rp.r)[..., None] * rp.d
        return u

    def _fold_ramps(self) -> None:
        """Add the ramps that ended by now to the base command (they are constant on)."""
        done = [rp for rp in self.ramps if rp.end <= self.t]
        for rp in done:
            self.u0_base = self.u0_base + rp.d
        self.ramps = [rp for rp in self.ramps if rp.end > self.t]

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
        if np.any(old.u0 != new.u0) and len(self.ramps) < RAMP_SLOTS:
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
            The states reached. An attempt that stops is restarted from the last state
            reached with a smaller first step; when :data:`MAX_ATTEMPTS` attempts fail
            the loop is held there (``failure`` says why, :meth:`resume` releases it) and
            the pending changes wait.
        """
        if self.failure or quanta < 1:
            return Advance(np.empty(0), np.empty((0, self.x.size)), self.failure)
        self._fold_ramps()
        ks = self.k + np.arange(0, quanta + 1)
        t_end = float(ks[-1] * self.quantum)
        if self.k > 0:
            self.restarts.append(self.t)
        changes = self.pending(t_end)
        self.switch_at = t_end if any(c.kind != "u0" for c in changes) else None
        self.parameters_changed()
        ts, xs, steps, why = self._attempts(ks)
        if why:
            self.failure = why
        else:
            self._land(changes, t_end)
        self.switch_at = None
        self.parameters_changed()
        return Advance(np.array(ts), np.array(xs).reshape(len(ts), self.x.size), why, steps)

    def _attempts(self, ks: np.ndarray) -> tuple[list[float], list[np.ndarray], int, str]:
        """Integrate to ``ks[-1]`` quanta, restarting after a failure; what was reached.

        Returns the times and states reached (after the start), the steps taken and,
        when every attempt failed, why (else ``""``).
        """
        ts: list[float] = []
        xs: list[np.ndarray] = []
        steps = 0
        for attempt in range(MAX_ATTEMPTS):
            rest = ks[ks >= self.k]
            t_out = rest * self.quantum
            breaks = [rp.end for rp in self.ramps if t_out[0] < rp.end < t_out[-1]]
            res = self.integrate(self.x, t_out, sorted(breaks), attempt)
            reached = len(res.t)  # includes t_out[0]
            if reached > 1:
                self.k = int(rest[reached - 1])
                self.x = np.asarray(res.x[-1], dtype=float).copy()
                ts.extend(float(v) for v in res.t[1:])
                xs.extend(np.asarray(r, dtype=float) for r in res.x[1:])
            steps += res.steps
            self.steps += res.steps
            if not res.failure:
                if attempt:
                    self.events.append(
                        Event(self.t, "recovered", f"attempt {attempt + 1} reached t = {self.t:g}")
                    )
                return ts, xs, steps, ""
            self.events.append(Event(self.t, "failure", res.failure))
            if self.k > int(rest[0]):  # progress was made: restarts begin there
                self.restarts.append(self.t)
        why = (
            f"held at t = {self.t:g} s: {MAX_ATTEMPTS} integrator attempts failed "
            f"({self.events[-1].text}); resume retries from here, reset starts again at t = 0"
        )
        self.events.append(Event(self.t, "held", why))
        return ts, xs, steps, why

    def _land(self, changes: list[Change], t_end: float) -> None:
        """Apply the changes that land at the end of a completed call."""
        if not changes:
            return
        for c in changes:
            if c.kind == "u0":
                d = np.array(c.values) - self.settings.u0
                self.ramps.append(Ramp(t_end, d, self.rise))
                self.settings.u0 = np.array(c.values)
        u0 = self.settings.u0
        self.settings = self.target.copy()
        if not any(c.kind == "u0" for c in changes):  # a u0 change that waits for a ramp
            self.settings.u0 = u0
        self.changes.extend(changes)

    def integrate(
        self, x0: np.ndarray, t_out: np.ndarray, breaks: list[float], attempt: int = 0
    ) -> Advance:
        """States at the output times; subclasses.

        Parameters
        ----------
        x0 : ndarray
            The state at ``t_out[0]`` (now).
        t_out : ndarray
            Output times, the first one now.
        breaks : list of float
            Restart times strictly inside (the ends of ramps of u0).
        attempt : int
            0 for the first attempt of a call; k > 0 for the k-th restart after a
            failure (a smaller first step).
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
    rise : float
        Rise time of the shaped changes of u0 (s).
    """

    def __init__(
        self, sc: Any, gains: Any, built: Any, bias_max: float, rise: float = CONSOLE_RISE
    ) -> None:
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
        # u0_k: a + Σ_j d_j*smoothstep((t - c_j)/r_j), literals a, then (d_j, c_j, r_j)
        self.u0_slices = [lay.slices[f"expr:leader.u0[{k}]"] for k in range(sc.p)]
        if any(sl.stop - sl.start != 1 + 3 * RAMP_SLOTS for sl in self.u0_slices):
            raise BuildError(
                f"{sc.path}: leader.u0: not the console's ramp expressions "
                "(console.scenario.console_table writes them)"
            )
        # the literals (a, d, c) of a + d*step(t - c): the last three of each expression
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
            u0=np.array([self.p0[sl.start] for sl in self.u0_slices]),
            health=self.p0[self.idx_g].copy(),
            bias=np.zeros((sc.N, sc.n)),
            weights=weights,
        )
        self.layout = built.closed_loop.layout
        self._bound: Any = None
        super().__init__(
            limits, sc.integration.output_step, nominal, built.closed_loop.x0, rise=rise
        )

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

        for k, sl in enumerate(self.u0_slices):
            p[sl.start] = self.u0_base[k]
            for j in range(RAMP_SLOTS):
                rp = self.ramps[j] if j < len(self.ramps) else None
                # an unused slot: no change (d = 0) with the console's rise time
                ramp = (0.0, 0.0, self.rise) if rp is None else (rp.d[k], rp.c, rp.r)
                p[sl.start + 1 + 3 * j : sl.start + 4 + 3 * j] = ramp
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
        import dataclasses

        from generated.api import fix_parameters

        if self._bound is None:
            p = self.param_vector()
            b = dataclasses.replace(self.built, p=p)
            if self.sc.integration.method != "native":  # CasADi's integrators call dyn
                b = dataclasses.replace(b, dyn=fix_parameters(self.built.dyn_p, p))
            self._bound = b
        return self._bound

    # ---------------------------------------------------------------- time
    def integrate(
        self, x0: np.ndarray, t_out: np.ndarray, breaks: list[float], attempt: int = 0
    ) -> Advance:
        """The compiled loop from ``x0`` at ``t_out[0]`` (a restart, as at a breakpoint).

        The first attempt uses the scenario's settings. The k-th restart after a failure
        (``attempt`` = k >= 1) starts again from ``x0``, the last state reached, with
        10^k × ``max_steps`` and a smaller first step: through CasADi's CVODES
        (``integration.method = "cvodes"``) a first step of :data:`FIRST_STEP` / 100^(k−1)
        s; the native driver lets CVODE choose its first step, so there the first output
        interval is cut by 10^k − 1 restarts (each a fresh CVODE start, whose first step
        CVODE chooses from the tolerances and the right-hand side at that point).

        Parameters
        ----------
        x0 : ndarray
            The state at ``t_out[0]``.
        t_out : ndarray
            Output times (multiples of the quantum).
        breaks : list of float
            Restart times strictly inside (ends of u0 ramps).
        attempt : int
            0, or the restart after a failure.
        """
        import dataclasses

        from generated.api import integrate_built

        s = self.settings_int
        if attempt:
            s = dataclasses.replace(s, max_steps=int(s.max_steps * 10**attempt))
            if self.sc.integration.method == "native":
                cuts = t_out[0] + (t_out[1] - t_out[0]) * np.arange(1, 10**attempt) / 10**attempt
                breaks = sorted(set(breaks) | {float(c) for c in cuts})
            else:
                h0 = FIRST_STEP / 100.0 ** (attempt - 1)
                s = dataclasses.replace(s, extra_options=(*s.extra_options, ("step0", h0)))
        traj = integrate_built(self.bound(), x0, t_out, s, breaks)
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
        y0 = o["y0"].ravel()
        P = np.array([x[self.layout.slices[("p", i)]] for i in range(self.sc.N)])
        b = o["b"].reshape(self.sc.N, -1)  # the offsets the controllers track (blended)
        norm = lambda a: np.linalg.norm(a.reshape(self.sc.N, -1), axis=1).tolist()  # noqa: E731
        return {
            "y0": y0.tolist(),
            "p": P.tolist(),
            "slots": (y0 + b).tolist(),
            "u0_now": self.u0_at(self.t).tolist(),
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
