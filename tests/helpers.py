"""Helpers shared by the test modules: paths, the paper's closed loop integrated on a grid.

The closed loop is integrated with CVODES on the symbolic model (no generated C), so the
verification tests do not depend on the code they are not about. Import as
``from helpers import ...`` (pytest puts ``tests/`` on ``sys.path``).
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import pandas as pd
import pytest

from core.models import build_model
from core.scenario import Scenario

ROOT = Path(__file__).resolve().parents[1]
#: the project's packages, in layer order (the style and docstring checks cover each)
PACKAGES = (
    "core",
    "synthesis",
    "symbolic",
    "generated",
    "verify",
    "design",
    "benchmarks",
    "sweep",
    "console",
)
SCENARIOS = ROOT / "scenarios"
PAPER = SCENARIOS / "paper.toml"


@dataclass
class LoopRun:
    """A closed loop integrated on a grid: scenario, gains, closed loop, times and states.

    Attributes
    ----------
    sc : Scenario
    gains : synthesis.gains.Gains
    cl : symbolic.closed_loop.ClosedLoop
    t : ndarray
        Output times (the first is the initial time).
    X : ndarray
        States, one row per time.
    """

    sc: Scenario
    gains: object
    cl: object
    t: np.ndarray
    X: np.ndarray

    def frame(self) -> pd.DataFrame:
        """The run in the ``trajectory.csv`` format (the simulator's own writer)."""
        return trajectory_frame(self.sc, self.cl, self.t, self.X)


def paper_loop(overrides: dict | None, variant: str, out: Path) -> tuple[Scenario, object, object]:
    """The paper scenario with ``overrides``, its synthesised gains and its closed loop.

    Parameters
    ----------
    overrides : dict or None
        Scenario fields to override (``"section.key": value``).
    variant : str
        Name suffix of the run (keeps gains of different variants apart).
    out : Path
        Output root for the gains.
    """
    api = pytest.importorskip("generated.api")
    from symbolic.closed_loop import build_closed_loop

    sc = api.load(PAPER, overrides, variant=variant)
    gains, _ = api.ensure_gains(sc, out)
    return sc, gains, build_closed_loop(sc, gains)


def integrate(cl, grid: np.ndarray, options: dict) -> np.ndarray:  # noqa: ANN001 (ClosedLoop)
    """States of ``cl`` from its x0 at ``grid[0]`` on ``grid`` (CVODES with ``options``).

    Parameters
    ----------
    cl : symbolic.closed_loop.ClosedLoop
        The closed loop (its ``ode_dyn`` and ``x0``).
    grid : ndarray
        Output times, increasing; the first is the initial time.
    options : dict
        CasADi integrator options (tolerances, step limit).
    """
    F = ca.integrator("F", "cvodes", cl.ode_dyn.expand(), float(grid[0]), grid[1:], options)
    return np.vstack([np.asarray(cl.x0).reshape(1, -1), np.array(F(x0=cl.x0)["xf"]).T])


def simulate_paper(
    overrides: dict | None, variant: str, out: Path, grid: np.ndarray | None, options: dict
) -> LoopRun:
    """The paper's closed loop with ``overrides`` integrated on ``grid``.

    Parameters
    ----------
    overrides : dict or None
        Scenario fields to override.
    variant : str
        Name suffix of the run.
    out : Path
        Output root for the gains.
    grid : ndarray or None
        Output times (from 0); None: the scenario's output grid over its horizon.
    options : dict
        CasADi integrator options.
    """
    sc, gains, cl = paper_loop(overrides, variant, out)
    if grid is None:
        step = sc.integration.output_step
        grid = np.arange(0.0, sc.integration.horizon + step / 2, step)
    return LoopRun(sc, gains, cl, grid, integrate(cl, grid, options))


def trajectory_frame(sc: Scenario, cl, t: np.ndarray, X: np.ndarray) -> pd.DataFrame:  # noqa: ANN001
    """States ``X`` at times ``t`` as ``trajectory.csv`` columns (the simulator's writer).

    Parameters
    ----------
    sc : Scenario
    cl : symbolic.closed_loop.ClosedLoop
        The closed loop (its outputs fill the signal columns).
    t : ndarray
        Output times.
    X : ndarray
        States, one row per time.
    """
    from generated import api

    built = types.SimpleNamespace(outputs=cl.outputs, closed_loop=cl)
    return api.trajectory_frame(built, sc, types.SimpleNamespace(t=t, x=X))


def printed_law_ode(sc: Scenario, cl) -> ca.Function:  # noqa: ANN001 (ClosedLoop)
    """The closed loop with the printed adaptive law ĝ̇_i = −γ_i χ_iᵀ M(p_i) Ψ_i (section 9.4).

    Parameters
    ----------
    sc : Scenario
    cl : symbolic.closed_loop.ClosedLoop
        The closed loop whose ĝ rates are replaced.
    """
    t, x = ca.MX.sym("t"), ca.MX.sym("x", cl.layout.nx)
    xdot = cl.ode(t, x)
    outs = dict(zip(cl.outputs.name_out(), cl.outputs(t, x), strict=True))
    parts, pos = [], 0
    for i in range(sc.N):
        sl = cl.layout.slices[("ghat", i)]
        parts.append(xdot[pos : sl.start])
        fo = sc.followers[i]
        M = build_model(fo.model, fo.params).M(x[cl.layout.slices[("p", i)]])
        chi, Psi = outs["chi"][i, :].T, outs["Psi"][i, :].T
        parts.append(-float(sc.controller.gamma[i]) * ca.mtimes([chi.T, M, Psi]))
        pos = sl.stop
    parts.append(xdot[pos:])
    return ca.Function("ode_printed", [t, x], [ca.vertcat(*parts)])


#: a two-follower scenario with a fault at t = 0.3 s and a short horizon (tests of generated/)
SMALL = """
name = "small"
description = "two followers, short horizon (tests of generated/)"

[leader]
A0 = [[0.0, 1.0], [0.0, 0.0]]
B0 = [[0.0], [1.0]]
C0 = [[1.0, 1.0], [2.0, 2.0]]
eta0 = [0.0, 0.0]
u0 = ["2*cos(t)"]
alpha = 2.0

[graph]
adjacency = [[0.0, 0.0], [1.0, 0.0]]
pinning = [1.0, 1.0]

[[followers]]
model = "two_link"
p0 = [1.0, 0.5]
q0 = [0.0, 0.0]
b0 = [1.0, 0.0]
g = [[0.0, 1.0], [0.3, 0.8]]        # a fault at t = 0.3 s: a breakpoint
f = ["sin(2*t)", "cos(t)"]

[[followers]]
model = "two_link"
p0 = [0.5, 1.0]
q0 = [0.0, 0.0]
b0 = [0.0, 1.0]
g = 0.9
f = ["0.5*sin(t)", "0.5"]

[observer]
lambda1 = 1.9
lambda2 = 2.0
Q = [[35.4, 14.9]]
Theta = "synthesize"
alpha1 = 1.0
alpha1_bar = 1.0
phi0 = 1.0
phi_min = 1e-3
lambda_bar1 = 1.0
delta1 = 0.5
delta2 = 1.0
delta1_hat = 0.25
delta2_hat = 0.5

[controller]
Lambda = 10.0
k1 = 5.0
k2 = 1.0

[options]
sign = "tanh"
sign_width = 0.05
ghat_law = "projection"
tau_threshold = 0.5

[initial]
eta = [0.0, 0.0]
mu = [0.0, 0.0]
ghat = 1.1   # inside the projection interval [1, 2]: at its edge (1.0) IDAS fails at t = 0

[integration]
method = "cvodes"
rtol = 1e-8
atol = 1e-10
horizon = 0.5
output_step = 0.01
fixed_step = 1e-3
max_steps = 20000
"""

#: tolerances at which two integrators must agree to TIGHT_BOUND (the fixture's rtol 1e-8
#: leaves each its own error of the start-up transient, ~1e-5 in this norm)
TIGHT = {"rtol": 1e-10, "atol": 1e-13, "max_steps": 200000}
TIGHT_BOUND = 1e-6

#: the paper's two-link parameters (section 4)
TWO_LINK_PAPER = {"m1": 0.5, "m2": 1.5, "r1": 1.0, "r2": 0.8, "J1": 5.0, "J2": 5.0, "g0": 9.81}


def two_link_closed_form(p, q, m1, m2, r1, r2, J1, J2, g0):
    """Plain numpy transcription of docs/reading.md, 'Followers' (the paper's printed M, C, G)."""
    c2 = np.cos(p[1])
    m11 = (m1 + m2) * r1**2 + m2 * r2**2 + 2 * m2 * r1 * r2 * c2 + J1
    m12 = m2 * r2**2 + m2 * r1 * r2 * c2
    m22 = m2 * r2**2 + J2
    c = m2 * r1 * r2 * np.sin(p[1])
    M = np.array([[m11, m12], [m12, m22]])
    C = np.array([[-c * q[1], -c * (q[0] + q[1])], [c * q[0], 0.0]])
    G = np.array(
        [
            ((m1 + m2) * r1 * np.cos(p[0]) + m2 * r2 * np.cos(p[0] + p[1])) * g0,
            m2 * r2 * np.cos(p[0] + p[1]) * g0,
        ]
    )
    return M, C, G
