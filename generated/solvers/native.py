"""Method ``native``: SUNDIALS CVODE (BDF) driven from C, one call from Python per run.

The engine is the per-agent one (:mod:`generated.agents`, ``agents.c``) for every N: one
kernel library per follower model with the graph, N, the switching times, the links'
fade and the per-follower numbers as runtime data, so any graph (cyclic, signed,
switching, fading) and mixed models are carried and a new graph compiles nothing. The
closed loop's outputs of a run are evaluated from the symbolic closed loop by CasADi's
virtual machine (nothing compiled).

One exception, named: a caller that needs a library taking the runtime parameters p
(``generated.api.build(..., runtime_parameters=True)``: the console's ``LiveLoop``, which
changes u0, faults and weights between attempts) gets the whole closed loop as flat
generated code with its sparse LU (:mod:`generated.native`, ``driver.c``), up to
:data:`generated.native.MAX_AGENTS` followers. Both integrate the same ODE with the same
CVODE settings (tests/test_agents.py).
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


def per_agent(sc: Scenario, runtime_parameters: bool = False) -> bool:
    """Whether method ``native`` runs ``sc`` on the per-agent engine: always, unless the
    caller needs a library taking the runtime parameters p (the whole loop, ``driver.c``).

    Parameters
    ----------
    sc : Scenario
    runtime_parameters : bool
        ``generated.api.build``'s switch of the same name (the console).
    """
    return not runtime_parameters


class Native(Solver):
    """CVODE from C: the per-agent engine (the whole loop where runtime p is required)."""

    name = "native"
    form = "ode"
    integrates_dyn = False  # the C drivers' own entry points, not Built.dyn
    summary = "BDF (SUNDIALS CVODE) driven from generated C"

    def prepare(self, sc: Scenario, gains: Gains) -> Any:
        """What the per-agent kernels need.

        Parameters
        ----------
        sc : Scenario
        gains : Gains

        Returns
        -------
        PerAgent
            (``generated.api.build(..., runtime_parameters=True)`` does not call this:
            the whole-loop build.)
        """
        return PerAgent(sc, gains)

    def build(
        self, dyn: ca.Function, cl: ClosedLoop, settings: CodegenSettings, prepared: Any = None
    ) -> BuildPlan:
        """The kernel libraries (per-agent), or the driver's functions and SUNDIALS (whole
        loop: nothing ``prepared``, a caller that needs runtime p).

        CVODES' ``jac_`` is not generated: the drivers bring their own Jacobians.

        Parameters
        ----------
        dyn, cl, settings, prepared
            As :meth:`generated.solvers.Solver.build`.
        """
        if not isinstance(prepared, PerAgent):
            if cl.layout.N > native.MAX_AGENTS:
                raise IntegrationError(
                    f"integration.method 'native' with runtime parameters p (the whole loop) "
                    f"is for N <= {native.MAX_AGENTS}; above, the per-agent engine: call "
                    "build(sc, gains, method='native')"
                )
            functions = native.native_functions(dyn, cse=settings.cse)[0]  # whole loop, flat SX
            return BuildPlan(tuple(functions), derivatives=False, toolchain=native.toolchain())
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
