"""Shaping the operator's command before it reaches the leader (``leader.u0_rise``).

A human's command is piecewise: a key pressed, a stick pushed and released, written
``step(t - t_k)`` in a scenario. The followers' oracle feed-forward (η̈_i, and b̈_i
through η⃛_i) differentiates the leader's input twice along the observer flow, so a
jump in u0 reaches their torques as an impulse scaled by λ2/φ_i (docs/verification.md,
'Operator steps'). A ground station smooths the stick before it drives the vehicle;
here every ``step(x)`` of u0 becomes ``smoothstep(x / rise)``: the same change,
made continuously differentiable over ``rise`` seconds (for x = t − t_k). The shaped
command is a convex blend of the values it moves between, so ‖u0‖ ≤ α still holds
where it held for the steps (the loader checks it again on the shaped command).
"""

from __future__ import annotations

from core.expressions import Expr
from core.faults import node_text


def shaped_steps(e: Expr, rise: float) -> Expr:
    """``e`` with every ``step(x)`` replaced by ``smoothstep(x / rise)``.

    Parameters
    ----------
    e : Expr
        An expression of t (one component of u0).
    rise : float
        Rise time in seconds, > 0 (for a step whose argument has slope 1 in t).

    Returns
    -------
    Expr
        ``e`` itself when it holds no ``step``, else the shaped expression.
    """
    node = _shape(e.node, float(rise))
    return e if node == e.node else Expr(node_text(node), node)


def _shape(node: tuple, rise: float) -> tuple:
    kind = node[0]
    if kind in ("num", "t"):
        return node
    if kind == "neg":
        return ("neg", _shape(node[1], rise))
    if kind == "bin":
        return ("bin", node[1], _shape(node[2], rise), _shape(node[3], rise))
    args = tuple(_shape(a, rise) for a in node[2])
    if node[1] == "step":
        return ("call", "smoothstep", (("bin", "/", args[0], ("num", rise)),))
    return ("call", node[1], args)
