"""What every integration method provides: the :class:`Solver` interface and its :class:`BuildPlan`.

A method is one :class:`Solver` subclass, registered by name
(:func:`generated.solvers.register`). The pipeline (:mod:`generated.api`) asks the
registry for the scenario's method and then only calls the interface: ``prepare``
before the closed loop is built, ``build`` for what goes into the compiled library,
``run`` for the trajectory. It never compares method names.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from core.errors import IntegrationError

if TYPE_CHECKING:
    import numpy as np

    from core.scenario import Scenario
    from generated.built import Built
    from generated.codegen import Library
    from generated.largescale import JacobianPlan as Plan
    from generated.values import CodegenSettings, IntegratorSettings, Trajectory
    from symbolic.closed_loop import ClosedLoop
    from synthesis.gains import Gains


@dataclass(frozen=True)
class BuildPlan:
    """The libraries a method runs instead of the closed loop's compiled one.

    Attributes
    ----------
    libraries : tuple of Library
        Empty: the closed loop's right-hand side (with its Jacobian) and outputs are
        compiled. Otherwise the method's own (the per-agent engine's kernels): nothing of
        the loop is compiled and its outputs are evaluated by CasADi's virtual machine.
    data : object
        Whatever ``run`` needs besides the libraries (the per-agent engine's problem).
    """

    libraries: tuple[Library, ...] = ()
    data: Any = None


class Solver(ABC):
    """One integration method.

    Attributes
    ----------
    name : str
        The ``integration.method`` (and ``IntegratorSettings.method``) that selects it.
    form : str
        ``"ode"`` (right-hand side ``(t, x) -> ẋ``) or ``"dae"`` (semi-explicit, with
        algebraic states z): the closed-loop form it integrates.
    summary : str
        One line for listings and errors.
    fixed_step : bool
        Whether it steps with a fixed step (only such a method may integrate the exact
        sign function, ``options.sign = "exact"``).
    """

    name: ClassVar[str]
    form: ClassVar[str] = "ode"
    summary: ClassVar[str] = ""
    fixed_step: ClassVar[bool] = False

    def prepare(self, sc: Scenario, gains: Gains) -> Any:
        """Checks and data needed before the closed loop is built (default: none).

        Parameters
        ----------
        sc : Scenario
        gains : Gains

        Returns
        -------
        object
            Passed to :meth:`build` as ``prepared``.
        """
        return None

    def build(self, cl: ClosedLoop, settings: CodegenSettings, prepared: Any = None) -> BuildPlan:
        """The method's own libraries, if it runs those instead of the closed loop's.

        Parameters
        ----------
        cl : ClosedLoop
        settings : CodegenSettings
            Resolved for the closed loop's N.
        prepared : object
            What :meth:`prepare` returned (None when the caller skipped it).
        """
        return BuildPlan()

    def check_built(self, built: Built) -> None:
        """Raise :class:`~core.errors.IntegrationError` if ``built`` was compiled for
        another method (default: the form must match).

        Parameters
        ----------
        built : Built
        """
        if built.form != self.form:
            raise IntegrationError(
                f"method {self.name!r} needs the {self.form.upper()} build "
                f"(this one is {built.form}): call build(..., method={self.name!r})"
            )

    @abstractmethod
    def run(
        self,
        built: Built,
        x0: np.ndarray,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float] = (),
        progress: Callable[[float], None] | None = None,
    ) -> Trajectory:
        """Integrate ``built`` from ``x0`` at ``t_out[0]`` through ``t_out``.

        Parameters
        ----------
        built : Built
            Compiled for this method (:meth:`check_built` has passed).
        x0 : ndarray
            Initial state.
        t_out : ndarray
            Increasing output times.
        settings : IntegratorSettings
        breakpoints : sequence of float
            Known discontinuity times: the run restarts there.
        progress : callable, optional
            Called with the simulated time reached.

        Returns
        -------
        Trajectory
            Incomplete (``status`` not ``OK``), not raised, on an integrator failure.
        """

    def linear_algebra(self, N: int, plan: Plan) -> str:
        """How the method solves its Newton systems at N followers, for reports.

        Parameters
        ----------
        N : int
            Number of followers.
        plan : Plan
            The large-N plan (:func:`generated.largescale.choose_plan`) the CasADi
            methods follow.
        """
        return f"{plan.jacobian}: {plan.strategy} Newton ({plan.reason})"

    def settings_used(self, settings: IntegratorSettings) -> dict[str, Any]:
        """The method-specific settings a run record lists (default: none).

        Parameters
        ----------
        settings : IntegratorSettings
        """
        return {}
