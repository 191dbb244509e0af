"""Random graphs that satisfy Assumption 1 by construction, and follower lists of size N."""

from __future__ import annotations

import copy
import re
from typing import Any

import numpy as np

from core.graph import check_network
from core.model import OPTIONAL_SECTIONS, SECTIONS
from core.settings import settings_of

#: the shapes of a section's settings that hold one entry per follower (core.settings)
PER_FOLLOWER_SHAPES = ("per_follower", "per_coordinate")
_FOLLOWER_KEY = re.compile(r"followers\[(\d+)\]\.(.+)")


def random_graph(
    N: int, edge_probability: float, weight: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A random directed graph containing a spanning tree rooted at the leader.

    The followers are visited in a random order; the first hears the leader (pinning
    a_i0 = weight) and each later one hears a uniformly chosen earlier one, which makes a
    directed spanning tree rooted at the leader. Every other ordered pair (i, j), i != j,
    then gets an extra edge a_ij = weight with probability ``edge_probability``.
    :func:`core.graph.check_network` confirms Assumption 1.

    Parameters
    ----------
    N : int
        Number of followers, >= 1.
    edge_probability : float
        Probability of each extra edge, in [0, 1].
    weight : float
        Weight of every edge and of the pinning, > 0.
    rng : numpy.random.Generator
        Source of randomness.

    Returns
    -------
    adjacency : ndarray
        N x N, ``adjacency[i, j] = a_ij`` (follower i hears follower j).
    pinning : ndarray
        N pinning gains; exactly one is non-zero.
    """
    order = rng.permutation(N)
    A = np.zeros((N, N))
    b = np.zeros(N)
    b[order[0]] = weight
    for k in range(1, N):
        A[order[k], order[rng.integers(k)]] = weight
    extra = rng.random((N, N)) < edge_probability
    np.fill_diagonal(extra, False)
    A[extra] = weight
    check_network(A, b)  # raises if the construction were wrong
    return A, b


def resize_followers(data: dict, N: int) -> None:
    """Make ``data["followers"]`` N long: the base's followers repeated cyclically, or cut.

    Parameters
    ----------
    data : dict
        A scenario table (changed in place).
    N : int
        Number of followers wanted.
    """
    base = data["followers"]
    data["followers"] = [copy.deepcopy(base[i % len(base)]) for i in range(N)]


def cyclic_keys(keys: dict[str, Any], base_n: int, N: int) -> dict[str, Any]:
    """``--set`` keys written for the base's ``base_n`` followers, made for N followers
    repeated cyclically as :func:`resize_followers` repeats them: follower i takes what
    follower ``i % base_n`` of the base was given.

    A per-follower setting (``controller.Lambda = [l1, ..., l_base_n]``) is repeated or cut
    to N entries; ``followers[k].x`` is given to every follower i with ``i % base_n = k - 1``
    (1-based k, dropped when no such follower exists); every other key is kept as it is.

    Parameters
    ----------
    keys : dict
        ``--set`` key -> value, for the base's followers.
    base_n : int
        The base scenario's number of followers.
    N : int
        Number of followers of the sample.
    """
    out: dict[str, Any] = {}
    for key, v in keys.items():
        m = _FOLLOWER_KEY.fullmatch(key)
        if m:
            k = int(m.group(1)) - 1
            for i in range(k, N, base_n):
                out[f"followers[{i + 1}].{m.group(2)}"] = copy.deepcopy(v)
            continue
        out[key] = copy.deepcopy(v)
        if _per_follower(key) and isinstance(v, list) and len(v) == base_n:
            out[key] = [copy.deepcopy(v[i % base_n]) for i in range(N)]
    return out


def _per_follower(key: str) -> bool:
    """``section.field`` names a setting with one entry per follower."""
    section, _, name = key.partition(".")
    cls = {**SECTIONS, **OPTIONAL_SECTIONS}.get(section)
    s = settings_of(cls).get(name) if cls is not None else None
    return s is not None and s.shape in PER_FOLLOWER_SHAPES
