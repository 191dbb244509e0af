"""The methods that integrate a compiled ``casadi.Function`` with :func:`generated.integrate.integrate`."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from generated.solvers.base import Solver

if TYPE_CHECKING:
    import casadi as ca

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
