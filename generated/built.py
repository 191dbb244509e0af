"""A closed loop compiled for one method: what :func:`generated.api.build` returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

if TYPE_CHECKING:
    from generated.agents import AgentProblem
    from generated.codegen import Library
    from symbolic.closed_loop import ClosedLoop


@dataclass(frozen=True)
class Built:
    """A closed loop compiled for one method, bound to one scenario's runtime parameters p.

    ``dyn`` (the ODE, or the DAE for ``idas``, in integrator form) and ``outputs`` are the
    library's Functions with p fixed; for method ``native`` (``agents`` set: the kernel
    libraries and the scenario's runtime data) they are the symbolic closed loop's.
    """

    closed_loop: ClosedLoop  # bound to the scenario (x0, p0, breakpoints)
    library: Library
    dyn: ca.Function
    outputs: ca.Function  # (t, x) -> named outputs
    form: str  # "ode" or "dae"
    timings: dict[str, float] = field(default_factory=dict)  # symbolic_build, codegen, compile
    agents: tuple[tuple[Library, ...], AgentProblem] | None = None
    p: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dyn_p: ca.Function | None = None  # the library's Functions with p as an input
    outputs_p: ca.Function | None = None
