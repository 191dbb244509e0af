"""The integration engine over a compiled closed loop: schedule, chunks, replay, statistics.

The methods that integrate a generated ``casadi.Function`` with the integrator signature
``(t, x, z, p, u) -> (ode, alg, quad, zero)`` (usually a :func:`casadi.external` from
:mod:`generated.codegen`) each give a *stepper* (:mod:`generated.solvers.cvodes`,
``idas``, ``fixed``); this module runs it.

The run is split at the known discontinuity times (fault onsets, steps in inputs):
each segment is a fresh integrator started from the state reached, so a
variable-step method never steps across a jump. Segments are further cut into
chunks of ``IntegratorSettings.chunk`` seconds: one stepper call each, which
bounds the work lost on a failure and drives the progress bar. On a failure
(a stepper raises :class:`generated.solvers.ChunkFailure`: too many steps, step size
too small, repeated convergence failures, NaN) the failing chunk is replayed one output
interval at a time, so the returned :class:`Trajectory` keeps every output time
reached; it is marked incomplete and carries the method, the time reached and the
solver's reason.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from core.errors import IntegrationError
from core.scenario import Integration
from core.settings import default_of
from generated import solvers
from generated.solvers import ChunkFailure, Status, flag_status
from generated.sundials_log import (  # noqa: F401  (re-exported)
    new_sundials_log,
    sundials_messages,
    sundials_summary,
    take_sundials_log,
)

#: SUNDIALS return flags -> readable reason
_REASONS = {
    "TOO_MUCH_WORK": "too many steps before the next output time (raise max_steps)",
    "TOO_MUCH_ACC": "tolerances too small for machine precision",
    "ERR_FAIL": "error test failed repeatedly (step size too small)",
    "ERR_FAILURE": "error test failed repeatedly (step size too small)",
    "CONV_FAIL": "Newton iteration failed repeatedly (step size too small)",
    "CONV_FAILURE": "Newton iteration failed repeatedly (step size too small)",
    "RHSFUNC_FAIL": "right-hand side failed (NaN or Inf)",
    "RES_FAIL": "residual failed (NaN or Inf)",
    "REP_RES_ERR": "residual failed repeatedly (NaN or Inf)",
    "LSETUP_FAIL": "linear solver setup failed (singular iteration matrix)",
    "LSOLVE_FAIL": "linear solve failed",
    "CONSTR_FAIL": "constraint test failed",
    "FIRST_RES_FAIL": "residual failed at the first call",
    "LINESEARCH_FAIL": "consistent initial conditions not found (line search)",
    "NO_RECOVERY": "consistent initial conditions not found",
}


@dataclass(frozen=True)
class IntegratorSettings:
    """How to integrate.

    Attributes
    ----------
    method : str
        A registered method (:func:`generated.solvers.names`): ``cvodes`` (BDF through
        CasADi, default), ``native`` (BDF, SUNDIALS CVODE driven from C:
        :mod:`generated.native`), ``idas`` (the DAE form) or ``fixed`` (ROS2).
    rtol, atol : float
        Relative and absolute tolerances (CVODES, IDAS).
    max_steps : int
        CVODES/IDAS ``max_num_steps``: steps allowed between two output times.
    fixed_step : float
        Largest step of the fixed-step method (each output interval is divided
        into equal steps no longer than this).
    fixed_rtol, fixed_atol : float
        Safeguard of the fixed-step method: an output interval whose embedded error
        estimate ``|h (k1 + k2)/2| / (atol + rtol |x|)`` exceeds 1 anywhere (or that
        produces NaN) is recomputed as two halves with the same number of steps each
        (bisection, recursively, at most ``fixed_max_halvings`` levels deep). Loose by design: the exact sign function's chattering (a jump in f of
        size Δ gives an estimate h Δ / 2) passes; a violent transient does not.
    fixed_max_halvings : int
    chunk : float
        Simulated seconds per integrator call (restart, progress, failure granularity).
    newton_scheme, linear_solver : str
        Linear algebra of CVODES/IDAS (see ``CodegenSettings.integrator_options``);
        ``linear_solver`` is also the sparse solver of the fixed-step method.
    algebraic_atol : float
        IDAS only: absolute tolerance of the algebraic states z. z is not error-tested
        (``suppress_algebraic``), so this enters only IDAS's Newton convergence test,
        with weights 1/(rtol|z| + algebraic_atol). The default 1e30 leaves z out of
        that test: in the semi-explicit form z enters ẋ, so a Newton error in z shows
        up in the x-corrections (times h/α), as in the ODE form, while testing z itself
        asked for more digits than z(x) has on the paper scenario (a 1-ulp change of x
        moves the accelerations by up to 1.6e-3 = 5 000 rtol|z|: 757 244 steps and
        3.4e5 Newton failures instead of 78 082 and 1 061; docs/simulation.md).
        ``algebraic_atol = atol`` restores the former behaviour.
    extra_options : tuple of (str, value) pairs
        Merged last into the CVODES/IDAS options (e.g. ``("use_preconditioner", False)``,
        ``("max_krylov", 50)`` for GMRES at large N).
    """

    # the scenario's [integration] defaults: core.scenario.Integration owns them
    method: str = default_of(Integration, "method")
    rtol: float = default_of(Integration, "rtol")
    atol: float = default_of(Integration, "atol")
    max_steps: int = default_of(Integration, "max_steps")
    fixed_step: float = default_of(Integration, "fixed_step")
    chunk: float = 1.0
    fixed_rtol: float = 1e-3
    fixed_atol: float = 1e-3
    fixed_max_halvings: int = 30
    newton_scheme: str = "direct"
    linear_solver: str = "csparse"
    algebraic_atol: float = 1e30
    extra_options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if self.method not in solvers.names():
            raise IntegrationError(
                f"IntegratorSettings.method: {self.method!r} is not one of "
                f"{', '.join(solvers.names())}"
            )
        positive = ("rtol", "atol", "fixed_step", "chunk", "fixed_rtol", "fixed_atol")
        for name in (*positive, "algebraic_atol"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise IntegrationError(f"IntegratorSettings.{name}: {v!r} must be a number > 0")
        if not 0 <= int(self.fixed_max_halvings) <= 30:
            raise IntegrationError(
                f"IntegratorSettings.fixed_max_halvings: {self.fixed_max_halvings} not in [0, 30]"
            )
        if int(self.max_steps) < 1:
            raise IntegrationError(f"IntegratorSettings.max_steps: {self.max_steps} must be >= 1")


@dataclass(frozen=True)
class Trajectory:
    """States at the output times, complete or up to a failure.

    Attributes
    ----------
    t : ndarray, shape (K,)
    x : ndarray, shape (K, nx)
    z : ndarray or None, shape (K, nz)
        Algebraic states (IDAS only).
    method : str
    status : Status
        ``Status.OK`` for a complete run, else why the integrator gave up before the
        last output time (test this, not the message).
    t_reached : float
        Last output time integrated successfully.
    message : str
        Empty when complete, else the reason (method, time reached, solver flag).
    stats : dict of str to float
        ``steps``, ``rhs_evals``, ``jac_evals``, ``lin_setups``, ``error_test_fails``,
        ``newton_fails``, ``newton_iters``, ``jtimes_evals``, ``restarts``, ``integrator_calls``,
        ``wall_seconds`` and, for CVODES/IDAS, ``last_step`` (the last step size taken).
    sundials_log : str
        SUNDIALS' warnings and errors of the run, one line each (``[WARNING][CVode]
        text (cvode.c:line)``; the native drivers), empty when there were none; counted
        by :func:`sundials_messages`.
    t_stop : float
        Where the integrator stood when it returned (the native drivers; NaN for the
        others): on a failure CVODE's last internal step, between ``t_reached`` and the
        next output time; the horizon for a complete run.
    x_stop : ndarray or None, shape (nx,)
        The state at ``t_stop`` (the native drivers; None for the others). On a failure
        it tells a state that ran away from an integrator that stalled on a tame one,
        which the output rows, ending at ``t_reached``, cannot.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray | None
    method: str
    status: Status
    t_reached: float
    message: str
    stats: dict[str, float] = field(default_factory=dict)
    sundials_log: str = ""
    t_stop: float = math.nan
    x_stop: np.ndarray | None = None

    @property
    def complete(self) -> bool:
        """True when every output time was reached (``status is Status.OK``)."""
        return self.status is Status.OK

    def largest_at_stop(self) -> int | None:
        """Index of the largest ``|x_stop|`` entry (a non-finite one first); None without it."""
        if self.x_stop is None:
            return None
        return int(np.argmax(np.nan_to_num(np.abs(self.x_stop), nan=np.inf)))

    def raise_if_incomplete(self) -> None:
        """Raise :class:`IntegrationError` (with ``t_reached``) when incomplete."""
        if not self.complete:
            raise IntegrationError(self.message, self.t_reached)


