"""The driver's graph data (generated/agent_graph.py): orders and depths.

Independent truth: the definitions themselves, checked edge by edge on random digraphs
with and without cycles.
"""

from __future__ import annotations

import numpy as np
import pytest

from generated.agent_graph import topology


def _random_digraph(N: int, p: float, seed: int, acyclic: bool) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A = (rng.random((N, N)) < p).astype(float)
    np.fill_diagonal(A, 0.0)
    for i in range(1, N):  # a spanning tree: follower i hears an earlier one
        A[i, rng.integers(i)] = 1.0
    return np.tril(A) if acyclic else A


@pytest.mark.parametrize("acyclic", [True, False])
@pytest.mark.parametrize("seed", range(5))
def test_depths_hold_the_forward_substitutions_edges(acyclic, seed):
    N = 12
    A = _random_digraph(N, 0.25, seed, acyclic)
    pin = np.zeros(N)
    pin[0] = 1.0
    top = topology(0.0, A, pin, np.ones(N))
    assert top.acyclic == acyclic
    assert sorted(top.order) == list(range(N))
    # the order is grouped by depth, 0 first
    assert top.depth[top.order[0]] == 0 and np.all(np.diff(top.depth[top.order]) >= 0)
    pos = np.empty(N, int)
    pos[top.order] = np.arange(N)
    kept = dropped = 0
    for i in range(N):
        heard = [int(j) for j in np.flatnonzero(A[i])]
        lower = [top.depth[j] for j in heard if top.depth[j] < top.depth[i]]
        # a follower's depth is one more than the deepest heard follower it keeps
        assert top.depth[i] == (1 + max(lower) if lower else 0)
        for j in heard:
            if top.depth[j] < top.depth[i]:
                kept += 1
                assert pos[j] < pos[i]  # computed before i along the order
            else:
                dropped += 1
    assert kept + dropped == int((A != 0).sum())
    assert (dropped == 0) == acyclic  # only a cycle loses edges to the preconditioner
