"""The methods that integrate a compiled ``casadi.Function`` with :func:`generated.integrate.integrate`.

:class:`CasadiSolver` is such a method; :class:`SundialsStepper` is the stepper of those
that call one of CasADi's SUNDIALS plugins per chunk (``cvodes``, ``idas``).
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from generated.solvers.base import ChunkFailure, Solver, Status

if TYPE_CHECKING:
    from generated.api import Built
    from generated.integrate import IntegratorSettings, Trajectory


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
        """:func:`generated.integrate.integrate` on ``built.dyn``.

        Parameters
        ----------
        built, x0, t_out, settings, breakpoints, progress
            As :meth:`generated.solvers.Solver.run`.
        """
        from generated.integrate import integrate

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
        from generated.integrate import add_stats

        opts, z = self.call_options(t0, x, z, new)
        integ = ca.integrator("sim", self.plugin, self.f, t0, times, opts)
        acc["integrator_calls"] += 1
        try:
            return integ(x0=x, z0=z)
        finally:
            try:
                add_stats(acc, integ.stats())
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
        from generated.integrate import failure_reason

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