def stop_note(t_stop: float, state: str, value: float) -> str:
    """The clause a failure's message gains: where CVODE stood and its largest state there.

    Parameters
    ----------
    t_stop : float
        ``Trajectory.t_stop``.
    state : str
        The name of the largest entry of ``x_stop`` (e.g. ``StateLayout.name_of``).
    value : float
        Its magnitude.
    """
    return (
        f"; at CVODE's last step, t = {t_stop:.7g} s, the largest state is {state} = "
        f"{value:.3g} in magnitude"
    )


def output_grid(horizon: float, output_step: float) -> np.ndarray:
    """Output times ``0, h, 2h, ..., horizon`` (the last one exactly ``horizon``).

    Parameters
    ----------
    horizon : float
        Final time (s).
    output_step : float
        Spacing ``h`` of the output times (s); must divide ``horizon``.

    Raises
    ------
    IntegrationError
        If the step does not divide the horizon (to 1e-9 relative).
    """
    n = round(horizon / output_step)
    if n < 1 or abs(n * output_step - horizon) > 1e-9 * max(horizon, 1.0):
        raise IntegrationError(
            f"integration.output_step: {output_step} does not divide the horizon {horizon} "
            "(choose a step that does)"
        )
    return np.linspace(0.0, horizon, n + 1)


