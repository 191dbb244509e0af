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

    Attributes
    ----------
    closed_loop : symbolic.closed_loop.ClosedLoop
        Bound to the scenario (``x0``, ``p0``, breakpoints).
    library : Library
    dyn, outputs : casadi.Function
        The library's integrator-form right-hand side (ODE, or DAE for ``idas``) and
        ``(t, x) -> named outputs``, with p fixed.
    form : str
        ``"ode"`` or ``"dae"``.
    timings : dict
        ``symbolic_build``, ``codegen``, ``compile`` seconds.
    agents : (tuple of Library, AgentProblem) or None
        Method ``native``: the kernel libraries and the scenario's runtime data;
        :attr:`dyn` and :attr:`outputs` are then the symbolic closed loop's.
    p : ndarray
    dyn_p, outputs_p : casadi.Function or None
        The library's Functions with p as an input.
    """

    closed_loop: ClosedLoop
    library: Library
    dyn: ca.Function
    outputs: ca.Function
    form: str
    timings: dict[str, float] = field(default_factory=dict)
    agents: tuple[tuple[Library, ...], AgentProblem] | None = None
    p: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dyn_p: ca.Function | None = None
    outputs_p: ca.Function | None = None
