"""A closed loop compiled for one method: what :func:`generated.api.build` returns and
every method's :meth:`~generated.solvers.Solver.run` takes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

if TYPE_CHECKING:
    import ctypes

    from generated.agents import AgentProblem
    from generated.codegen import Library
    from symbolic.closed_loop import ClosedLoop


@dataclass(frozen=True)
class Built:
    """A closed loop compiled for one method, bound to one scenario's numbers.

    The library takes the closed loop's runtime parameters p as an input
    (:mod:`symbolic.parameters`); :attr:`dyn` and :attr:`outputs` are the library's
    Functions with :attr:`p` filled in; :func:`generated.api.build` binds the same library to every
    later scenario of the same structure.

    Attributes
    ----------
    closed_loop : symbolic.closed_loop.ClosedLoop
        Bound to the scenario (``x0``, ``p0``, breakpoints).
    library : Library
    dyn : casadi.Function
        The compiled integrator-form right-hand side (ODE, or DAE for ``idas``) with p
        fixed (its p input is empty).
    outputs : casadi.Function
        The compiled ``(t, x) -> named outputs`` with p fixed.
    form : str
        ``"ode"`` or ``"dae"``.
    timings : dict
        ``symbolic_build``, ``codegen``, ``compile`` seconds.
    agents : (tuple of Library, AgentProblem) or None
        Method ``native`` (unless built with ``runtime_parameters``): the
        per-agent kernel libraries (:mod:`generated.agents`) and the scenario's runtime
        data; :attr:`library` is then the first kernel library's record and :attr:`dyn`,
        :attr:`outputs` the symbolic closed loop's Functions (CasADi's virtual machine).
        None otherwise.
    p : ndarray
        The runtime parameters the library is called with.
    dyn_p, outputs_p : casadi.Function or None
        The library's Functions with p as an input.
    driver : ctypes.CDLL or None
        The native driver's entry points (:func:`generated.native.open_library`) of the
        loaded library; None if it has none.
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
    driver: ctypes.CDLL | None = None
