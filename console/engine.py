"""The closed loop stepped live: the operator's numbers change between integrator calls.

:class:`LoopBase` keeps what the operator set (u0, each follower's health g_i and
added bias, the cut links), the simulated clock and the record of every change
with its time. A change takes effect at the current simulated time, which is a
multiple of the quantum ``h``; the next integrator call starts there with the new
numbers (a breakpoint: the integrator restarts, it never steps across a change).
:class:`LiveLoop` integrates the compiled closed loop, whose numbers are a runtime
vector ``p`` (``symbolic.parameters``): u0 enters as the literals of
``leader.u0[k]``, g_i as the literal of ``followers[i].g``, the bias as the last
literal of ``followers[i].f[r]`` and a link as its weight in ``graph``. Nothing is
regenerated or recompiled while the console runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from console.protocol import Limits


@dataclass(frozen=True)
class Change:
    """One change the operator made, at simulated time ``t``.

    Attributes
    ----------
    t : float
        When it took effect (a multiple of the quantum).
    kind : str
        ``u0``, ``health``, ``bias`` or ``link``.
    follower : int or None
        0-based follower (``health``, ``bias``, ``link``).
    neighbour : int or None
        ``link``: 0-based neighbour, -1 for the leader.
    values : tuple of float
        ``u0``: the command; ``health``: (g,); ``bias``: the n components; ``link``:
        (weight,) after the change (0 for a cut).
    """

    t: float
    kind: str
    follower: int | None = None
    neighbour: int | None = None
    values: tuple[float, ...] = ()


@dataclass
class Advance:
    """What one integrator call produced.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Output times reached (possibly fewer than asked, on a failure).
    x : ndarray, shape (K, nx)
        States at those times.
    failure : str
        Empty when every time was reached, else the integrator's reason.
    steps : int
        Integrator steps taken.
    """

    t: np.ndarray
    x: np.ndarray
    failure: str = ""
    steps: int = 0


@dataclass
class Settings:
    """The operator's current numbers (what the parameter vector carries)."""

    u0: np.ndarray
    health: np.ndarray
    bias: np.ndarray  # N x n
    weights: dict[tuple[int, int], float] = field(default_factory=dict)  # (i, j) -> a_ij / a_i0

    def copy(self) -> Settings:
        """An independent copy."""
        return Settings(self.u0.copy(), self.health.copy(), self.bias.copy(), dict(self.weights))


class LoopBase:
    """Clock, operator settings and record of a live loop; subclasses integrate.

    Parameters
    ----------
    limits : Limits
        Sizes and ranges (:class:`console.protocol.Limits`).
    quantum : float
        Simulated seconds between logged states; every change lands on a multiple.
    nominal : Settings
        The settings at t = 0 (and after ``clear`` for a follower).
    x0 : ndarray
        The state at t = 0.
    """

    def __init__(self, limits: Limits, quantum: float, nominal: Settings, x0: np.ndarray) -> None:
        self.limits, self.quantum = limits, float(quantum)
        self.nominal, self.x0 = nominal, np.asarray(x0, dtype=float)
        self.reset()

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to t = 0 with the nominal settings; the record starts again."""
        self.k = 0  # quanta elapsed: t = k * quantum exactly
        self.x = self.x0.copy()
        self.settings = self.nominal.copy()
        self.changes: list[Change] = []
        self.failure = ""
        self.steps = 0

    @property
    def t(self) -> float:
        """Simulated time (s)."""
        return self.k * self.quantum

    # ---------------------------------------------------------------- changes
    def set_u0(self, values: tuple[float, ...]) -> None:
        """Hold the operator's command ``values`` from now on."""
        self.settings.u0 = np.array(values, dtype=float)
        self._record(Change(self.t, "u0", values=tuple(values)))

    def set_health(self, i: int, g: float) -> None:
        """Set follower i's actuator health g_i (0-based i)."""
        self.settings.health[i] = g
        self._record(Change(self.t, "health", i, values=(float(g),)))

    def set_bias(self, i: int, values: tuple[float, ...]) -> None:
        """Set the bias added to follower i's f_i (0-based i)."""
        self.settings.bias[i] = values
        self._record(Change(self.t, "bias", i, values=tuple(values)))

    def set_link(self, i: int, j: int, cut: bool) -> None:
        """Cut (weight 0) or restore the edge i <- j (j = -1: the leader's pinning)."""
        w = 0.0 if cut else self.nominal.weights[(i, j)]
        self.settings.weights[(i, j)] = w
        self._record(Change(self.t, "link", i, j, (w,)))

    def clear(self, i: int) -> None:
        """Remove every fault of follower i: nominal health, no bias, its links restored."""
        if self.settings.health[i] != self.nominal.health[i]:
            self.set_health(i, float(self.nominal.health[i]))
        if np.any(self.settings.bias[i] != self.nominal.bias[i]):
            self.set_bias(i, tuple(self.nominal.bias[i]))
        for ii, j in sorted(self.nominal.weights):
            if ii == i and self.settings.weights[(ii, j)] != self.nominal.weights[(ii, j)]:
                self.set_link(i, j, cut=False)

    def _record(self, ch: Change) -> None:
        """Log a change; a later change of the same thing at the same time replaces it."""
        same = [
            k
            for k, c in enumerate(self.changes)
            if (c.t, c.kind, c.follower, c.neighbour) == (ch.t, ch.kind, ch.follower, ch.neighbour)
        ]
        if same:
            del self.changes[same[0]]
        self.changes.append(ch)
        self.parameters_changed()

    def parameters_changed(self) -> None:
        """Hook: the settings changed (subclasses rebuild their parameter vector)."""

    # ---------------------------------------------------------------- time
    def advance(self, quanta: int) -> Advance:
        """Integrate ``quanta`` quanta from the current time with the current settings.

        Parameters
        ----------
        quanta : int
            Number of quanta (>= 1); the states at each are returned.

        Returns
        -------
        Advance
            On a failure the clock stops at the last time reached and ``failure`` says
            why; further calls return nothing until :meth:`reset`.
        """
        if self.failure or quanta < 1:
            return Advance(np.empty(0), np.empty((0, self.x.size)), self.failure)
        ks = self.k + np.arange(0, quanta + 1)
        t_out = ks * self.quantum
        res = self.integrate(self.x, t_out)
        reached = len(res.t)  # includes t_out[0]
        if reached > 1:
            self.k = int(ks[reached - 1])
            self.x = np.asarray(res.x[-1], dtype=float).copy()
        self.steps += res.steps
        if res.failure:
            self.failure = res.failure
        return Advance(res.t[1:], res.x[1:], res.failure, res.steps)

    def integrate(self, x0: np.ndarray, t_out: np.ndarray) -> Advance:
        """States at ``t_out`` (``t_out[0]`` is now, ``x0`` the state there); subclasses."""
        raise NotImplementedError

    def signals(self, x: np.ndarray) -> dict[str, Any]:
        """What the page draws at state ``x`` and the current time; subclasses."""
        raise NotImplementedError


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
