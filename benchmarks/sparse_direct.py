"""A sparse direct solver for the cyclic Newton systems, projected beside GMRES.

The per-agent driver solves CVODE's Newton systems on a cyclic graph by GMRES on the
jets system ``dj_i − G_i Σ_j w_ij dj_j = r_i`` (generated/native/agents.c). The
alternative a sparse direct solver offers is one LU factorisation of that system per
linear-solver set-up and two triangular solves per Newton iteration. This module
measures both on the graph's own pattern with SuperLU (scipy's sequential build, the
algorithm of the SuperLU_MT that ships with SUNDIALS) and projects them onto a GMRES
run's counters: ``lin_setups × factor + newton_iters × solve``, the sparse direct
solver's linear algebra alone for the same steps.

What the projection assumes, each in the direct solver's favour: the jets system is
the smaller Schur complement of the whole Newton matrix (the agents' own states
eliminated for free); the step sequence is GMRES's (a direct solve is exact, GMRES
solves to a relative 1e-14); the values of the blocks G_i are random on their pattern,
block diagonally dominant so that SuperLU keeps its fill-reducing column order with
diagonal pivots (``diag_pivot_thresh = 0``): the fill, and so the work, is the
pattern's. SuperLU_MT on this machine's two cores is at most twice as fast (the
``two_cores`` column halves the projection).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

#: the spectral scale of the random blocks: Σ_j |w_ij| ‖G_i‖ ≤ DOMINANCE < 1 in every row
DOMINANCE = 0.5


def jets_matrix(
    ptr: np.ndarray, idx: np.ndarray, w: np.ndarray, n3: int, seed: int = 0
) -> sp.csc_matrix:
    """``I − blockdiag(G_i) (W ⊗ I)`` on a graph's CSR, with random blocks G_i.

    Parameters
    ----------
    ptr, idx, w : ndarray
        The graph's CSR without its diagonal: follower i hears ``idx[ptr[i]:ptr[i+1]]``
        with weights ``w`` (the off-diagonal (L + B)_ij).
    n3 : int
        Jets per agent (3n).
    seed : int
        Seed of the random blocks.

    Returns
    -------
    scipy.sparse.csc_matrix, shape (N n3, N n3)
    """
    N = len(ptr) - 1
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((N, n3, n3))
    row_w = np.array([np.abs(w[ptr[i] : ptr[i + 1]]).sum() for i in range(N)])
    norm = np.linalg.norm(G, 2, axis=(1, 2)) * np.maximum(row_w, 1e-300)
    G *= (DOMINANCE / norm)[:, None, None]
    agent = np.repeat(np.arange(N), np.diff(ptr))
    blocks = -w[:, None, None] * G[agent]  # block (i, j) of each edge
    r = (agent[:, None, None] * n3 + np.arange(n3)[None, :, None]).repeat(n3, axis=2)
    c = (idx[:, None, None] * n3 + np.arange(n3)[None, None, :]).repeat(n3, axis=1)
    A = sp.coo_matrix((blocks.ravel(), (r.ravel(), c.ravel())), shape=(N * n3, N * n3))
    return (A + sp.eye(N * n3)).tocsc()


@dataclass(frozen=True)
class DirectCost:
    """SuperLU on one jets system: seconds per factorisation and per solve, and its fill."""

    unknowns: int
    factor_s: float
    solve_s: float
    fill: int  # nonzeros of L + U

    def projected_s(self, lin_setups: int, newton_iters: int) -> float:
        """The linear algebra of a run with these counters (s).

        Parameters
        ----------
        lin_setups : int
            Linear-solver set-ups (one factorisation each).
        newton_iters : int
            Newton iterations (one solve each).
        """
        return lin_setups * self.factor_s + newton_iters * self.solve_s


def superlu_cost(A: sp.csc_matrix, repeats: int = 3) -> DirectCost:
    """The fastest of ``repeats`` factorisations (COLAMD order) and the mean of 20 solves.

    Parameters
    ----------
    A : scipy.sparse.csc_matrix
    repeats : int
    """
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        lu = splu(A, permc_spec="COLAMD", diag_pivot_thresh=0.0)
        times.append(time.perf_counter() - t0)
    b = np.ones(A.shape[0])
    t0 = time.perf_counter()
    for _ in range(20):
        lu.solve(b)
    return DirectCost(A.shape[0], min(times), (time.perf_counter() - t0) / 20, lu.L.nnz + lu.U.nnz)
