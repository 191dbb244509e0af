"""A sparse LU factorisation without pivoting, written out as straight-line generated code.

The per-agent kernels factorise each follower's block D = I + c A_ss on its fixed pattern,
eliminated once *symbolically*; the caller treats a tiny or non-finite pivot as a
recoverable failure of the set-up (CVODE then retries with a smaller step, where D → I).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca

from core.errors import BuildError


@dataclass(frozen=True)
class SparseLU:
    """Generated-code LU of one sparsity pattern.

    Attributes
    ----------
    pattern : casadi.Sparsity
        Pattern of the matrix M (square, full structural diagonal).
    factor : casadi.Function
        ``M -> (LU, pivots)``: the unit-lower L (below the diagonal) and U (on and
        above it) in one sparse matrix with the fill-in pattern, and U's diagonal.
    solve : casadi.Function
        ``(LU, b) -> x`` with ``M x = b``.
    fill : int
        Nonzeros of LU minus those of M.
    """

    pattern: ca.Sparsity
    factor: ca.Function
    solve: ca.Function
    fill: int


def sparse_lu(
    pattern: ca.Sparsity, prefix: str = "lu", *, cse: bool = True, reciprocal: bool = False
) -> SparseLU:
    """Symbolic Gaussian elimination (no pivoting) on ``pattern``, as two SX Functions.

    Parameters
    ----------
    pattern : casadi.Sparsity
        Square pattern that contains the whole diagonal.
    prefix : str
        The Functions are named ``<prefix>_factor`` and ``<prefix>_solve``.
    cse : bool
    reciprocal : bool
        Store 1 / u_kk on LU's diagonal: a solve, called many times per factorisation,
        has no division (the rounding differs from the default's).

    Raises
    ------
    BuildError
        If the pattern is not square or lacks a diagonal entry.
    """
    n = pattern.size1()
    if pattern.size2() != n:
        raise BuildError(f"sparse_lu: pattern is {n}x{pattern.size2()}, expected square")
    if (pattern + ca.Sparsity.diag(n)).nnz() != pattern.nnz():
        raise BuildError("sparse_lu: pattern lacks diagonal entries (add ca.Sparsity.diag(n))")
    M = ca.SX.sym("M", pattern)
    rows = _rows_by_index(M.nz, pattern, n)
    pivots = _eliminate(rows, n)
    ij = [(i, j) for i in range(n) for j in rows[i]]  # the eliminated rows' pattern
    lu_sp = ca.Sparsity.triplet(n, n, [i for i, _ in ij], [j for _, j in ij])
    lci, lrow = lu_sp.colind(), lu_sp.row()
    if reciprocal:
        for i in range(n):
            rows[i][i] = 1 / rows[i][i]
    values = [rows[lrow[k]][c] for c in range(n) for k in range(lci[c], lci[c + 1])]
    opts = {"cse": True} if cse else {}
    factor = ca.Function(
        f"{prefix}_factor",
        [M],
        [ca.SX(lu_sp, ca.vertcat(*values)), ca.vertcat(*pivots)],
        ["M"],
        ["LU", "pivots"],
        opts,
    )
    solve = _solve_function(f"{prefix}_solve", lu_sp, n, opts, reciprocal)
    return SparseLU(pattern, factor, solve, lu_sp.nnz() - pattern.nnz())


def _rows_by_index(nz: Any, pattern: ca.Sparsity, n: int) -> list[dict[int, ca.SX]]:
    """``rows[i][j]``: the nonzero (i, j) of a matrix on ``pattern`` (``nz``: its nonzeros)."""
    colind, row = pattern.colind(), pattern.row()
    rows: list[dict[int, ca.SX]] = [{} for _ in range(n)]
    for c in range(n):
        for k in range(colind[c], colind[c + 1]):
            rows[row[k]][c] = nz[k]
    return rows


def _eliminate(rows: list[dict[int, ca.SX]], n: int) -> list[ca.SX]:
    """Gaussian elimination without pivoting, in place: ``rows`` becomes L (below the
    diagonal, unit diagonal implied) and U (on and above it), with fill-in; the pivots."""
    below: list[list[int]] = [[] for _ in range(n)]  # below[k] = rows i > k with (i, k) set
    for i in range(n):
        for j in rows[i]:
            if j < i:
                below[j].append(i)
    pivots = []
    for k in range(n):
        p = rows[k][k]
        pivots.append(p)
        right = [(j, v) for j, v in rows[k].items() if j > k]
        for i in sorted(below[k]):
            lik = rows[i][k] / p
            rows[i][k] = lik
            for j, v in right:
                if j not in rows[i] and j < i:
                    below[j].append(i)  # fill-in below the diagonal, eliminated later
                rows[i][j] = rows[i].get(j, 0) - lik * v
    return pivots


def _solve_function(
    name: str, lu_sp: ca.Sparsity, n: int, opts: dict, reciprocal: bool = False
) -> ca.Function:
    """``(LU, b) -> x`` with ``M x = b``: forward (L, unit) then backward (U) substitution
    (``reciprocal``: U's diagonal stored inverted)."""
    LU = ca.SX.sym("LU", lu_sp)
    b = ca.SX.sym("b", n)
    lrows = _rows_by_index(LU.nz, lu_sp, n)
    y: list[ca.SX] = []
    for i in range(n):  # L y = b, L unit lower triangular
        s = b[i]
        for j, v in lrows[i].items():
            if j < i:
                s = s - v * y[j]
        y.append(s)
    x: list[ca.SX] = [ca.SX(0)] * n
    for i in reversed(range(n)):  # U x = y
        s = y[i]
        for j, v in lrows[i].items():
            if j > i:
                s = s - v * x[j]
        x[i] = s * lrows[i][i] if reciprocal else s / lrows[i][i]
    return ca.Function(name, [LU, b], [ca.vertcat(*x)], ["LU", "b"], ["x"], opts)
