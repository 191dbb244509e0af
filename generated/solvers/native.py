"""Method ``native``: SUNDIALS CVODE (BDF) driven from C, one call from Python per run.

Two drivers behind one method. Up to :data:`generated.native.MAX_AGENTS` followers the
whole closed loop is flat generated code with its sparse LU (:mod:`generated.native`);
above, one follower's block is evaluated along the acyclic graph and the Newton systems
are solved by block forward substitution (:mod:`generated.dag`). Both integrate the
same ODE with the same CVODE settings and agree to rounding (tests/test_dag.py), so the
size decides the driver as the large-N plan decides the linear algebra: a scenario
names what is computed, not how the library is laid out, and a shipped scenario keeps
its method at any N.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from core.errors import BuildError, IntegrationError
from generated import dag, native
from generated.solvers import register
from generated.solvers.base import BuildPlan, Solver
from symbolic.cascade import build_cascade

if TYPE_CHECKING:
    import casadi as ca

    from core.scenario import Scenario
    from generated.built import Built
    from generated.largescale import JacobianPlan as Plan
    from generated.values import CodegenSettings, IntegratorSettings, Trajectory
    from symbolic.closed_loop import ClosedLoop
    from synthesis.gains import Gains


class Native(Solver):
    """CVODE from C: the whole loop (N <= 20) or the graph-ordered blocks (above)."""

    name = "native"
    form = "ode"
    integrates_dyn = False  # the C drivers' own entry points, not Built.dyn
    summary = "BDF (SUNDIALS CVODE) driven from generated C"

    def prepare(self, sc: Scenario, gains: Gains) -> Any:
        """The per-follower blocks above :data:`generated.native.MAX_AGENTS` (None below).

        Parameters
        ----------
        sc : Scenario
        gains : Gains

        Raises
        ------
        ScenarioError
            Above the limit, if the graph has a cycle or the followers differ in model.
        """
        if sc.N <= native.MAX_AGENTS:
            return None
        return build_cascade(sc, gains)

    def build(
        self, dyn: ca.Function, cl: ClosedLoop, settings: CodegenSettings, prepared: Any = None
    ) -> BuildPlan:
        """The driver's functions and SUNDIALS (whole loop), or the block library (above).

        CVODES' ``jac_`` is not generated: the drivers bring their own Jacobians.

        Parameters
        ----------
        dyn, cl, settings, prepared
            As :meth:`generated.solvers.Solver.build`.
        """
        if cl.layout.N <= native.MAX_AGENTS:  # whole loop, flat SX
            functions = native.native_functions(dyn, cse=settings.cse)[0]
            return BuildPlan(tuple(functions), derivatives=False, toolchain=native.toolchain())
        if prepared is None:
            raise BuildError(
                f"integration.method 'native' above N = {native.MAX_AGENTS} needs the "
                "per-follower blocks: call build(sc, gains, method='native') or pass "
                "cascade=native_cascade(sc, gains)"
            )
        return BuildPlan(derivatives=False, companion=dag.build(prepared, settings), data=prepared)

    def check_built(self, built: Built) -> None:
        """The build must hold the native driver (whole loop) or the block library.

        Parameters
        ----------
        built : Built
        """
        super().check_built(built)
        if built.dag is None and native.RHS_NAME not in built.library.names:
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
        return "native CVODE, graph-ordered blocks: block forward substitution"

    def run(
        self,
        built: Built,
        x0: np.ndarray,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float] = (),
        progress: Callable[[float], None] | None = None,
    ) -> Trajectory:
        """:func:`generated.dag.run` or :func:`generated.native.run`.

        Parameters
        ----------
        built, x0, t_out, settings, breakpoints, progress
            As :meth:`generated.solvers.Solver.run`.
        """
        if built.dag is not None:
            lib, cascade = built.dag
            return dag.run(
                lib.path, cascade, x0, t_out, settings, breakpoints=breakpoints, progress=progress
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
