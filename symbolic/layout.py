"""The closed loop's state vector: ``x = (η0, s_1, …, s_N)`` and its names.

Agent block ``s_i = (μ_i, η_i, φ_i, p_i, q_i, θ̂_i, ĝ_i[, w_i, z_i])`` (``w``, ``z``: the
derivative filters of the ``filtered`` option). :class:`StateLayout` maps names to
slices and back; :func:`make_layout` builds it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from symbolic.derivatives import filter_sizes

AGENT_STATES = ("mu", "eta", "phi", "p", "q", "thetahat", "ghat", "w", "z")


@dataclass(frozen=True)
class StateLayout:
    """Maps state names to slices of the flat state vector x.

    ``slices["eta0"]`` is the leader's state; per agent i (0-based):
    ``slices[("mu", i)]``, ``("eta", i)``, ``("phi", i)``, ``("p", i)``, ``("q", i)``,
    ``("thetahat", i)``, ``("ghat", i)`` and, with filtered derivatives, the filter states
    ``("w", i)`` (2m: filtered η̇_i and its derivative) and ``("z", i)`` (3n: filtered b_i,
    ḃ_i, b̈_i).

    Attributes
    ----------
    slices : dict
        Name -> slice of x.
    nx : int
        Length of x.
    m, N : int
        Leader state size and number of agents.
    agent_offsets : dict
        Name -> slice inside one agent block (same for every agent).
    agent_size : int
        Length of one agent block.
    """

    slices: dict[Any, slice]
    nx: int
    m: int = 0
    N: int = 0
    agent_offsets: dict[str, slice] = field(default_factory=dict)
    agent_size: int = 0

    def get(self, x: np.ndarray, name: str, i: int | None = None) -> np.ndarray:
        """The part of ``x`` (1-D, or 2-D with time along axis 0) named ``name`` (agent ``i``).

        Parameters
        ----------
        x : ndarray
            State, 1-D (nx,) or 2-D (time, nx).
        name : str
            ``"eta0"`` or an agent-state name (``"mu"``, ``"eta"``, ``"phi"``, ``"p"``, ...).
        i : int, optional
            0-based agent; required for agent states, omitted for ``"eta0"``.
        """
        x = np.asarray(x)
        sl = self.slices[name] if i is None else self.slices[(name, i)]
        return x[..., sl]

    def unpack(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """``{"eta0": (m,), "mu": (N, m), "p": (N, n), ...}`` from a flat state ``x``.

        Parameters
        ----------
        x : ndarray
            Flat state of length nx.
        """
        x = np.asarray(x, dtype=float).reshape(-1)
        blocks = x[self.m :].reshape(self.N, self.agent_size)
        out = {"eta0": x[: self.m].copy()}
        for name, sl in self.agent_offsets.items():
            out[name] = blocks[:, sl].copy()
        return out

    def name_of(self, k: int) -> str:
        """The name of entry ``k`` of x as trajectory.csv spells it (1-based agents and parts).

        ``"eta0_2"``, ``"q10_1"`` (the first entry of follower 10's q), ``"phi3"``
        (a scalar state has no part index).

        Parameters
        ----------
        k : int
            0-based index into x.
        """
        if not 0 <= k < self.nx:
            raise IndexError(f"state index {k} outside 0..{self.nx - 1}")
        if k < self.m:
            return f"eta0_{k + 1}"
        i, r = divmod(k - self.m, self.agent_size)
        name, sl = next((n, s) for n, s in self.agent_offsets.items() if s.start <= r < s.stop)
        width = sl.stop - sl.start
        return f"{name}{i + 1}" if width == 1 else f"{name}{i + 1}_{r - sl.start + 1}"

    def pack(self, parts: dict[str, np.ndarray]) -> np.ndarray:
        """Inverse of :meth:`unpack`; every name of the layout must be present.

        Parameters
        ----------
        parts : dict
            ``"eta0"`` (m,) and one (N, size) array per agent-state name.
        """
        x = np.zeros(self.nx)
        x[: self.m] = np.asarray(parts["eta0"], dtype=float).reshape(-1)
        blocks = np.zeros((self.N, self.agent_size))
        for name, sl in self.agent_offsets.items():
            blocks[:, sl] = np.asarray(parts[name], dtype=float).reshape(self.N, -1)
        x[self.m :] = blocks.reshape(-1)
        return x


def _offsets(sizes: list[tuple[str, int]]) -> tuple[dict[str, slice], int]:
    """Consecutive slices for named blocks of the given sizes, and the total size."""
    off, k = {}, 0
    for name, s in sizes:
        off[name] = slice(k, k + s)
        k += s
    return off, k


def agent_offsets(m: int, n: int, filtered: bool) -> tuple[dict[str, slice], int]:
    """Slices of one agent block ``s_i`` by state name, and its size.

    Parameters
    ----------
    m, n : int
        Leader and follower coordinate counts.
    filtered : bool
        With the derivative filters' states ``w``, ``z``.
    """
    sizes = [("mu", m), ("eta", m), ("phi", 1), ("p", n), ("q", n), ("thetahat", n), ("ghat", 1)]
    if filtered:
        nw, nz = filter_sizes(m, n)
        sizes += [("w", nw), ("z", nz)]
    return _offsets(sizes)


def make_layout(m: int, n: int, N: int, filtered: bool) -> StateLayout:
    """The state layout for leader size m, n coordinates, N agents.

    Parameters
    ----------
    m : int
        Leader state size.
    n : int
        Coordinates per follower.
    N : int
        Number of followers.
    filtered : bool
        Add the derivative-filter states ``w`` and ``z`` to each agent block.
    """
    off, na = agent_offsets(m, n, filtered)
    slices: dict[Any, slice] = {"eta0": slice(0, m)}
    for i in range(N):
        base = m + i * na
        for name, sl in off.items():
            slices[(name, i)] = slice(base + sl.start, base + sl.stop)
    return StateLayout(slices=slices, nx=m + N * na, m=m, N=N, agent_offsets=off, agent_size=na)