#: two times closer than this many machine epsilons of the run's time scale are one instant
TIME_ULPS = 1000


def time_tolerance(t0: float, tf: float) -> float:
    """The time resolution of a run over ``[t0, tf]``: ``TIME_ULPS · eps · max(1, |t0|, |tf|)``.

    CVODE refuses an output time within ``2 eps |t|`` of the current time (``TOO_CLOSE``)
    and takes a stop time within ``100 eps (|t| + |h|)`` as reached; 1000 eps of the
    time scale lies above both and far below any output step (4.4e-12 s at 20 s).

    Parameters
    ----------
    t0, tf : float
        First and last output time.
    """
    return TIME_ULPS * float(np.finfo(float).eps) * max(1.0, abs(t0), abs(tf))


@dataclass(frozen=True)
class Schedule:
    """Where every integrator of a run stops: restarts and the time integrated to per row.

    Made by :func:`schedule`, the one place that reconciles output times with breakpoints
    (the CasADi methods here, and the native drivers, which receive ``targets`` and
    ``breaks``). Every two distinct times among ``t0``, ``breaks`` and ``targets`` are
    more than ``tol`` apart, so no integrator is asked for a time within ``tol`` of the
    time it stands at.

    Attributes
    ----------
    t_out : ndarray
        The requested output times; the trajectory's rows keep exactly these.
    targets : ndarray
        The time integrated to for each row: ``t_out[k]``, or the breakpoint within
        ``tol`` of it (the row then holds the state at that breakpoint, reached by the
        segment that ends there; it differs from the state at ``t_out[k]`` by at most
        ``tol · |ẋ|``).
    breaks : ndarray
        Restart times, strictly inside ``(t0 + tol, tf - tol)``, sorted, pairwise more
        than ``tol`` apart.
    tol : float
        :func:`time_tolerance` of the run.
    """

    t_out: np.ndarray
    targets: np.ndarray
    breaks: np.ndarray
    tol: float

    def segments(self) -> list[tuple[float, float, list[int]]]:
        """``(start, end, rows)`` per segment between restarts; ``rows``: the output rows
        whose target lies in ``(start, end]`` (``end`` is a breakpoint or the horizon)."""
        ends = [*self.breaks.tolist(), float(self.targets[-1])]
        out, k, start = [], 1, float(self.targets[0])
        for end in ends:
            rows = []
            while k < len(self.targets) and self.targets[k] <= end:
                rows.append(k)
                k += 1
            out.append((start, end, rows))
            start = end
        return out


