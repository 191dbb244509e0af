"""The follower network: graph matrices and agent-wise assembly.

The coupling between agents is linear (docs/reading.md, 'Network and signed graphs'): with the columns
``E = [η_1 … η_N]`` (m×N), the neighbourhood error is
``e_η = E L_Bᵀ − η0 (a0 ∘ h)ᵀ`` and its measured output is
``ψ = C0 E L_Bᵀ − y0 (a0 ∘ h)ᵀ``. Both are one sparse matrix product, so the
expression graph does not grow with N. Everything local to an agent is one
CasADi Function applied to all agents with ``Function.map`` (``assembly="map"``)
or, for comparison, called once per agent (``assembly="flat"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from core.errors import ScenarioError, SynthesisError
from core.graph import pinned_laplacian
from core.scenario import Graph
from synthesis.gains import Gains

ASSEMBLIES = ("map", "flat")


@dataclass(frozen=True)
class GraphMatrices:
    """Numerical graph data used by the closed loop.

    Attributes
    ----------
    A : ndarray
        N×N adjacency, ``A[i, j] = a_ij`` (signed allowed).
    a0 : ndarray
        N pinning gains ``a_i0``.
    h : ndarray
        N gauge signs ``h_i = ±1`` (all +1 on cooperative graphs).
    L_B : ndarray
        N×N, ``L + B`` with ``D = diag(Σ_j |a_ij|)``, ``L = D − A``.
    l_bar : ndarray
        N, the diagonal ``l̄_ii = Σ_j |a_ij| + a_i0`` of ``L̄ = H L_B H``.
    """

    A: np.ndarray
    a0: np.ndarray
    h: np.ndarray
    L_B: np.ndarray
    l_bar: np.ndarray

    @property
    def N(self) -> int:
        return self.A.shape[0]

    @property
    def a0h(self) -> np.ndarray:
        """``a_i0 h_i``: the weight of the leader's output in ψ_i."""
        return self.a0 * self.h

    def LBt_sparse(self) -> ca.DM:
        """``L_Bᵀ`` as a sparse CasADi matrix (structural zeros dropped)."""
        return _sparse(self.L_B.T)

    def a0h_sparse(self) -> ca.DM:
        """``(a0 ∘ h)ᵀ`` as a sparse 1×N CasADi row."""
        return _sparse(self.a0h.reshape(1, -1))


def _sparse(a: np.ndarray) -> ca.DM:
    cols, rows = np.nonzero(a.T)  # column-major order, as CasADi stores nonzeros
    sp = ca.Sparsity.triplet(a.shape[0], a.shape[1], rows.tolist(), cols.tolist())
    return ca.DM(sp, a[rows, cols].tolist() if rows.size else [])


def graph_matrices(graph: Graph, gains: Gains) -> GraphMatrices:
    """Build :class:`GraphMatrices` from a scenario graph and its certified gains.

    The gauge h and ``L + B = H L̄ H`` are read from the gains (synthesis found and
    certified them, Assumption 1); the adjacency and the pinning gains from the graph.

    Parameters
    ----------
    graph : Graph
        The scenario's graph.
    gains : Gains
        Gains synthesised for this graph (``gains.H``, ``gains.L_bar``).

    Raises
    ------
    ScenarioError
        If ``gains.H`` is not N signs ±1.
    SynthesisError
        If ``gains.L_bar`` is not H(L + B)H of this graph (gains made for another one).
    """
    A = np.asarray(graph.adjacency, dtype=float)
    a0 = np.asarray(graph.pinning, dtype=float)
    h = np.diag(np.atleast_2d(gains.H)).astype(float)
    if h.shape != a0.shape or not np.all(np.abs(h) == 1.0):
        raise ScenarioError("gains", "H", f"gauge has entries {h}", f"{len(a0)} signs +1/-1")
    L_bar = np.atleast_2d(np.asarray(gains.L_bar, dtype=float))
    # H = diag(±1) is its own inverse: L + B = H L̄ H exactly (+ 0.0 turns −0.0 into 0.0)
    L_B = h[:, None] * L_bar * h[None, :] + 0.0
    if L_B.shape != A.shape or not np.allclose(
        L_B, pinned_laplacian(A, a0).toarray(), rtol=1e-12, atol=0.0
    ):
        raise SynthesisError(
            "gains.L_bar is not H(L + B)H of the scenario's graph; re-run make synth"
        )
    return GraphMatrices(A=A, a0=a0, h=h, L_B=L_B, l_bar=np.diag(L_B).copy())


def coupling(
    C0: np.ndarray | None,
    X: Any,
    leader: Any,
    gm: GraphMatrices,
    weights: tuple[Any, Any] | None = None,
) -> Any:
    """``C0 X L_Bᵀ − leader (a0 ∘ h)ᵀ``: neighbourhood sums for all agents at once.

    With ``X = E`` (columns η_i) and ``leader = y0`` this is ψ (the measured
    neighbourhood output of eq. (6)); with ``C0 = None`` and ``leader = η0`` it
    is the (uncomputable) neighbourhood state error e_η.

    Parameters
    ----------
    C0 : ndarray or None
        n×m output matrix, or None for the state (no output map).
    X : casadi.SX or MX
        Agent columns, m×N (η_i).
    leader : casadi.SX or MX
        The leader's column, y0 (with ``C0``) or η0 (without).
    gm : GraphMatrices
        Graph matrices (L_B and a0 ∘ h).
    weights : (L_Bᵀ, (a0 ∘ h)ᵀ), optional
        The same matrices with symbolic nonzeros (runtime parameters); default the
        constants of ``gm``.
    """
    CX = X if C0 is None else ca.mtimes(ca.DM(C0), X)
    LBt, a0h = weights if weights is not None else (gm.LBt_sparse(), gm.a0h_sparse())
    return ca.mtimes(CX, LBt) - ca.mtimes(leader, a0h)


def apply_agents(fun: ca.Function, N: int, args: Sequence[Any], assembly: str) -> list[Any]:
    """Apply a per-agent Function to the columns of ``args`` for all N agents.

    Parameters
    ----------
    fun : casadi.Function
        Per-agent function; every input is a column vector.
    N : int
        Number of agents.
    args : sequence
        One matrix per input with N columns (column i belongs to agent i).
    assembly : {"map", "flat"}
        ``map``: one ``Function.map`` call (graph size independent of N);
        ``flat``: one call per agent, concatenated.

    Returns
    -------
    list
        One matrix per output, N columns.
    """
    if assembly == "map":
        res = fun.map(N)(*args)
        return [res] if fun.n_out() == 1 else list(res)
    if assembly != "flat":
        raise ScenarioError("options", "assembly", f"{assembly!r} is unknown", "'map' or 'flat'")
    cols = [fun(*[a[:, i] for a in args]) for i in range(N)]
    if fun.n_out() == 1:
        cols = [[c] for c in cols]
    return [ca.horzcat(*[c[k] for c in cols]) for k in range(fun.n_out())]
