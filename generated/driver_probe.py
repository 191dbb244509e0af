"""One evaluation of a native driver outside a run: its right-hand side and a Newton solve.

The per-agent driver (:mod:`generated.agents`) exports a ``hitl_agents_probe`` entry
point; the
tests compare what it returns with the whole closed loop. :func:`probe_driver` is the
one place that calls such an entry point and turns its failure into an error.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable

import numpy as np

from core.errors import IntegrationError
from generated import native


def checked_state(x: np.ndarray, nx: int) -> np.ndarray:
    """``x`` as a contiguous float vector of the closed loop's ``nx`` states.

    Parameters
    ----------
    x : ndarray
        A state (or a right-hand side of the Newton system).
    nx : int
        States of the closed loop.

    Raises
    ------
    IntegrationError
        If ``x`` does not have ``nx`` entries.
    """
    x = np.ascontiguousarray(x, dtype=float).ravel()
    if x.size != nx:
        raise IntegrationError(f"x: {x.size} entries, the closed loop has {nx} states")
    return x


def probe_driver(
    entry: Callable[..., int],
    problem: ctypes.Structure,
    t: float,
    x: np.ndarray,
    gamma: float,
    b: np.ndarray,
    driver: str,
) -> tuple[np.ndarray, np.ndarray]:
    """The driver's right-hand side at (t, x) and its solution of (I − γJ) sol = b.

    Parameters
    ----------
    entry : callable
        The library's ``hitl_*_probe`` (argument types declared).
    problem : ctypes.Structure
        The driver's problem struct; the caller keeps the arrays it points into alive.
    t : float
    x, b : ndarray
        A state and a right-hand side, from :func:`checked_state`.
    gamma : float
        CVODE's γ.
    driver : str
        How the driver is named in the error message.

    Returns
    -------
    (xdot, sol) : (ndarray, ndarray)

    Raises
    ------
    IntegrationError
        If the driver failed (its own message).
    """
    xdot, sol = np.zeros_like(x), np.zeros_like(x)
    msg = ctypes.create_string_buffer(native.MSG_LEN)
    dp = native.dptr
    ret = entry(
        ctypes.byref(problem),
        float(t),
        dp(x),
        float(gamma),
        dp(b),
        dp(xdot),
        dp(sol),
        msg,
        native.MSG_LEN,
    )
    if ret != 0:
        raise IntegrationError(f"{driver}: {msg.value.decode(errors='replace') or 'solve failed'}")
    return xdot, sol