def schedule(t_out: np.ndarray, breakpoints: Sequence[float] = ()) -> Schedule:
    """Reconcile output times with breakpoints (restart times) to the run's time resolution.

    A breakpoint within ``tol`` (:func:`time_tolerance`) of ``t0``, of the horizon or of
    an earlier kept breakpoint is dropped (the run starts, stops or restarts there
    already), as is one outside ``(t0, tf)``; an output time within ``tol`` of a kept
    breakpoint is integrated to that breakpoint (:attr:`Schedule.targets`).

    Parameters
    ----------
    t_out : ndarray
        Output times, increasing by more than ``2 tol`` (the first is the start).
    breakpoints : sequence of float
        Known discontinuity times, any order.

    Returns
    -------
    Schedule

    Raises
    ------
    IntegrationError
        If the output times are not finite, or two are within ``2 tol`` of each other.
    """
    t_out = np.asarray(t_out, dtype=float).ravel()
    if t_out.size < 1 or not np.all(np.isfinite(t_out)):
        raise IntegrationError("output times: need at least one, all finite")
    t0, tf = float(t_out[0]), float(t_out[-1])
    tol = time_tolerance(t0, tf)
    if t_out.size > 1 and np.diff(t_out).min() <= 2.0 * tol:
        raise IntegrationError(
            f"output times must increase by more than {2.0 * tol:.3g} s (the time resolution); "
            "choose a larger integration.output_step"
        )
    kept: list[float] = []
    for b in sorted(float(b) for b in breakpoints if math.isfinite(b)):
        if t0 + tol < b < tf - tol and (not kept or b - kept[-1] > tol):
            kept.append(b)
    breaks = np.array(kept, dtype=float)
    return Schedule(t_out=t_out, targets=_targets(t_out, breaks, tol), breaks=breaks, tol=tol)


def _targets(t_out: np.ndarray, breaks: np.ndarray, tol: float) -> np.ndarray:
    """``t_out`` with every time after the first moved to its nearest break if within ``tol``.

    The nearest of the two breaks around ``t_out[k]`` (the earlier on a tie), for all
    rows at once.
    """
    targets = t_out.copy()
    if not breaks.size or t_out.size < 2:
        return targets
    tk = t_out[1:]
    i = np.searchsorted(breaks, tk)
    lo = breaks[np.maximum(i - 1, 0)]
    hi = breaks[np.minimum(i, breaks.size - 1)]
    d_lo = np.where(i >= 1, np.abs(lo - tk), np.inf)
    d_hi = np.where(i < breaks.size, np.abs(hi - tk), np.inf)
    near = np.where(d_lo <= d_hi, lo, hi)
    move = np.abs(near - tk) <= tol
    targets[1:][move] = near[move]
    return targets


def _plan(t_out: np.ndarray, breakpoints: Sequence[float], chunk: float) -> list[list[tuple]]:
    """Chunks of targets ``(time, output index or -1)``; a new chunk starts at every breakpoint.

    Each chunk is one integrator call from the previous chunk's last target.
    """
    return _chunks(schedule(t_out, breakpoints), chunk)


def _chunks(sched: Schedule, chunk: float) -> list[list[tuple]]:
    """:func:`_plan` on a :class:`Schedule`: its segments cut into calls of <= ``chunk`` s."""
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


def flag_reason(flag: str) -> str:
    """``"TOO_MUCH_WORK: too many steps ..."`` for a SUNDIALS return flag name.

    Parameters
    ----------
    flag : str
        The flag's name with or without its ``CV_``/``IDA_`` prefix.
    """
    flag = re.sub(r"^(?:CV|IDA)_", "", flag)
    return f"{flag}: {_REASONS.get(flag, 'solver failure')}"


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


def add_stats(acc: dict[str, Any], st: dict[str, Any]) -> None:
    """Add a SUNDIALS integrator's counters ``st`` to the run's statistics ``acc``.

    Parameters
    ----------
    acc, st : dict
    """
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
