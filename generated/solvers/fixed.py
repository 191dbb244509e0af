"""Method ``fixed``: the linearly implicit ROS2 method with a fixed step (the exact sign's method)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from generated.solvers import register
from generated.solvers.engine import CasadiSolver

if TYPE_CHECKING:
    import casadi as ca

    from generated.integrate import IntegratorSettings


class Fixed(CasadiSolver):
    """ROS2 (:class:`generated.integrate.Ros2Stepper`) with the generated sparse Jacobian."""

    name = "fixed"
    form = "ode"
    summary = "ROS2, fixed step with a loose safeguard"
    fixed_step = True

    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """A :class:`generated.integrate.Ros2Stepper`.

        Parameters
        ----------
        f, settings, nx, nz
            As :meth:`generated.solvers.engine.CasadiSolver.stepper`.
        """
        from generated.integrate import Ros2Stepper

        return Ros2Stepper(f, settings, nx)

    def settings_used(self, settings: IntegratorSettings) -> dict[str, Any]:
        """``fixed_step``, ``fixed_rtol`` and ``fixed_atol``.

        Parameters
        ----------
        settings : IntegratorSettings
        """
        return {
            "fixed_step": settings.fixed_step,
            "fixed_rtol": settings.fixed_rtol,
            "fixed_atol": settings.fixed_atol,
        }


SOLVER = register(Fixed())
