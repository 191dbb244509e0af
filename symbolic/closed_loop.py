"""The closed loop of the paper as one CasADi model (interface; implemented per issue 4).

Data flow: Scenario + Gains -> :func:`build_closed_loop` -> :class:`ClosedLoop`,
which the ``generated/`` stage turns into C and integrates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np


@dataclass(frozen=True)
class StateLayout:
    """Maps state names to slices of the flat state vector x.

    ``slices["eta0"]`` is the leader's state; per agent i (0-based):
    ``slices[("mu", i)]``, ``("eta", i)``, ``("phi", i)``, ``("p", i)``, ``("q", i)``,
    ``("thetahat", i)``, ``("ghat", i)`` and, with filtered derivatives, the filter states.
    """

    slices: dict[Any, slice]
    nx: int


@dataclass(frozen=True)
class ClosedLoop:
    """The symbolic closed loop.

    Attributes
    ----------
    layout : StateLayout
    ode : casadi.Function
        ``(t, x) -> xdot``.
    ode_dyn : casadi.Function
        The same in integrator form: inputs ``ca.dyn_in()`` = (t, x, z, p, u), outputs
        ``ca.dyn_out()`` = (ode, alg, quad, zero); z, p, u empty.
    dae_dyn : casadi.Function
        Semi-explicit DAE for IDAS, same inputs/outputs, with z = accelerations of all
        followers and alg = M(p)a + C(p,q)q + G(p) − g u − f.
    outputs : casadi.Function
        ``(t, x) -> named outputs`` (e_t, chi, u, b, ehat, ebar, V1, V2, ...).
    x0 : ndarray
    z0 : ndarray
        Consistent initial accelerations for the DAE.
    breakpoints : tuple of float
        Known discontinuity times in (0, horizon).
    """

    layout: StateLayout
    ode: ca.Function
    ode_dyn: ca.Function
    dae_dyn: ca.Function
    outputs: ca.Function
    x0: np.ndarray
    z0: np.ndarray
    breakpoints: tuple[float, ...]
