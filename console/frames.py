"""What the live loop hands out: the signals a page's frame draws, and the logged states.

:func:`page_signals` turns the compiled loop's outputs at the current time into the
frame's plotted numbers (leader, followers, formation slots, error norms, ĝ_i, |u_i|);
:func:`state_columns` and :func:`state_table` lay logged states out as the columns of
``trajectory.csv`` (the record replays against them).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from symbolic.layout import StateLayout

#: the state columns of trajectory.csv, per follower, in order (generated.trajectory_file)
AGENT_COLUMNS = (("p", "n"), ("q", "n"), ("eta", "m"), ("mu", "m"), ("phi", ""))
AGENT_COLUMNS += (("thetahat", "n"), ("ghat", ""))


def desired_formation(y0: np.ndarray, eta0dot: np.ndarray, b0: np.ndarray) -> np.ndarray:
    """The paper's formation slots y0 + R(τ0) b_i0, τ0 the heading of the leader's η̇0.

    R(τ) is the planar rotation; where η̇0 has no heading (its first two components are
    zero) or n ≠ 2, the slots are y0 + b_i0.

    Parameters
    ----------
    y0 : ndarray, shape (n,)
        The leader's output.
    eta0dot : ndarray, shape (m,)
        The leader's η̇0 (its first two components set τ0).
    b0 : ndarray, shape (N, n)
        The formation vectors b_i0.
    """
    b0 = np.asarray(b0, dtype=float)
    if b0.shape[1] != 2 or eta0dot.size < 2 or math.hypot(eta0dot[0], eta0dot[1]) == 0.0:
        return y0 + b0
    tau = math.atan2(eta0dot[1], eta0dot[0])
    c, s = math.cos(tau), math.sin(tau)
    R = np.array([[c, -s], [s, c]])
    return y0 + b0 @ R.T


def page_signals(
    outputs: dict[str, Any], x: np.ndarray, layout: StateLayout, N: int, u0_now: np.ndarray
) -> dict[str, Any]:
    """Leader output, followers, formation slots, error norms, ĝ_i and |u_i|.

    Parameters
    ----------
    outputs : dict
        The compiled outputs at the current time (``y0``, ``b``, ``et``, ``ebar``,
        ``ghat``, ``u``).
    x : ndarray
        The state (at the current time).
    layout : StateLayout
        The closed loop's state layout (``slices[("p", i)]``).
    N : int
        Followers.
    u0_now : ndarray
        The shaped command now.
    """
    o = {k: np.asarray(v, dtype=float) for k, v in outputs.items()}
    y0 = o["y0"].ravel()
    P = np.array([x[layout.slices[("p", i)]] for i in range(N)])
    b = o["b"].reshape(N, -1)  # the offsets the controllers track (blended)
    norm = lambda a: np.linalg.norm(a.reshape(N, -1), axis=1).tolist()  # noqa: E731
    return {
        "y0": y0.tolist(),
        "p": P.tolist(),
        "slots": (y0 + b).tolist(),
        "u0_now": u0_now.tolist(),
        "et": norm(o["et"]),
        "est": norm(o["ebar"]),
        "ghat": o["ghat"].ravel().tolist(),
        "unorm": norm(o["u"]),
    }


def state_columns(N: int, n: int, m: int) -> list[str]:
    """The state columns of trajectory.csv: η0, then :data:`AGENT_COLUMNS` per follower.

    Parameters
    ----------
    N : int
        Followers.
    n : int
        Output dimension.
    m : int
        Dimension of η.
    """
    size = {"m": m, "n": n, "": 1}
    cols = [f"eta0_{k}" for k in range(1, m + 1)]
    for i in range(1, N + 1):
        for name, dim in AGENT_COLUMNS:
            k = size[dim]
            cols += [f"{name}{i}"] if dim == "" else [f"{name}{i}_{r}" for r in range(1, k + 1)]
    return cols


def state_table(X: np.ndarray, layout: StateLayout, N: int) -> np.ndarray:
    """Logged states as :func:`state_columns`'s columns.

    Parameters
    ----------
    X : ndarray, shape (K, nx)
        States, one row per time.
    layout : StateLayout
        The closed loop's state layout.
    N : int
        Followers.
    """
    sl = layout.slices
    blocks = [X[:, sl["eta0"]]]
    for i in range(N):
        blocks += [X[:, sl[(name, i)]] for name, _ in AGENT_COLUMNS]
    return np.hstack(blocks)
