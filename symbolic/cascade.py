"""The closed loop follower by follower: one block per follower, in graph order.

On an acyclic graph (every graph the paper and the benchmark use) follower i hears only
followers that come before it in a topological order, so the closed loop is a cascade of
per-follower blocks. The block of follower i is

    x_b = (η0, s_i)         the leader's state (evaluated in every block) and the agent
                            block s_i of :class:`symbolic.closed_loop.StateLayout`
    ẋ_b = (η̇0, ṡ_i)         eq. (3) and the agent's own equations, exactly as in the
                            whole closed loop (:func:`symbolic.closed_loop.agent_function`)

with the neighbourhood output of eq. (6) split into the follower's own term, the
leader's and the neighbours':

    ψ_i = l̄_ii C0 η_i − a_i0 h_i y0 + Σ_{j≠i} (L+B)_ij C0 η_j.

The last sum and, for the oracle derivatives (docs/fidelity.md, D9), its first two time derivatives
are the block's input ``nb`` (3n numbers); the block outputs the jets
``(C0 η_i, C0 η̇_i, C0 η̈_i)`` its listeners sum into their ``nb``. Evaluated in
the order, the blocks give the whole closed loop's right-hand side exactly
(tests/test_dag.py), and its Jacobian is block lower triangular: what the native
integrator above N = 20 uses (:mod:`generated.dag`).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from core.errors import ScenarioError
from core.scenario import Scenario
from symbolic.closed_loop import (
    StateLayout,
    agent_function,
    fault_function,
    make_layout,
    model_groups,
    observer_gains,
    saturated,
)
from symbolic.derivatives import flow_jets
from symbolic.leader import leader_function
from symbolic.network import graph_matrices
from symbolic.observer import ObserverGains, observer_function
from symbolic.parameters import param_layout, param_matrix
from synthesis.gains import Gains


@dataclass(frozen=True)
class Cascade:
    """The closed loop as a cascade of per-follower blocks.

    Attributes
    ----------
    block : casadi.Function
        ``(t, xb, nb, cpl, prm, gf) -> (xbdot, jets)``: ``xb`` = (η0, s_i), ``nb`` the
        neighbours' sum Σ_{j≠i} (L+B)_ij C0 η_j and its two time derivatives (3n),
        ``cpl`` = (l̄_ii, a_i0 h_i), ``prm`` the agent's numbers (a column of
        ``params``), ``gf`` = (g_i(t), f_i(t)); ``jets`` = (C0 η_i, C0 η̇_i, C0 η̈_i)
        (3n).
    faults : casadi.Function
        ``t -> values``: every distinct fault expression once.
    fault_index : ndarray
        N × (1+n) int: ``gf`` of agent i is ``values[fault_index[i]]``.
    params : ndarray
        npar × N, the agents' numbers.
    coupling : ndarray
        N × 2: (l̄_ii, a_i0 h_i).
    order : ndarray
        A topological order of the followers (each after every follower it hears).
    upstream_ptr, upstream_idx : ndarray
        CSR lists: follower i hears ``upstream_idx[upstream_ptr[i]:upstream_ptr[i+1]]``.
    upstream_weight : ndarray
        The weights (L+B)_ij of those lists.
    layout : StateLayout
        The whole closed loop's layout (where each block's states go).
    n : int
        Outputs per follower (C0 has n rows).
    """

    block: ca.Function
    faults: ca.Function
    fault_index: np.ndarray
    params: np.ndarray
    coupling: np.ndarray
    order: np.ndarray
    upstream_ptr: np.ndarray
    upstream_idx: np.ndarray
    upstream_weight: np.ndarray
    layout: StateLayout
    n: int

    @property
    def block_size(self) -> int:
        """States of one block: m + the agent block."""
        return self.layout.m + self.layout.agent_size


def topological_order(adjacency: np.ndarray, where: str = "scenario") -> np.ndarray:
    """A topological order of the followers (Kahn's algorithm).

    Parameters
    ----------
    adjacency : ndarray
        N×N, ``adjacency[i, j] != 0`` when follower i hears follower j.
    where : str
        The scenario file, for the error message.

    Returns
    -------
    ndarray
        Followers in an order where each comes after every follower it hears (ties by
        index).

    Raises
    ------
    ScenarioError
        If the followers' graph has a cycle (the cascade needs an acyclic graph).
    """
    A = np.asarray(adjacency) != 0
    N = A.shape[0]
    np.fill_diagonal(A, False)
    indeg = A.sum(axis=1)
    ready = sorted(int(i) for i in np.flatnonzero(indeg == 0))
    order: list[int] = []
    while ready:
        j = ready.pop(0)
        order.append(j)
        for i in np.flatnonzero(A[:, j]):
            indeg[i] -= 1
            if indeg[i] == 0:
                ready.append(int(i))
        ready.sort()
    if len(order) < N:
        cyc = sorted(set(range(N)) - set(order))
        raise ScenarioError(
            where,
            "graph.adjacency",
            f"followers {', '.join(str(i + 1) for i in cyc[:6])} are on a cycle",
            "an acyclic graph for method 'native' above N = 20 (or method 'cvodes')",
        )
    return np.asarray(order, dtype=np.int32)


def _one_model(sc: Scenario) -> int:
    """The follower whose model serves all: one generated block needs one model."""
    groups = model_groups(sc)
    if len(groups) > 1:
        raise ScenarioError(
            sc.path,
            "followers.model",
            f"{len(groups)} different models/parameter sets",
            "one model and parameter set for method 'native' above N = 20 (or method 'cvodes')",
        )
    return groups[0][0]


def agent_block(
    sc: Scenario, og: ObserverGains, lay: StateLayout, model_index: int | None = None
) -> ca.Function:
    """Follower i's block ``(t, xb, nb, cpl, prm, gf) -> (xbdot, jets)`` (module docstring).

    Parameters
    ----------
    sc : Scenario
    og : ObserverGains
    lay : StateLayout
    model_index : int, optional
        0-based follower whose model and parameters the block uses (the per-agent
        kernels of :mod:`generated.agents`, one per model); default: the one model of
        all followers (refused if they differ).
    """
    m, n = sc.m, sc.n
    filtered = sc.options.derivatives == "filtered"
    C0 = ca.DM(np.atleast_2d(sc.leader.C0))
    poff, npar = param_layout(n, saturated(sc))
    t = ca.SX.sym("t")
    xb = ca.SX.sym("xb", m + lay.agent_size)
    nb = ca.SX.sym("nb", 3 * n)
    cpl = ca.SX.sym("cpl", 2)
    prm = ca.SX.sym("prm", npar)
    gf = ca.SX.sym("gf", 1 + n)
    eta0, s = xb[:m], xb[m:]
    lii, a0h = cpl[0], cpl[1]
    eta0dot, _, y0, y0dot, y0ddot, _, _ = leader_function(sc.leader)(t, eta0)  # eq. (3)
    so = s[: 2 * m + 1]  # (μ_i, η_i, φ_i)
    eta = s[lay.agent_offsets["eta"]]
    # eq. (6), follower i's row of ψ = C0 E (L+B)ᵀ − y0 (a0 ∘ h)ᵀ
    psi = lii * ca.mtimes(C0, eta) + nb[:n] - a0h * y0
    if filtered:
        dpsi = ddpsi = ca.SX.zeros(n)
    else:  # the oracle's time derivatives of the same row (symbolic.closed_loop._network)
        obs = observer_function(og)
        D1, _ = flow_jets(obs)
        Pobs = prm[poff["obs"]]
        sod = obs(so, psi, Pobs)[0]
        dpsi = lii * ca.mtimes(C0, sod[m : 2 * m]) + nb[n : 2 * n] - a0h * y0dot
        sodd = D1(so, psi, Pobs, sod, dpsi)
        ddpsi = lii * ca.mtimes(C0, sodd[m : 2 * m]) + nb[2 * n :] - a0h * y0ddot
    agent = agent_function(sc, og, _one_model(sc) if model_index is None else model_index)
    res = dict(
        zip(agent.name_out(), agent(s, psi, dpsi, ddpsi, gf, ca.SX.zeros(n), prm), strict=True)
    )
    xbdot = ca.vertcat(eta0dot, res["sdot"])
    etaddot = ca.SX.zeros(m) if filtered else res["etaddot"]  # filtered: ψ alone is used
    jets = ca.vertcat(*(ca.mtimes(C0, v) for v in (eta, res["etadot"], etaddot)))
    return ca.Function(
        "cascade_block",
        [t, xb, nb, cpl, prm, gf],
        [xbdot, jets],
        ["t", "xb", "nb", "cpl", "prm", "gf"],
        ["xbdot", "jets"],
        {"cse": True},
    )


def _upstream(L_B: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row i's off-diagonal (L+B)_ij in CSR form: pointers, follower indices, weights."""
    ptr, idx, wts = [0], [], []
    for i in range(L_B.shape[0]):
        js = [j for j in np.flatnonzero(L_B[i]) if j != i]
        idx += js
        wts += [float(L_B[i, j]) for j in js]
        ptr.append(len(idx))
    return (
        np.asarray(ptr, dtype=np.int32),
        np.asarray(idx, dtype=np.int32),
        np.asarray(wts, dtype=float),
    )


def build_cascade(scenario: Scenario, gains: Gains) -> Cascade:
    """The per-follower block of ``scenario``'s closed loop and the data that strings them.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario with an acyclic graph and followers of one model.
    gains : Gains
        Synthesised gains.

    Returns
    -------
    Cascade

    Raises
    ------
    ScenarioError
        The graph has a cycle or switches, or the followers have different models or
        parameters (one generated block serves all followers; method 'native' above N = 20).
    """
    sc = scenario
    n, N = sc.n, sc.N
    _one_model(sc)
    if sc.graph.switches:  # the blocks are strung along the base graph only
        raise ScenarioError(
            sc.path,
            "graph.switches",
            "switch the graph, which the graph-ordered native build (above 20 followers) "
            "does not model",
            'integration.method = "cvodes" (the whole loop)',
        )
    order = topological_order(sc.graph.adjacency, sc.path)
    lay = make_layout(sc.m, n, N, sc.options.derivatives == "filtered")
    gm = graph_matrices(sc.graph, gains)  # h and L + B = H L̄ H from the gains
    block = agent_block(sc, observer_gains(sc, gains), lay)
    faults, fidx = fault_function(sc)
    ptr, idx, wts = _upstream(gm.L_B)
    return Cascade(
        block=block,
        faults=faults,
        fault_index=np.asarray(fidx, dtype=np.int32).reshape(N, 1 + n),
        params=param_matrix(sc),
        coupling=np.column_stack([np.diag(gm.L_B), gm.a0h]).astype(float),
        order=order,
        upstream_ptr=ptr,
        upstream_idx=idx,
        upstream_weight=wts,
        layout=lay,
        n=n,
    )
