"""Method ``native``: SUNDIALS CVODE (BDF) driven from C, one call from Python per run.

The engine is the per-agent one (:mod:`generated.agents`) for every N: a new graph
compiles nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from core.errors import IntegrationError
from generated import agents
from generated.solvers import register
from generated.solvers.base import BuildPlan, Solver

if TYPE_CHECKING:
    from core.scenario import Scenario
    from generated.built import Built
    from generated.largescale import JacobianPlan as Plan
    from generated.values import CodegenSettings, IntegratorSettings, Trajectory
    from symbolic.closed_loop import ClosedLoop
    from synthesis.gains import Gains


class Native(Solver):
    """CVODE from C: the per-agent engine (:mod:`generated.agents`)."""

    name = "native"
    form = "ode"
    summary = "BDF (SUNDIALS CVODE) driven from generated C"

    def prepare(self, sc: Scenario, gains: Gains) -> tuple[Scenario, Gains]:
        """The scenario and gains the kernels are compiled from.

        Parameters
        ----------
        sc : Scenario
        gains : Gains
        """
        return sc, gains

    def build(self, cl: ClosedLoop, settings: CodegenSettings, prepared: Any = None) -> BuildPlan:
        """The per-agent kernel libraries and problem (nothing of the closed loop is compiled).

        Parameters
        ----------
        cl : ClosedLoop
        settings : CodegenSettings
        prepared : (Scenario, Gains)
        """
        if prepared is None:
            raise IntegrationError(
                "method 'native' builds from the scenario: call "
                "generated.api.build(sc, gains, method='native')"
            )
        sc, gains = prepared
        libs, model = agents.build_models(sc, gains, settings)
        return BuildPlan(libraries=tuple(libs), data=agents.problem(sc, gains, model))

    def check_built(self, built: Built) -> None:
        """The build must hold the kernel libraries.

        Parameters
        ----------
        built : Built
        """
        super().check_built(built)
        if built.agents is None:
            raise IntegrationError(
                "method 'native' needs the native build: call build(..., method='native')"
            )

    def linear_algebra(self, N: int, plan: Plan) -> str:
        """The driver's Newton solves (the CasADi plan does not apply).

        Parameters
        ----------
        N : int
        plan : Plan
        """
        return (
            "native CVODE, per-agent engine: jets system by forward substitution "
            "(acyclic topology) or GMRES (cyclic)"
        )

    def run(
        self,
        built: Built,
        x0: np.ndarray,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float] = (),
        progress: Callable[[float], None] | None = None,
    ) -> Trajectory:
        """:func:`generated.agents.run` of the build's kernels and problem.

        Parameters
        ----------
        built, x0, t_out, settings, breakpoints, progress
            As :meth:`generated.solvers.Solver.run`.
        """
        libs, prob = built.agents
        paths = [lib.path for lib in libs]
        return agents.run(
            paths, prob, x0, t_out, settings, breakpoints=breakpoints, progress=progress
        )


SOLVER = register(Native())
