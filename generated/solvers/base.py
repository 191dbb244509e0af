"""What every integration method provides: the :class:`Solver` interface and its :class:`BuildPlan`.

The pipeline (:mod:`generated.api`) calls only this interface (``prepare``, ``build``,
``run``), never comparing method names; docs/ARCHITECTURE.md has the recipe.
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
    """The libraries a method runs instead of the closed loop's compiled one (none: the
    loop is compiled; else nothing of it is) and the data its ``run`` needs."""

    libraries: tuple[Library, ...] = ()
    data: Any = None


class Solver(ABC):
    """One integration method."""

    name: ClassVar[str]  # the integration.method that selects it
    form: ClassVar[str] = "ode"  # or "dae" (semi-explicit, with algebraic states z)
    summary: ClassVar[str] = ""  # one line for listings and errors
    fixed_step: ClassVar[bool] = False  # only such a method may integrate sign = "exact"

    def prepare(self, sc: Scenario, gains: Gains) -> Any:
        """Checks and data (passed to :meth:`build`) before the closed loop is built.

        Parameters
        ----------
        sc : Scenario
        gains : Gains
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
        """Raise :class:`~core.errors.IntegrationError` if ``built`` is of another form.

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
        """Integrate ``built`` from ``x0`` at ``t_out[0]``; a failure gives an incomplete result.

        Parameters
        ----------
        built : Built
            Compiled for this method (:meth:`check_built` has passed).
        x0 : ndarray
        t_out : ndarray
            Increasing output times.
        settings : IntegratorSettings
        breakpoints : sequence of float
            Known discontinuity times: the run restarts there.
        progress : callable, optional
            Called with the simulated time reached.
        """

    def linear_algebra(self, N: int, plan: Plan) -> str:
        """How the method solves its Newton systems at N followers, for reports.

        Parameters
        ----------
        N : int
        plan : Plan
            The large-N plan (:func:`generated.largescale.choose_plan`).
        """
        return f"{plan.jacobian}: {plan.strategy} Newton ({plan.reason})"

    def settings_used(self, settings: IntegratorSettings) -> dict[str, Any]:
        """The method-specific settings a run record lists (default: none).

        Parameters
        ----------
        settings : IntegratorSettings
        """
        return {}
