"""The integration engine over a compiled closed loop: schedule, chunks, replay, statistics.

The methods that integrate a generated ``casadi.Function`` with the integrator signature
``(t, x, z, p, u) -> (ode, alg, quad, zero)`` (usually a :func:`casadi.external` from
:mod:`generated.codegen`) are :class:`CasadiSolver` subclasses that each give a
*stepper* (:mod:`generated.solvers.cvodes`, ``idas``, ``fixed``); :func:`integrate`
runs it. :class:`SundialsStepper` is the stepper of those that call one of CasADi's
SUNDIALS plugins per chunk (``cvodes``, ``idas``).

The run is split at the known discontinuity times (fault onsets, steps in inputs,
:func:`generated.schedule.schedule`): each segment is a fresh integrator started from
the state reached, so a variable-step method never steps across a jump. Segments are
further cut into chunks of ``IntegratorSettings.chunk`` seconds: one stepper call each,
which bounds the work lost on a failure and drives the progress bar. On a failure (a
stepper raises :class:`generated.values.ChunkFailure`: too many steps, step size too
small, repeated convergence failures, NaN) the failing chunk is replayed one output
interval at a time, so the returned :class:`~generated.values.Trajectory` keeps every
output time reached; it is marked incomplete and carries the method, the time reached
and the solver's reason.
"""

from __future__ import annotations

import math
import re
import time
from abc import abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from core.errors import IntegrationError
from generated import solvers
from generated.schedule import Schedule, schedule
from generated.solvers.base import Solver
from generated.values import (
    ChunkFailure,
    IntegratorSettings,
    Status,
    Trajectory,
    flag_reason,
    flag_status,
)

if TYPE_CHECKING:
    from generated.built import Built


class CasadiSolver(Solver):
    """A method run by the chunked integration engine over ``Built.dyn``.

    Subclasses give :meth:`stepper`; the engine does the schedule (restarts at
    breakpoints), the chunks, the replay after a failure and the statistics.
    """

    @abstractmethod
    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """The engine's stepper: ``(t0, x, z, times, acc, new_segment) -> (X, Z)``.

        Parameters
        ----------
        f : casadi.Function
            Integrator form ``(t, x, z, p, u) -> (ode, alg, quad, zero)``.
        settings : IntegratorSettings
        nx, nz : int
            Numbers of differential and algebraic states.
        """

    def run(
        self,
        built: Built,
        x0: np.ndarray,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float] = (),
        progress: Callable[[float], None] | None = None,
    ) -> Trajectory:
        """:func:`integrate` on ``built.dyn``.

        Parameters
        ----------
        built, x0, t_out, settings, breakpoints, progress
            As :meth:`generated.solvers.Solver.run`.
        """
        dae = self.form == "dae"
        z0 = np.asarray(built.closed_loop.z0, dtype=float) if dae else None
        return integrate(
            built.dyn, x0, t_out, settings, breakpoints=breakpoints, z0=z0, progress=progress
        )


