"""The closed loop stepped live: the operator's numbers change between integrator calls.

:class:`LoopBase` keeps what the operator asked for (u0, each follower's health g_i
and added bias, the cut links), what the loop currently integrates with, the
simulated clock and the record of every change with its time. A change asked for
between two integrator calls takes effect at the *end* of the next call, a multiple
of the quantum ``h`` (one frame of latency), and the next call starts there: every
change is a restart point of the integrator (as at a breakpoint of the replay).

**u0 is shaped** (:mod:`console.ramps`): a change of the operator's command enters as a
C¹ smoothstep ramp over the rise time, at most :data:`RAMP_SLOTS` at once; the end of a
ramp is a breakpoint of the call that crosses it.

Health, bias and links enter as steps: at the end of the call, through
``a + (b − a)·step(t − t_end)``, exactly as the replay's health table, bias faults
and graph switches (right-continuous steps) bring them in.

**Failures** (:mod:`console.recovery`): a call the integrator stops inside is restarted
from the last state reached, up to :data:`MAX_ATTEMPTS` attempts, each failure an
:class:`Event`; then the loop is *held* there until :meth:`LoopBase.resume` or
:meth:`LoopBase.reset`.

The operator's numbers and their changes are :mod:`console.changes`; what the page
draws and the logged states' columns are :mod:`console.frames`.

:class:`LiveLoop` integrates the per-agent engine (:mod:`generated.agents`), whose
numbers are runtime data: the console scenario writes u0_k as
``a + Σ_j d_j*smoothstep((t - c_j)/r_j)`` (:data:`RAMP_SLOTS` terms), g_i as
``a + d*step(t - c)`` and each f_ir as ``(f_ir) + a + d*step(t - c)``, and the console
sets their literals in the agents' rows; the links are the problem's topologies (a
change switches between two calls). Nothing is regenerated or recompiled while the
console runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from console.calls import CallTimeout, ChildCalls
from console.changes import Change, Settings, pending_changes
from console.frames import desired_formation, page_signals, state_columns, state_table
from console.protocol import Limits, MessageError
from console.ramps import CONSOLE_RISE, RAMP_SLOTS, Ramp, command_at, fold_finished, u0_literals
from console.recovery import ATTEMPT_WALL, MAX_ATTEMPTS, Event, restart_settings, run_attempts
from core.errors import BuildError

#: the names other modules import from here (they live in the modules named above)
__all__ = [
    "CONSOLE_RISE",
    "MAX_ATTEMPTS",
    "RAMP_SLOTS",
    "Advance",
    "Change",
    "Event",
    "LiveLoop",
    "LoopBase",
    "Settings",
    "desired_formation",
]


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
    timed_out : bool
        The attempt ran past its wall-time budget and was stopped (no retry follows).
    """

    t: np.ndarray
    x: np.ndarray
    failure: str = ""
    steps: int = 0
    timed_out: bool = False


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
        # the links in force from each time on: the nominal ones, then every change landed
        self.links: list[tuple[float, dict[tuple[int, int], float]]] = [
            (0.0, dict(self.nominal.weights))
        ]
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
        return command_at(self.u0_base, self.ramps, t)

    def _fold_ramps(self) -> None:
        """Add the ramps that ended by now to the base command (they are constant on)."""
        self.u0_base, self.ramps = fold_finished(self.u0_base, self.ramps, self.t)

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

        Raises
        ------
        MessageError
            A cut that would leave a follower unreachable from the leader (Assumption 1):
            refused, naming them; nothing changes.
        """
        if cut:
            lost = unreachable_after(self.target.weights, (i, j), self.limits.N)
            if lost:
                names = ", ".join(str(k + 1) for k in lost)
                edge = f"{i + 1} ← {'leader' if j < 0 else j + 1}"
                raise MessageError(
                    f"link {edge}: refused, the cut would leave follower{'s' if len(lost) > 1 else ''}"
                    f" {names} unreachable from the leader (Assumption 1); restore another "
                    "link to it first"
                )
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
        room = len(self.ramps) < RAMP_SLOTS
        if self.ramps:  # changes land at most every rise / RAMP_SLOTS: the slots never fill
            room = room and t - self.ramps[-1].c >= self.rise / RAMP_SLOTS - 1e-9
        return pending_changes(self.settings, self.target, self.limits.N, room, t)

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
        ts, xs, steps, why = run_attempts(self, ks)
        if why:
            self.failure = why
        else:
            self._land(changes, t_end)
        self.switch_at = None
        self.parameters_changed()
        return Advance(np.array(ts), np.array(xs).reshape(len(ts), self.x.size), why, steps)

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
        if self.settings.weights != self.links[-1][1]:
            self.links.append((t_end, dict(self.settings.weights)))
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


def unreachable_after(
    weights: dict[tuple[int, int], float], cut: tuple[int, int], N: int
) -> list[int]:
    """0-based followers the leader cannot reach once ``cut`` is cut (core.graph, Assumption 1).

    Parameters
    ----------
    weights : dict
        (i, j) -> a_ij, j = -1 for the leader's pinning a_i0 (the links as they are asked for).
    cut : (int, int)
        The link to cut.
    N : int
        Followers.
    """
    from core.graph import unreachable_followers

    A, a0 = np.zeros((N, N)), np.zeros(N)
    for (i, j), w in weights.items():
        if (i, j) == cut:
            continue
        if j < 0:
            a0[i] = w
        else:
            A[i, j] = w
    return unreachable_followers(A, a0)


# --------------------------------------------------------------------------- the real loop


class LiveLoop(LoopBase):
    """The per-agent engine on a console scenario, stepped with its runtime data.

    Integration: the per-agent kernels of the scenario's follower models
    (:func:`generated.agents.build_models`, compiled or found in the build cache once)
    run by :func:`generated.agents.run` in a child process killed past the attempt's
    wall-time budget (:mod:`console.calls`). Every operator number is runtime data of
    that engine: the literals of the ramps of u0 and of the health and bias steps are
    columns of the agents' rows (:func:`symbolic.parameters.agent_rows`), the links are
    the problem's topologies (the link changes since the last that is no longer fading,
    then the pending one at the end of the call). What the page draws is the symbolic
    closed loop's outputs with the whole loop's parameter vector p of the same numbers
    (CasADi's virtual machine: nothing compiled).

    Parameters
    ----------
    sc : Scenario
        The console scenario (:func:`console.scenario.console_scenario`): u0, g_i and the
        bias slot of every f_ir are plain literals.
    gains : Gains
        Its certified gains.
    bias_max : float
        Largest bias component accepted (the scenario's d already includes it).
    rise : float
        Rise time of the shaped changes of u0 (s).
    codegen : CodegenSettings, optional
        Compiler settings of the kernels (default: those of ``generated sim``).
    """

    def __init__(
        self,
        sc: Any,
        gains: Any,
        bias_max: float,
        rise: float = CONSOLE_RISE,
        codegen: Any = None,
    ) -> None:
        from generated import agents, api
        from symbolic.closed_loop import closed_loop_for, observer_gains
        from symbolic.parameters import agent_rows, layout_of, row_layout, row_slices

        self.sc, self.gains = sc, gains
        self.settings_int = api.integrator_settings(sc, "native")
        # the symbolic closed loop: x(0) and the page's outputs (nothing compiled)
        self.closed_loop = closed_loop_for(sc, gains)
        libs, model = agents.build_models(sc, gains, api.resolve_codegen(sc.N, codegen))
        self.libraries = tuple(libs)
        self.problem = agents.problem(sc, gains, model)
        self.p0 = np.asarray(self.closed_loop.p0, dtype=float)
        og = observer_gains(sc, gains)
        self.rows0 = agent_rows(sc, og)
        lay, rows = layout_of(sc), row_slices(sc, row_layout(sc, og))
        # where each operator number goes: (name in p, last k literals) -> p's and the rows'
        # columns. u0_k: a + Σ_j d_j*smoothstep((t - c_j)/r_j), literals a, then (d_j, c_j, r_j)
        self.u0_names = [f"expr:leader.u0[{k}]" for k in range(sc.p)]
        if any(
            len(range(*lay.slices[n].indices(lay.size))) != 1 + 3 * RAMP_SLOTS
            for n in self.u0_names
        ):
            raise BuildError(
                f"{sc.path}: leader.u0: not the console's ramp expressions "
                "(console.scenario.console_table writes them)"
            )
        # the literals (a, d, c) of a + d*step(t - c): the last three of each expression
        self.g_names = [f"expr:followers[{i}].g" for i in range(sc.N)]
        self.f_names = [[f"expr:followers[{i}].f[{r}]" for r in range(sc.n)] for i in range(sc.N)]
        self.p_slices, self.row_slices = lay.slices, rows
        self.graph_slice, self.times_slice = lay.slices["graph"], lay.slices["graph_times"]
        self.link_slots = self.times_slice.stop - self.times_slice.start
        if self.link_slots < 1:
            raise BuildError(f"{sc.path}: graph: the console scenario needs its link slots")
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
            u0=np.array([self.p0[lay.slices[n].start] for n in self.u0_names]),
            health=np.array([self.p0[lay.slices[n].stop - 3] for n in self.g_names]),
            bias=np.zeros((sc.N, sc.n)),
            weights=weights,
        )
        self.layout = self.closed_loop.layout
        self._p: np.ndarray | None = None
        # the engine is one C call: it runs in a child process killed past the attempt's
        # wall-time budget (console/calls.py)
        paths = tuple(lib.path for lib in self.libraries)
        self.calls = ChildCalls(init=(load_agents, (paths,)))
        self.calls.warm_later()
        super().__init__(
            limits, sc.integration.output_step, nominal, self.closed_loop.x0, rise=rise
        )

    # ---------------------------------------------------------------- parameters
    def parameters_changed(self) -> None:
        """Drop the current p; the next outputs use the new settings."""
        self._p = None

    def literals(self) -> dict[str, np.ndarray]:
        """The operator's numbers as the last literals of each console expression, by name.

        u0_k: all its literals (the base, then each slot's (d, c, r)); g_i and f_ir: the
        (a, d, c) of a + d*step(t − c), the settings switching to the target at
        :attr:`switch_at` (the end of the call) when changes are pending.
        """
        old, new, c = self.settings, self.target, self.switch_at

        def step(a: float, b: float) -> np.ndarray:  # a + (b − a) step(t − c)
            return np.array((a, 0.0, 0.0) if c is None else (a, b - a, c))

        out = {
            # an unused slot: no change (d = 0) with the console's rise time
            name: np.asarray(u0_literals(self.u0_base[k], self.ramps, k, self.rise), float)
            for k, name in enumerate(self.u0_names)
        }
        for i, name in enumerate(self.g_names):
            out[name] = step(old.health[i], new.health[i])
            for r, fname in enumerate(self.f_names[i]):
                out[fname] = step(old.bias[i, r], new.bias[i, r])
        return out

    def param_vector(self) -> np.ndarray:
        """The whole loop's parameter vector p of the current numbers (the page's outputs):
        the settings, switching to the target at :attr:`switch_at` when changes are pending."""
        p = self.p0.copy()
        for name, v in self.literals().items():
            sl = self.p_slices[name]
            p[sl.stop - v.size : sl.stop] = v
        # the graphs of the next call (the engine's), padded with copies of the last: a
        # switch to equal weights changes nothing, faded or not
        hist = self.link_history()
        hist += [hist[-1]] * (1 + self.link_slots - len(hist))
        p[self.graph_slice] = np.concatenate([self._graph(w) for _, w in hist])
        p[self.times_slice] = [t0 for t0, _ in hist[1:]]
        return p

    def agent_rows(self) -> np.ndarray:
        """The agents' rows of runtime numbers (:func:`symbolic.parameters.agent_rows`) with
        the operator's numbers of :meth:`literals`."""
        R = self.rows0.copy()
        for name, v in self.literals().items():
            i, sl = self.row_slices[name]
            R[slice(None) if i is None else i, sl.stop - v.size : sl.stop] = v
        return R

    def link_history(self) -> list[tuple[float, dict[tuple[int, int], float]]]:
        """The links of the next call: from the last change whose fade (``graph.link_fade``)
        has ended by now, every change with its time, then the pending one at
        :attr:`switch_at` (the replay's ``[[graph.switches]]`` as they ran)."""
        fade = float(self.sc.graph.link_fade)
        hist = list(self.links)
        if self.switch_at is not None and self.target.weights != self.settings.weights:
            hist.append((self.switch_at, dict(self.target.weights)))
        first = max(k for k, (t0, _) in enumerate(hist) if k == 0 or t0 <= self.t - fade)
        return hist[first:]

    def topologies(self) -> tuple[Any, ...]:
        """The per-agent problem's graphs of the next call (:meth:`link_history`)."""
        from generated.agent_graph import topology

        return tuple(topology(t0, *self._matrices(w), self.h) for t0, w in self.link_history())

    def set_link(self, i: int, j: int, cut: bool) -> None:
        """As :meth:`LoopBase.set_link`; also refused while :data:`LINK_SLOTS` changes fade.

        Parameters
        ----------
        i, j, cut
            As :meth:`LoopBase.set_link`.

        Raises
        ------
        MessageError
            As :meth:`LoopBase.set_link`, or a new change while the page's outputs hold
            no more fading graphs (the oldest fade must end first).
        """
        pending = self.target.weights != self.settings.weights  # a new change joins it
        if not pending and len(self.link_history()) > self.link_slots:
            raise MessageError(
                f"link {i + 1} ← {'leader' if j < 0 else j + 1}: refused, {self.link_slots} "
                f"link changes are still fading (graph.link_fade = "
                f"{self.sc.graph.link_fade:g} s); try again when the oldest has ended"
            )
        super().set_link(i, j, cut)

    def agent_problem(self) -> Any:
        """The per-agent problem of the next call (:meth:`agent_rows`, :meth:`topologies`)."""
        import dataclasses

        return dataclasses.replace(
            self.problem, params=self.agent_rows(), topologies=self.topologies()
        )

    def _matrices(self, weights: dict[tuple[int, int], float]) -> tuple[np.ndarray, np.ndarray]:
        """Adjacency and pinning of a set of links."""
        A = np.zeros((self.sc.N, self.sc.N))
        a0 = np.zeros(self.sc.N)
        for (i, j), w in weights.items():
            if j < 0:
                a0[i] = w
            else:
                A[i, j] = w
        return A, a0

    def _graph(self, weights: dict[tuple[int, int], float]) -> np.ndarray:
        """The ``graph`` weights of one topology: ``weights`` on the compiled pattern."""
        from symbolic.parameters import graph_values

        return graph_values(self.sc, self.h, *self._matrices(weights))

    def outputs_at(self, t: float, x: np.ndarray) -> dict[str, Any]:
        """The closed loop's named outputs at (t, x) with the current numbers.

        Parameters
        ----------
        t : float
        x : ndarray
        """
        if self._p is None:
            self._p = self.param_vector()
        return self.closed_loop.parametric.outputs.call({"t": t, "x": x, "p": self._p})

    # ---------------------------------------------------------------- time
    def integrate(
        self, x0: np.ndarray, t_out: np.ndarray, breaks: list[float], attempt: int = 0
    ) -> Advance:
        """The per-agent engine from ``x0`` at ``t_out[0]`` (a restart, as at a breakpoint).

        The first attempt uses the scenario's settings; the k-th restart after a failure
        (``attempt`` = k >= 1) starts again from ``x0``, the last state reached, with the
        settings of :func:`console.recovery.restart_settings`.

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
        # CVODE chooses the first step of the C driver: a restart cuts the first interval
        s, breaks = restart_settings(self.settings_int, t_out, breaks, attempt, False)
        paths = tuple(lib.path for lib in self.libraries)
        args = (paths, self.agent_problem(), x0, t_out, s, breaks)
        try:
            traj = self.calls.call(agents_attempt, args, ATTEMPT_WALL)
        except CallTimeout:
            why = (
                f"attempt {attempt + 1} stopped after its wall-time budget of "
                f"{ATTEMPT_WALL:g} s (working towards t = {float(t_out[-1]):.6g} s)"
            )
            return Advance(t_out[:1], np.asarray(x0)[None, :], why, 0, timed_out=True)
        except RuntimeError as exc:  # the child died or raised: held, saying so
            why = f"attempt {attempt + 1}: {exc}"
            return Advance(t_out[:1], np.asarray(x0)[None, :], why, 0, timed_out=True)
        fail = "" if traj.complete else traj.message
        return Advance(traj.t, traj.x, fail, int(traj.stats.get("steps", 0) or 0))

    def close(self) -> None:
        """Stop the integrator's child process (at shutdown)."""
        self.calls.close()

    def signals(self, x: np.ndarray) -> dict[str, Any]:
        """Leader output, followers, formation slots, error norms, ĝ_i and |u_i|.

        Parameters
        ----------
        x : ndarray
            The state (at the current time).
        """
        out = self.outputs_at(self.t, x)
        return page_signals(out, x, self.layout, self.sc.N, self.u0_at(self.t))

    # ---------------------------------------------------------------- log
    def state_columns(self) -> list[str]:
        """Names of :meth:`state_table`'s columns (those of trajectory.csv)."""
        return state_columns(self.sc.N, self.sc.n, self.sc.m)

    def state_table(self, X: np.ndarray) -> np.ndarray:
        """Logged states as :meth:`state_columns`'s columns.

        Parameters
        ----------
        X : ndarray, shape (K, nx)
            States, one row per time.
        """
        return state_table(X, self.layout, self.sc.N)


# --------------------------------------------------------------------------- the child's side
def load_agents(paths: tuple[Any, ...]) -> None:
    """Load the kernel libraries in this (child) process once (checked as
    :func:`generated.agents.load` checks them; later loads of the same paths are free).

    Parameters
    ----------
    paths : tuple of Path
        The kernel libraries, in model order.
    """
    from generated import agents

    agents.load(paths)


def agents_attempt(
    paths: tuple[Any, ...],
    problem: Any,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: Any,
    breaks: list[float],
) -> Any:
    """One integrator attempt of the per-agent engine (run in the integrator's child process).

    Parameters
    ----------
    paths : tuple of Path
        As :func:`load_agents`.
    problem : generated.agents.AgentProblem
        The runtime data of the call.
    x0, t_out, settings, breaks
        As :func:`generated.agents.run`.

    Returns
    -------
    Trajectory
    """
    from generated import agents

    return agents.run(paths, problem, x0, t_out, settings, breakpoints=breaks)
