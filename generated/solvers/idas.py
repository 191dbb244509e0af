"""Method ``idas``: the semi-explicit DAE form (accelerations as algebraic states) with IDAS."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from generated.solvers import register
from generated.solvers.engine import CasadiSolver

if TYPE_CHECKING:
    import casadi as ca

    from generated.integrate import IntegratorSettings


class Idas(CasadiSolver):
    """IDAS (BDF) on the DAE form through CasADi; z solved from alg = 0 at restarts."""

    name = "idas"
    form = "dae"
    summary = "BDF on the DAE form (SUNDIALS IDAS) through CasADi"

    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """A :class:`generated.integrate.SundialsStepper` with the ``idas`` plugin.

        Parameters
        ----------
        f, settings, nx, nz
            As :meth:`generated.solvers.engine.CasadiSolver.stepper`.
        """
        from generated.integrate import SundialsStepper

        return SundialsStepper(f, settings, nz, "idas")


SOLVER = register(Idas())