class SundialsStepper:
    """One call of a CasADi SUNDIALS plugin per chunk (a fresh integrator: a restart).

    Subclasses set :attr:`plugin` and may add options (:meth:`plugin_options`) or choose
    each call's options and starting z (:meth:`call_options`).

    Parameters
    ----------
    f : casadi.Function
        Integrator form; ``nz`` algebraic states for a DAE plugin, none otherwise.
    s : IntegratorSettings
    nz : int
    """

    plugin: str = ""

    def __init__(self, f: ca.Function, s: IntegratorSettings, nz: int) -> None:
        self.f, self.s, self.nz = f, s, nz
        opts: dict[str, Any] = {
            "abstol": s.atol,
            "reltol": s.rtol,
            "max_num_steps": int(s.max_steps),
            "newton_scheme": s.newton_scheme,
            "disable_internal_warnings": True,
            "show_eval_warnings": False,
        }
        if s.newton_scheme == "direct":
            opts["linear_solver"] = s.linear_solver
        opts.update(self.plugin_options())
        opts.update(dict(s.extra_options))
        self.opts = opts

    def plugin_options(self) -> dict[str, Any]:
        """Options of this plugin added to the common ones (default: none)."""
        return {}

    def call_options(
        self, t0: float, x: np.ndarray, z: np.ndarray, new_segment: bool
    ) -> tuple[dict[str, Any], np.ndarray]:
        """The options of one call and the z it starts from (default: the same every call).

        Parameters
        ----------
        t0 : float
        x, z : ndarray
        new_segment : bool
            The call starts a segment (t = 0 or a breakpoint).
        """
        return self.opts, z

    def _solve(
        self, t0: float, x: np.ndarray, z: np.ndarray, times: list[float], acc: dict, new: bool
    ) -> dict[str, Any]:
        """One CasADi integrator call (its counters added to ``acc`` even on a failure)."""
        opts, z = self.call_options(t0, x, z, new)
        integ = ca.integrator("sim", self.plugin, self.f, t0, times, opts)
        acc["integrator_calls"] += 1
        try:
            return integ(x0=x, z0=z)
        finally:
            try:
                _add_stats(acc, integ.stats())
            except RuntimeError:  # no stats when the call failed before the solver ran
                pass

    def __call__(
        self,
        t0: float,
        x: np.ndarray,
        z: np.ndarray,
        times: list[float],
        acc: dict,
        new_segment: bool = True,
    ) -> tuple[np.ndarray, np.ndarray]:
        """States (and algebraic states) at ``times``; raises :class:`ChunkFailure`.

        Parameters
        ----------
        t0 : float
        x, z : ndarray
            The state and the algebraic states at t0.
        times : list of float
            Output times of the chunk.
        acc : dict
            Statistics, updated.
        new_segment : bool
        """
        try:
            res = self._solve(t0, x, z, times, acc, new_segment)
        except RuntimeError as exc:
            raise ChunkFailure(*failure_reason(exc), times[-1]) from None
        X = np.array(res["xf"], dtype=float).reshape(len(x), len(times), order="F").T
        Z = (
            np.array(res["zf"], dtype=float).reshape(self.nz, len(times), order="F").T
            if self.nz
            else np.zeros((len(times), 0))
        )
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Z))):
            raise ChunkFailure("state is not finite (NaN or Inf)", Status.NOT_FINITE, times[-1])
        return X, Z


def _chunks(sched: Schedule, chunk: float) -> list[list[tuple]]:
    """Chunks of targets ``(time, output index or -1)``: the schedule's segments cut into
    integrator calls of <= ``chunk`` s, each from the previous chunk's last target."""
    chunks: list[list[tuple]] = []
    for start, end, rows in sched.segments():
        if end <= start:  # a single output time: nothing to integrate
            continue
        seg = [(float(sched.targets[k]), k) for k in rows]
        if not seg or seg[-1][0] != end:
            seg.append((end, -1))  # restart point that is not an output time
        cur: list[tuple] = []
        for tgt in seg:
            if cur and tgt[0] - start > chunk * (1 + 1e-12):
                chunks.append(cur)
                start = cur[-1][0]
                cur = []
            cur.append(tgt)
        chunks.append(cur)
    return chunks


def failure_reason(exc: Exception) -> tuple[str, Status]:
    """The readable reason and the :class:`Status` of a CasADi integrator's exception.

    Parameters
    ----------
    exc : Exception
    """
    m = re.search(r'returned "((?:CV|IDA)_\w+)"', str(exc))
    if m:
        return flag_reason(m.group(1)), flag_status(m.group(1))
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return (lines[-1] if lines else type(exc).__name__), Status.FAILED


