"""The operator's numbers and the changes between them, each dated when it lands.

:class:`Settings` is one set of the numbers the operator sets (u0, each follower's
health g_i and added bias, the links' weights); the loop keeps two, what it integrates
with and what the operator asked for, and :func:`pending_changes` lists the
:class:`Change` records that take it from the first to the second.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


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
class Settings:
    """The operator's current numbers (what the parameter vector carries)."""

    u0: np.ndarray
    health: np.ndarray
    bias: np.ndarray  # N x n
    weights: dict[tuple[int, int], float] = field(default_factory=dict)  # (i, j) -> a_ij / a_i0

    def copy(self) -> Settings:
        """An independent copy."""
        return Settings(self.u0.copy(), self.health.copy(), self.bias.copy(), dict(self.weights))


def pending_changes(old: Settings, new: Settings, N: int, u0_room: bool, t: float) -> list[Change]:
    """The changes from ``old`` to ``new``, dated ``t``.

    Parameters
    ----------
    old : Settings
        What the loop integrates with.
    new : Settings
        What the operator asked for.
    N : int
        Followers.
    u0_room : bool
        Whether a ramp slot is free; a change of u0 waits (is not listed) until one is.
    t : float
        The time they are dated (when they land).
    """
    out = []
    if np.any(old.u0 != new.u0) and u0_room:
        out.append(Change(t, "u0", values=tuple(map(float, new.u0))))
    for i in range(N):
        if old.health[i] != new.health[i]:
            out.append(Change(t, "health", i, values=(float(new.health[i]),)))
        if np.any(old.bias[i] != new.bias[i]):
            out.append(Change(t, "bias", i, values=tuple(map(float, new.bias[i]))))
    for (i, j), w in sorted(new.weights.items()):
        if old.weights[(i, j)] != w:
            out.append(Change(t, "link", i, j, (float(w),)))
    return out
