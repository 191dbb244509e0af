"""Method ``cvodes``: BDF (SUNDIALS CVODES) through CasADi's integrator interface."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from generated.solvers import register
from generated.solvers.engine import CasadiSolver, SundialsStepper

if TYPE_CHECKING:
    import casadi as ca

    from generated.values import IntegratorSettings


class CvodesStepper(SundialsStepper):
    """CVODES' BDF on the ODE form, one CasADi integrator call per chunk."""

    plugin = "cvodes"

    def plugin_options(self) -> dict[str, Any]:
        """BDF (CVODES' ``linear_multistep_method``)."""
        return {"linear_multistep_method": "bdf"}


class Cvodes(CasadiSolver):
    """CVODES' BDF on the ODE form, one CasADi integrator call per chunk."""

    name = "cvodes"
    form = "ode"
    summary = "BDF (SUNDIALS CVODES) through CasADi"

    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """A :class:`CvodesStepper`.

        Parameters
        ----------
        f, settings, nx, nz
        """
        return CvodesStepper(f, settings, nz)


SOLVER = register(Cvodes())
