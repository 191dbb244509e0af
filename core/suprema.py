"""Suprema of signals of t over a run's horizon, refined around their maxima (scipy).

A signal given by expressions is sampled on a time grid plus both sides of its known
breakpoints (so a step is not missed), and each sampled maximum is refined by a bounded
scalar search; results are remembered for equal expressions and grids (a study asks
again per sample).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from core.expressions import Expr
from core.memo import MEMO


def sample_times(e: Expr, tgrid: np.ndarray) -> np.ndarray:
    """``tgrid`` plus both sides of the known breakpoints of ``e`` (so a step is not missed);
    remembered for equal expressions and grids (read-only: a study asks again per sample).

    Parameters
    ----------
    e : Expr
    tgrid : ndarray
        The time grid.
    """
    return _times_of(e, np.ascontiguousarray(tgrid, dtype=float).tobytes())


@MEMO.memoize("signal-sample-times", 512)
def _times_of(e: Expr, tgrid_bytes: bytes) -> np.ndarray:
    tgrid = np.frombuffer(tgrid_bytes, dtype=float)
    H = tgrid[-1]
    extra = [x for b in e.breakpoints() if 0.0 <= b <= H for x in (b, b - 1e-9, b + 1e-9)]
    ts = np.concatenate([tgrid, np.array(extra, dtype=float)])
    out = np.unique(ts[(ts >= 0.0) & (ts <= H)])
    out.setflags(write=False)
    return out


def sample_signal(e: Expr, ts: np.ndarray) -> np.ndarray:
    """``e`` evaluated on the times ``ts`` as a float array of the same shape.

    Parameters
    ----------
    e : Expr
    ts : ndarray
        Sample times.
    """
    return np.array(np.broadcast_to(e.numpy(ts), ts.shape), dtype=float)


def signal_values(kind: str, exprs: tuple[Expr, ...], t: np.ndarray) -> np.ndarray:
    """``|e|``, ``-e`` or ``e`` of the one expression, or the Euclidean norm (``norm``) of all.

    Parameters
    ----------
    kind : str
        ``abs`` (the largest |component|) or ``norm`` (the Euclidean norm).
    exprs : tuple of Expr
    t : ndarray
        Times.
    """
    if kind == "norm":
        return np.sqrt(sum(sample_signal(e, t) ** 2 for e in exprs))
    v = sample_signal(exprs[0], t)
    return {"abs": np.abs, "neg": np.negative, "pos": np.positive}[kind](v)


def expression_sup(kind: str, exprs: tuple[Expr, ...], ts: np.ndarray) -> float:
    """:func:`_sup` of :func:`_signal` over ``ts``, remembered for equal expressions and times.

    A study's samples share most of their expressions (only the drawn ones change), and
    each supremum's refinement costs milliseconds; the value depends only on the
    expression trees and the times, so an equal key gives the identical number.
    Parameters
    ----------
    kind : str
        ``abs`` (the largest |component|) or ``norm`` (the Euclidean norm).
    exprs : tuple of Expr
    ts : ndarray
        Sample times.
    """
    return _expr_sup_of(kind, exprs, np.ascontiguousarray(ts, dtype=float).tobytes())


@MEMO.memoize("signal-suprema", 512)
def _expr_sup_of(kind: str, exprs: tuple[Expr, ...], ts_bytes: bytes) -> float:
    ts = np.frombuffer(ts_bytes, dtype=float)
    return signal_sup(lambda t: signal_values(kind, exprs, t), ts)


def signal_sup(fun: Callable[[np.ndarray], np.ndarray], ts: np.ndarray) -> float:
    """sup of ``fun`` over [ts[0], ts[-1]]: the sampled maximum, refined near its top peaks.

    Sampling alone under-estimates a supremum between grid points; a bound such
    as d_ir or alpha must not, so each near-maximal local peak is refined with a
    bounded scalar search. Returns nan when ``fun`` is not finite on ``ts``.
    Parameters
    ----------
    fun : callable
        ``t -> values``, vectorised.
    ts : ndarray
        Sample times.
    """
    with np.errstate(all="ignore"):
        return _sup_impl(fun, ts)


def _sup_impl(fun: Callable[[np.ndarray], np.ndarray], ts: np.ndarray) -> float:
    v = fun(ts)
    if not np.all(np.isfinite(v)):
        return math.nan
    top = float(v.max())
    if float(v.min()) == top:  # constant: nothing to refine
        return top
    # strict local peaks of the samples (one side may tie), the highest few
    left = np.concatenate([[-np.inf], v[:-1]])
    right = np.concatenate([v[1:], [-np.inf]])
    peaks = np.flatnonzero((v >= left) & (v >= right) & ((v > left) | (v > right)))
    tol = 1e-3 * max(1.0, abs(top))
    peaks = peaks[v[peaks] >= top - tol]
    for k in peaks[np.argsort(-v[peaks])][:5]:
        lo, hi = ts[max(k - 1, 0)], ts[min(k + 1, len(ts) - 1)]
        if hi > lo:
            res = minimize_scalar(
                lambda x: -float(fun(np.array([x]))[0]),
                bounds=(lo, hi),
                method="bounded",
                options={"xatol": 1e-12 * max(1.0, hi)},
            )
            if math.isfinite(res.fun):
                top = max(top, -float(res.fun))
    return top
