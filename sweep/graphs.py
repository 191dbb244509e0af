"""Random graphs that satisfy Assumption 1 by construction, and follower lists of size N."""

from __future__ import annotations

import copy

import numpy as np

from core.graph import check_network


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
