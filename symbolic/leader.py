"""The human-in-the-loop leader, eq. (3): η̇0 = A0 η0 + B0 u0(t), y0 = C0 η0."""

from __future__ import annotations

import casadi as ca
import numpy as np

from core.hold import jumps
from core.scenario import Leader


def operator_input(leader: Leader, t: ca.SX, lits: ca.SX | None = None) -> ca.SX:
    """The operator's command u0(t) as a CasADi expression of ``t`` (p×1).

    From the scenario's expressions, or from its CSV trace through a linear
    ``ca.interpolant`` (``u0_hold``: piecewise constant, ``ca.pw_const``); outside the
    trace's time range the end values are held (t is clamped), so the command stays bounded.

    Parameters
    ----------
    leader : Leader
        The scenario's leader (u0 expressions or CSV trace).
    t : casadi.SX
        Time symbol.
    lits : casadi.SX, optional
        The expressions' literals, concatenated in input order (runtime parameters);
        default: the scenario's numbers, written into the expression.
    """
    if leader.u0 is not None:
        if lits is None:
            return ca.vertcat(
                *[ca.SX(e.casadi(t)) if e.is_constant() else e.casadi(t) for e in leader.u0]
            )
        out, k = [], 0
        for e in leader.u0:
            nl = len(e.literals())
            out.append(ca.SX(e.casadi(t, lits[k : k + nl])) if nl else ca.SX(e.casadi(t)))
            k += nl
        return ca.vertcat(*out)
    tr = np.asarray(leader.u0_trace)
    if leader.u0_hold and leader.u0_rise > 0:  # each jump a smoothstep ramp (core/hold.py)
        r = leader.u0_rise
        return ca.vertcat(*[_shaped(t, tr[:, 0], tr[:, k], r) for k in range(1, tr.shape[1])])
    if leader.u0_hold:  # zero-order hold, right-continuous; every row is a breakpoint
        return ca.vertcat(*[_held(t, tr[:, 0], tr[:, 1 + k]) for k in range(tr.shape[1] - 1)])
    tc = ca.fmin(ca.fmax(t, float(tr[0, 0])), float(tr[-1, 0]))
    # one interpolant per input: linear in t, the trace's own knots
    return ca.vertcat(
        *[
            ca.interpolant(f"u0_{k}", "linear", [tr[:, 0]], tr[:, 1 + k])(tc)
            for k in range(tr.shape[1] - 1)
        ]
    )


def _shaped(t: ca.SX, ts: np.ndarray, vs: np.ndarray, rise: float) -> ca.SX:
    """A held column whose jumps are smoothstep ramps over ``rise`` s: v_0 + Σ_j Δ_j S((t − t_j)/r)."""
    tj, dj = jumps(ts, vs)
    out = ca.SX(float(vs[0]))
    for c, d in zip(tj, dj, strict=True):
        x = ca.fmin(ca.fmax((t - float(c)) / rise, 0.0), 1.0)
        out = out + float(d) * (x * x * (3.0 - 2.0 * x))
    return out


def _held(t: ca.SX, ts: np.ndarray, vs: np.ndarray) -> ca.SX:
    """Zero-order hold of ``vs`` at times ``ts``; only rows that change the value enter."""
    jumps = np.flatnonzero(vs[1:] != vs[:-1]) + 1
    if jumps.size == 0:
        return ca.SX(float(vs[0]))
    return ca.pw_const(t, ca.DM(ts[jumps]), ca.DM(np.concatenate([vs[:1], vs[jumps]])))


def leader_function(leader: Leader, parametric: bool = False) -> ca.Function:
    """The leader as a Function of ``(t, eta0)``, or ``(t, eta0, c)`` when ``parametric``.

    Outputs ``eta0dot`` (eq. (3)), ``eta0ddot`` (= A0 η̇0 + B0 u̇0, needed by the
    oracle derivatives), ``y0``, ``y0dot``, ``y0ddot``, ``u0`` and ``u0dot``
    (u̇0 = ∂u0/∂t by AD; piecewise constant for a CSV trace).

    Parameters
    ----------
    leader : Leader
        The scenario's leader (A0, B0, C0 and u0).
    parametric : bool
        Take the literals of the u0 expressions as a third input ``c`` (runtime
        parameters, :mod:`symbolic.parameters`) instead of writing them into the code.
    """
    A0, B0, C0 = (ca.DM(leader.A0), ca.DM(leader.B0), ca.DM(leader.C0))
    t = ca.SX.sym("t")
    eta0 = ca.SX.sym("eta0", leader.m)
    nc = sum(len(e.literals()) for e in leader.u0) if leader.u0 is not None else 0
    c = ca.SX.sym("c", nc)
    u0 = operator_input(leader, t, c if parametric else None)
    u0dot = ca.jtimes(u0, t, ca.SX(1.0))
    eta0dot = A0 @ eta0 + B0 @ u0  # eq. (3)
    eta0ddot = A0 @ eta0dot + B0 @ u0dot
    ins, names = ([t, eta0, c], ["t", "eta0", "c"]) if parametric else ([t, eta0], ["t", "eta0"])
    return ca.Function(
        "leader",
        ins,
        [eta0dot, eta0ddot, C0 @ eta0, C0 @ eta0dot, C0 @ eta0ddot, u0, u0dot],
        names,
        ["eta0dot", "eta0ddot", "y0", "y0dot", "y0ddot", "u0", "u0dot"],
    )