_STAT_KEYS = {
    "steps": ("nsteps",),
    "rhs_evals": ("nfevals", "nrevals"),
    "jac_evals": ("n_call_jacF", "njevals"),
    "lin_setups": ("nlinsetups",),
    "error_test_fails": ("netfails",),
    "newton_fails": ("nncfails",),
    "newton_iters": ("nniters",),
    "jtimes_evals": ("n_call_jtimesF",),
}


def _add_stats(acc: dict[str, Any], st: dict[str, Any]) -> None:
    """Add a SUNDIALS integrator's counters ``st`` to the run's statistics ``acc``."""
    h = st.get("hlast")
    if isinstance(h, float) and math.isfinite(h) and h > 0:
        acc["last_step"] = h
    for k, names in _STAT_KEYS.items():
        for nm in names:
            v = st.get(nm)
            if v is not None and isinstance(v, int | float) and math.isfinite(v):
                acc[k] += int(v)
                break


@dataclass
class _Rows:
    """The output rows of a run as they are reached (states, algebraic states, last row)."""

    t_out: np.ndarray
    X: np.ndarray
    Z: np.ndarray | None
    last: int = 0

    @classmethod
    def empty(cls, t_out: np.ndarray, nx: int, nz: int, keep_z: bool) -> _Rows:
        K = len(t_out)
        return cls(t_out, np.full((K, nx), np.nan), np.full((K, nz), np.nan) if keep_z else None)

    def store(self, idx: int, x: np.ndarray, z: np.ndarray) -> None:
        self.X[idx] = x
        if self.Z is not None:
            self.Z[idx] = z
        self.last = idx

    def trajectory(self, method: str, failure: ChunkFailure | None, acc: dict) -> Trajectory:
        n = self.last + 1
        message = ""
        if failure is not None:
            message = (
                f"{method} failed after t = {float(self.t_out[self.last]):.6g} s "
                f"(working towards t = {failure.t_target:.6g} s): {failure.reason}"
            )
        return Trajectory(
            t=self.t_out[:n].copy(),
            x=self.X[:n],
            z=None if self.Z is None else self.Z[:n],
            method=method,
            status=Status.OK if failure is None else failure.status,
            t_reached=float(self.t_out[self.last]),
            message=message,
            stats=acc,
        )


