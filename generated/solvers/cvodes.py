"""Method ``cvodes``: BDF (SUNDIALS CVODES) through CasADi's integrator interface."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from generated.solvers import register
from generated.solvers.engine import CasadiSolver

if TYPE_CHECKING:
    import casadi as ca

    from generated.integrate import IntegratorSettings


class Cvodes(CasadiSolver):
    """CVODES' BDF on the ODE form, one CasADi integrator call per chunk."""

    name = "cvodes"
    form = "ode"
    summary = "BDF (SUNDIALS CVODES) through CasADi"

    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """A :class:`generated.integrate.SundialsStepper` with the ``cvodes`` plugin.

        Parameters
        ----------
        f, settings, nx, nz
            As :meth:`generated.solvers.engine.CasadiSolver.stepper`.
        """
        from generated.integrate import SundialsStepper

        return SundialsStepper(f, settings, nz, "cvodes")


SOLVER = register(Cvodes())
