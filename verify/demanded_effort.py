"""The effort a follower's slot demands: eq. (2) solved for u along the slot (``info`` rows).

A follower that sits exactly on its slot s_i(t) (:func:`verify.operator_steps.slots`: the
formation position the controller steers it to) has p_i = s_i, ṗ_i = ṡ_i, p̈_i = s̈_i, and
eq. (2), M p̈ + C(p, ṗ) ṗ + G + D = g u + f, leaves it one torque:

    u_i*(t) = (M(s_i) s̈_i + C(s_i, ṡ_i) ṡ_i + G(s_i) + D(s_i, ṡ_i) − f_i(t)) / g_i(t).

Its peak after the start-up is what the operator's command asks of the actuators, whatever
the controller: a peak |u_i| close to it is the motion's, not the controller's. ṡ_i and
s̈_i are differences of the slot on the output grid, second order (central inside,
one-sided at the ends); a measurement, not a bound: the theory promises no effort.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from core.memo import MEMO
from core.models import build_model
from core.scenario import Scenario
from verify import claims as CL
from verify import signals as S
from verify.checks import CheckInput, register_check
from verify.effort import STARTUP
from verify.operator_steps import slots
from verify.rows import Rows
from verify.theorem2_rows import gauge

DEMANDED_LATE = CL.register(
    "effort.demanded_late",
    "peak |u_i*| after t = {startup:g} s, eq. (2) solved for u along the slot",
    CL.Kind.INFO,
)


@MEMO.memoize("inverse-dynamics", 16)
def inverse_dynamics(model: str, params: tuple[tuple[str, float], ...]) -> ca.Function:
    """``(p, q, a) -> M(p) a + C(p, q) q + G(p) + D(p, q)`` of one follower model (CasADi).

    Parameters
    ----------
    model : str
        Registered model name.
    params : tuple of (str, float)
        Its parameters, sorted.
    """
    m = build_model(model, dict(params))
    p, q, a = (ca.SX.sym(x, m.n) for x in "pqa")
    tau = m.M(p) @ a + m.C(p, q) @ q + m.forces(p, q)
    return ca.Function("inverse_dynamics", [p, q, a], [tau])


def demanded_effort(scenario: Scenario, df: S.FrameOrView, h: np.ndarray) -> np.ndarray:
    """‖u_i*(t)‖ per output time and follower, (K, N) (module docstring).

    Parameters
    ----------
    scenario : Scenario
    df : DataFrame, Columns or TrajectoryView
        The trajectory (``t`` and the leader's ``eta0_k``).
    h : ndarray
        The gauge.
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    s = slots(scenario, view, h)  # (K, N, n)
    sd = np.gradient(s, t, axis=0, edge_order=2)
    sdd = np.gradient(sd, t, axis=0, edge_order=2)
    out = np.empty(s.shape[:2])
    for i, fo in enumerate(scenario.followers):
        fn = inverse_dynamics(fo.model, tuple(sorted(fo.params.items()))).map(len(t))
        tau = np.asarray(fn(s[:, i].T, sd[:, i].T, sdd[:, i].T)).T  # (K, n)
        f = np.stack([np.broadcast_to(e.numpy(t), t.shape) for e in fo.f], 1)
        g = np.broadcast_to(fo.g.expr.numpy(t), t.shape)
        out[:, i] = np.linalg.norm((tau - f) / g[:, None], axis=1)
    return out


@register_check
def demanded_effort_check(R: Rows, inp: CheckInput) -> None:
    """Peak ‖u_i*‖ after :data:`verify.effort.STARTUP` per follower (info rows).

    Parameters
    ----------
    R : Rows
        Rows to append to.
    inp : CheckInput
        The table's inputs; a trajectory shorter than three samples or ending before the
        start-up gives no rows.
    """
    t = inp.view.t
    late = t >= STARTUP
    if len(t) < 3 or not late.any():
        return
    un = demanded_effort(inp.scenario, inp.view, gauge(inp.scenario, inp.gains))
    for i in range(inp.scenario.N):
        k = int(np.flatnonzero(late)[np.argmax(un[late, i])])
        R.add(
            DEMANDED_LATE,
            CL.Kind.INFO,
            math.inf,  # a measurement: no bound
            float(un[k, i]),
            (float(t[late][0]), float(t[-1])),
            f"at t = {t[k]:.4g} s; slot derivatives by central differences on the output grid",
            agent=i,
            holds=True,
            text={"startup": STARTUP},
        )
