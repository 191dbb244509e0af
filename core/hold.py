"""A held trace whose jumps are shaped (``leader.u0_csv`` with ``u0_hold`` and ``u0_rise``).

A held trace (rows t_j, v_j; ``leader.u0_hold``) is the zero-order hold
v_0 + Σ_j (v_j − v_{j−1}) step(t − t_j). With ``leader.u0_rise = r > 0`` every one of
those steps becomes ``smoothstep((t − t_j) / r)``, exactly as ``leader.u0_rise`` shapes
the steps of a u0 expression (core/shaping.py):

    u0(t) = v_0 + Σ_j (v_j − v_{j−1}) S((t − t_j) / r),   S(x) = 3x² − 2x³ on [0, 1].

Since S((t − t_j)/r) does not increase with j at any t, Abel summation writes u0(t) as
Σ_j v_j (S_j − S_{j+1}) with S_0 = 1, S_{K+1} = 0: a convex combination of the rows, so
‖u0‖ never exceeds the largest row norm. The console records its shaped commands this
way (docs/console.md), and every row and every t_j + r is a breakpoint.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def jumps(ts: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times and sizes of the changes of a held column (rows that change nothing dropped).

    Parameters
    ----------
    ts : ndarray, shape (K,)
        Row times, increasing.
    vs : ndarray, shape (K,)
        Row values.
    """
    ts, vs = np.asarray(ts, dtype=float), np.asarray(vs, dtype=float)
    k = np.flatnonzero(vs[1:] != vs[:-1]) + 1
    return ts[k], vs[k] - vs[k - 1]


def shaped_hold(ts: np.ndarray, vs: np.ndarray, rise: float, t: Any) -> tuple[Any, Any]:
    """The shaped held trace and its time derivative at ``t`` (numpy).

    Parameters
    ----------
    ts, vs : ndarray, shape (K,)
        One column of a held trace.
    rise : float
        Rise time r > 0.
    t : float or ndarray
        Time(s).

    Returns
    -------
    (u, udot)
        Arrays of ``t``'s shape.
    """
    tj, dj = jumps(ts, vs)
    t = np.asarray(t, dtype=float)
    x = np.clip((t[..., None] - tj) / rise, 0.0, 1.0)
    u = float(np.asarray(vs, dtype=float)[0]) + (dj * x * x * (3.0 - 2.0 * x)).sum(axis=-1)
    ud = (dj * 6.0 * x * (1.0 - x) / rise).sum(axis=-1)
    return u, ud


def shaped_breakpoints(trace: np.ndarray, rise: float) -> list[float]:
    """Where a shaped held trace restarts the integrator: every row (a held trace's rows
    are its breakpoints), and the end t_j + r of every ramp (where its curvature jumps).

    Parameters
    ----------
    trace : ndarray, shape (K, 1 + p)
        The trace: times, then one column per input.
    rise : float
        Rise time r > 0.
    """
    tr = np.asarray(trace, dtype=float)
    ends = {float(t) + rise for k in range(1, tr.shape[1]) for t in jumps(tr[:, 0], tr[:, k])[0]}
    return [float(t) for t in tr[:, 0]] + sorted(ends)
