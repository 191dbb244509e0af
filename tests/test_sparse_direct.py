"""The sparse direct projection of benchmarks/sparse_direct.py.

Truth: the jets system's definition, block by block (identity on the diagonal, −w_ij G_i
on each edge, nothing elsewhere, one G_i per row) and the norm bound that makes it
nonsingular; the projection's arithmetic on hand-made counters.
"""

from __future__ import annotations

import numpy as np

from benchmarks.sparse_direct import DOMINANCE, DirectCost, jets_matrix, superlu_cost


def _graph():
    # 0 <- 1, 1 <- 2, 2 <- 0 (a cycle), 3 <- 0 and 3 <- 2, weights of a Laplacian
    ptr = np.array([0, 1, 2, 3, 5])
    idx = np.array([1, 2, 0, 0, 2])
    w = np.array([-1.0, -2.0, -0.5, -1.0, -3.0])
    return ptr, idx, w


def test_jets_matrix_is_identity_minus_one_block_per_row_on_the_edges():
    ptr, idx, w = _graph()
    n3, N = 6, 4
    A = jets_matrix(ptr, idx, w, n3, seed=3).toarray()
    blk = A.reshape(N, n3, N, n3).transpose(0, 2, 1, 3)  # blk[i, j] = block (i, j)
    for i in range(N):
        assert np.array_equal(blk[i, i], np.eye(n3))
        heard = idx[ptr[i] : ptr[i + 1]]
        for j in set(range(N)) - set(heard) - {i}:
            assert not blk[i, j].any()
        G = [-blk[i, j] / wq for j, wq in zip(heard, w[ptr[i] : ptr[i + 1]], strict=True)]
        for g in G[1:]:
            np.testing.assert_allclose(g, G[0], rtol=1e-14)
        bound = np.abs(w[ptr[i] : ptr[i + 1]]).sum() * np.linalg.norm(G[0], 2)
        assert abs(bound - DOMINANCE) < 1e-12
    assert np.linalg.matrix_rank(A) == N * n3


def test_superlu_cost_and_projection():
    ptr, idx, w = _graph()
    cost = superlu_cost(jets_matrix(ptr, idx, w, 6), repeats=1)
    assert cost.unknowns == 24 and cost.fill >= 24 and cost.factor_s > 0 and cost.solve_s > 0
    c = DirectCost(unknowns=1, factor_s=2.0, solve_s=0.5, fill=1)
    assert c.projected_s(lin_setups=3, newton_iters=10) == 3 * 2.0 + 10 * 0.5