def integrate(
    f: ca.Function,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    *,
    breakpoints: Sequence[float] = (),
    z0: np.ndarray | None = None,
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate ``f`` from ``x0`` and return the states at the output times.

    Parameters
    ----------
    f : casadi.Function
        Integrator form ``(t, x, z, p, u) -> (ode, alg, quad, zero)``; for a DAE
        method (``idas``) with algebraic states z, for an ODE method (``cvodes``,
        ``fixed``) nz = 0. p and u must be empty.
    x0 : ndarray
        Initial state at ``t_out[0]``.
    t_out : ndarray
        Increasing output times (see :func:`output_grid`).
    settings : IntegratorSettings
        Its method must have a stepper over a ``casadi.Function``
        (:class:`generated.solvers.engine.CasadiSolver`).
    breakpoints : sequence of float
        Known discontinuity times: the run restarts there.
    z0 : ndarray, optional
        Initial guess of the algebraic states (IDAS).
    progress : callable, optional
        Called with the simulated time reached after every chunk.

    Returns
    -------
    Trajectory
        Never raises on an integrator failure: the result is then marked
        incomplete (``status``, ``message``, ``t_reached``); call
        :meth:`Trajectory.raise_if_incomplete` to turn it into an error.
    """
    wall0 = time.perf_counter()
    s = settings
    solver = solvers.get(s.method)
    make_stepper = getattr(solver, "stepper", None)
    if make_stepper is None:
        raise IntegrationError(
            f"method {s.method!r} does not integrate a casadi.Function: "
            "use generated.api.integrate_built"
        )
    nx, nz = _sizes(f, solver.form)
    x = np.asarray(x0, dtype=float).ravel()
    if x.size != nx:
        raise IntegrationError(f"x0 has {x.size} entries, {f.name()} expects {nx}")
    z = np.zeros(nz) if z0 is None else np.asarray(z0, dtype=float).ravel()
    rows = _Rows.empty(np.asarray(t_out, dtype=float), nx, nz, keep_z=solver.form == "dae")
    rows.store(0, x, z)
    acc = dict.fromkeys([*_STAT_KEYS, "restarts", "integrator_calls", "refined_intervals"], 0)
    run = _Run(make_stepper(f, s, nx, nz), schedule(rows.t_out, breakpoints), rows, acc)
    failure = run.chunks(s.chunk, x, z, solver.form == "dae", progress)
    acc["wall_seconds"] = time.perf_counter() - wall0
    return rows.trajectory(s.method, failure, acc)


def _sizes(f: ca.Function, form: str) -> tuple[int, int]:
    """``(nx, nz)`` of ``f``, checked against the method's form."""
    nx = int(f.size1_in(1))
    nz = int(f.size1_in(2))
    if f.nnz_in(3) or f.nnz_in(4):
        raise IntegrationError(f"{f.name()}: parameters p and controls u must be empty")
    if form != "dae" and nz:
        raise IntegrationError(
            f"an ODE method needs the ODE form (nz = 0); {f.name()} has nz = {nz}"
        )
    return nx, nz


@dataclass
class _Run:
    """The chunk loop of :func:`integrate` over one stepper."""

    stepper: Any
    sched: Schedule
    rows: _Rows
    acc: dict

    def chunks(
        self,
        chunk: float,
        x: np.ndarray,
        z: np.ndarray,
        dae: bool,
        progress: Callable[[float], None] | None,
    ) -> ChunkFailure | None:
        """Integrate every chunk; return the failure that stopped the run, or None."""
        restarts = set(self.sched.breaks.tolist())  # compared exactly: targets are these times
        t_cur = float(self.sched.t_out[0])
        for ci, chunk_targets in enumerate(_chunks(self.sched, chunk)):
            if ci:
                self.acc["restarts"] += 1
            times = [c[0] for c in chunk_targets]
            new_seg = ci == 0 or t_cur in restarts
            Xc, Zc, failure = self._advance(t_cur, x, z, times, new_seg, dae and ci == 0)
            for k in range(len(Xc)):
                tgt, idx = chunk_targets[k]
                x, t_cur = Xc[k], tgt
                if len(z):
                    z = Zc[k]
                if idx >= 0:
                    self.rows.store(idx, x, z)
            if failure is not None:
                return failure
            if progress is not None:
                progress(t_cur)
        return None

    def _advance(
        self, t0: float, x, z, times: list[float], new_seg: bool, first_dae: bool
    ) -> tuple[Any, Any, ChunkFailure | None]:
        """One chunk, replayed target by target after a failure to keep what was reached."""
        try:
            if first_dae:  # t0 in the grid: row 0 gets the consistent z(t0) the solve started from
                Xc, Zc = self.stepper(t0, x, z, [t0, *times], self.acc)
                self.rows.Z[0], Xc, Zc = Zc[0], Xc[1:], Zc[1:]
                return Xc, Zc, None
            Xc, Zc = self.stepper(t0, x, z, times, self.acc, new_seg)
            return Xc, Zc, None
        except ChunkFailure:
            return self._replay(t0, x, z, times, new_seg)

    def _replay(self, t0: float, x, z, times: list[float], new_segment: bool):
        """Advance target by target; return the states reached and the failure (or None)."""
        xs, zs = [], []
        for k, tt in enumerate(times):
            try:
                Xi, Zi = self.stepper(t0, x, z, [tt], self.acc, new_segment and k == 0)
            except ChunkFailure as fail:
                return xs, zs, fail
            x, t0 = Xi[-1], tt
            z = Zi[-1] if len(Zi[-1]) else z
            xs.append(x)
            zs.append(z)
        return xs, zs, None
