"""The chunked integration engine over a compiled closed loop: schedule, chunks, replay.

:class:`CasadiSolver` subclasses (``cvodes``, ``idas``, ``fixed``) each give a stepper
over ``Built.dyn``; :func:`integrate` runs it segment by segment between breakpoints,
in chunks of ``IntegratorSettings.chunk`` s, and replays a failing chunk one output
interval at a time so the trajectory keeps every output reached (docs/simulation.md).
"""

from __future__ import annotations

import math
import re
import time
from abc import abstractmethod
from collections.abc import Callable, Sequence
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
    """A method run by :func:`integrate` over ``Built.dyn``: subclasses give :meth:`stepper`."""

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
        z0 = np.asarray(built.closed_loop.z0, dtype=float) if self.form == "dae" else None
        return integrate(
            built.dyn, x0, t_out, settings, breakpoints=breakpoints, z0=z0, progress=progress
        )


class SundialsStepper:
    """One call of CasADi's SUNDIALS :attr:`plugin` per chunk (a fresh integrator: a restart).

    Parameters
    ----------
    f : casadi.Function
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
            The call starts a segment.
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
        """States (and algebraic states) at ``times``; raises :class:`ChunkFailure`."""
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
    """Integrate ``f`` from ``x0`` with ``settings.method``, a :class:`CasadiSolver`.

    A failure gives an incomplete :class:`Trajectory` (``status``, ``message``,
    ``t_reached``), never an exception.

    Parameters
    ----------
    f : casadi.Function
        Integrator form; nz = 0 for an ODE method; p and u empty.
    x0 : ndarray
    t_out : ndarray
        Increasing output times.
    settings : IntegratorSettings
    breakpoints : sequence of float
        Known discontinuity times: the run restarts there.
    z0 : ndarray, optional
        Initial guess of the algebraic states.
    progress : callable, optional
        Called with the simulated time reached after every chunk.
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
    dae = solver.form == "dae"
    nx, nz = int(f.size1_in(1)), int(f.size1_in(2))
    if f.nnz_in(3) or f.nnz_in(4):
        raise IntegrationError(f"{f.name()}: parameters p and controls u must be empty")
    if not dae and nz:
        raise IntegrationError(
            f"an ODE method needs the ODE form (nz = 0); {f.name()} has nz = {nz}"
        )
    x = np.asarray(x0, dtype=float).ravel()
    if x.size != nx:
        raise IntegrationError(f"x0 has {x.size} entries, {f.name()} expects {nx}")
    z = np.zeros(nz) if z0 is None else np.asarray(z0, dtype=float).ravel()
    t_out = np.asarray(t_out, dtype=float)
    acc = dict.fromkeys([*_STAT_KEYS, "restarts", "integrator_calls", "refined_intervals"], 0)
    stepper = make_stepper(f, s, nx, nz)
    X = np.full((len(t_out), nx), np.nan)
    Z = np.full((len(t_out), nz), np.nan) if dae else None
    X[0] = x
    if Z is not None:
        Z[0] = z
    sched = schedule(t_out, breakpoints)
    last, failure = _run_chunks(stepper, sched, s.chunk, x, z, X, Z, acc, progress)
    acc["wall_seconds"] = time.perf_counter() - wall0
    message = ""
    if failure is not None:
        message = (
            f"{s.method} failed after t = {float(t_out[last]):.6g} s "
            f"(working towards t = {failure.t_target:.6g} s): {failure.reason}"
        )
    return Trajectory(
        t=t_out[: last + 1].copy(),
        x=X[: last + 1],
        z=None if Z is None else Z[: last + 1],
        method=s.method,
        status=Status.OK if failure is None else failure.status,
        t_reached=float(t_out[last]),
        message=message,
        stats=acc,
    )


def _run_chunks(
    stepper: Any,
    sched: Schedule,
    chunk: float,
    x: np.ndarray,
    z: np.ndarray,
    X: np.ndarray,
    Z: np.ndarray | None,
    acc: dict,
    progress: Callable[[float], None] | None,
) -> tuple[int, ChunkFailure | None]:
    """Fill the rows X (and Z, for a DAE) reached; return the last one and the failure."""
    last, failure = 0, None
    restarts = set(sched.breaks.tolist())  # compared exactly: targets are these times
    t_cur = float(sched.t_out[0])
    for ci, targets in enumerate(_chunks(sched, chunk)):
        if ci:
            acc["restarts"] += 1
        times = [c[0] for c in targets]
        new_seg = ci == 0 or t_cur in restarts
        try:
            if Z is not None and ci == 0:  # row 0 gets the consistent z(t0) IDAS starts from
                Xc, Zc = stepper(t_cur, x, z, [t_cur, *times], acc)
                Z[0], Xc, Zc = Zc[0], Xc[1:], Zc[1:]
            else:
                Xc, Zc = stepper(t_cur, x, z, times, acc, new_seg)
        except ChunkFailure:
            Xc, Zc, failure = _replay(stepper, acc, t_cur, x, z, times, new_seg)
        for k in range(len(Xc)):
            tgt, idx = targets[k]
            x, t_cur = Xc[k], tgt
            if len(z):
                z = Zc[k]
            if idx >= 0:
                X[idx], last = x, idx
                if Z is not None:
                    Z[idx] = z
        if failure is not None:
            break
        if progress is not None:
            progress(t_cur)
    return last, failure


def _replay(stepper: Any, acc: dict, t0: float, x, z, times: list[float], new_segment: bool):
    """A failed chunk target by target: the states reached and the failure (or None)."""
    xs, zs = [], []
    for k, tt in enumerate(times):
        try:
            Xi, Zi = stepper(t0, x, z, [tt], acc, new_segment and k == 0)
        except ChunkFailure as fail:
            return xs, zs, fail
        x, t0 = Xi[-1], tt
        z = Zi[-1] if len(Zi[-1]) else z
        xs.append(x)
        zs.append(z)
    return xs, zs, None
