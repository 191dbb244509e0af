"""Method ``native``: SUNDIALS CVODE (BDF) driven from C, one call from Python per run.

Two engines behind one method. Up to :data:`generated.native.MAX_AGENTS` followers the
whole closed loop is flat generated code with its sparse LU (:mod:`generated.native`,
``driver.c``); above, the per-agent engine (:mod:`generated.agents`, ``agents.c``) runs
one kernel library per follower model with the graph, N and the per-follower numbers as
runtime data, so any graph (cyclic, signed, switching) and mixed models are carried and
a new graph compiles nothing. Both integrate the same ODE with the same CVODE settings
(tests/test_agents.py); the size decides the engine, as the large-N plan decides the
CasADi methods' linear algebra. The closed loop's outputs of a per-agent run are
evaluated from the symbolic closed loop by CasADi's virtual machine (nothing compiled).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from core.errors import IntegrationError
from generated import agents, native
from generated.solvers import register
from generated.solvers.base import BuildPlan, Solver

if TYPE_CHECKING:
    import casadi as ca

    from core.scenario import Scenario
    from generated.built import Built
    from generated.largescale import JacobianPlan as Plan
    from generated.values import CodegenSettings, IntegratorSettings, Trajectory
    from symbolic.closed_loop import ClosedLoop
    from synthesis.gains import Gains


@dataclass(frozen=True)
class PerAgent:
    """The scenario and gains a per-agent build compiles its kernels from (:meth:`Native.prepare`)."""

    scenario: Scenario
    gains: Gains


def per_agent(sc: Scenario) -> bool:
    """Whether method ``native`` runs ``sc`` on the per-agent engine (above the flat build's size).

    Parameters
    ----------
    sc : Scenario
    """
    return sc.N > native.MAX_AGENTS


class Native(Solver):
    """CVODE from C: the whole loop (N <= 20) or the per-agent engine (above)."""

    name = "native"
    form = "ode"
    integrates_dyn = False  # the C drivers' own entry points, not Built.dyn
    summary = "BDF (SUNDIALS CVODE) driven from generated C"

    def prepare(self, sc: Scenario, gains: Gains) -> Any:
        """Above :data:`generated.native.MAX_AGENTS`: what the per-agent kernels need.

        Parameters
        ----------
        sc : Scenario
        gains : Gains

        Returns
        -------
        PerAgent or None
            None for the whole-loop build.
        """
        return PerAgent(sc, gains) if per_agent(sc) else None

    def build(
        self, dyn: ca.Function, cl: ClosedLoop, settings: CodegenSettings, prepared: Any = None
    ) -> BuildPlan:
        """The driver's functions and SUNDIALS (whole loop), or the kernel libraries (above).

        CVODES' ``jac_`` is not generated: the drivers bring their own Jacobians.

        Parameters
        ----------
        dyn, cl, settings, prepared
            As :meth:`generated.solvers.Solver.build`.
        """
        if cl.layout.N <= native.MAX_AGENTS:  # whole loop, flat SX
            functions = native.native_functions(dyn, cse=settings.cse)[0]
            return BuildPlan(tuple(functions), derivatives=False, toolchain=native.toolchain())
        if not isinstance(prepared, PerAgent):
            raise IntegrationError(
                f"integration.method 'native' above N = {native.MAX_AGENTS} runs the per-agent "
                "engine: call build(sc, gains, method='native')"
            )
        sc, gains = prepared.scenario, prepared.gains
        libs, model = agents.build_models(sc, gains, settings)
        prob = agents.problem(sc, gains, model)
        return BuildPlan(derivatives=False, whole_loop=False, libraries=tuple(libs), data=prob)

    def check_built(self, built: Built) -> None:
        """The build must hold the native driver (whole loop) or the kernel libraries.

        Parameters
        ----------
        built : Built
        """
        super().check_built(built)
        if built.agents is None and native.RHS_NAME not in built.library.names:
            raise IntegrationError(
                "method 'native' needs the native build: call build(..., method='native')"
            )

    def linear_algebra(self, N: int, plan: Plan) -> str:
        """The driver's Newton solves at N followers (the CasADi plan does not apply).

        Parameters
        ----------
        N : int
        plan : Plan
        """
        if N <= native.MAX_AGENTS:
            return "native CVODE: generated J (reused by CVODE) and sparse LU without pivoting"
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
        """:func:`generated.agents.run` or :func:`generated.native.run`.

        Parameters
        ----------
        built, x0, t_out, settings, breakpoints, progress
            As :meth:`generated.solvers.Solver.run`.
        """
        if built.agents is not None:
            libs, prob = built.agents
            paths = [lib.path for lib in libs]
            return agents.run(
                paths, prob, x0, t_out, settings, breakpoints=breakpoints, progress=progress
            )
        return native.run(
            built.library.path,
            x0,
            t_out,
            settings,
            breakpoints=breakpoints,
            progress=progress,
            p=built.p,
            driver=built.driver,
        )


SOLVER = register(Native())
