"""The closed loop follower by follower: one follower's block, whatever the graph.

The block of follower i is

    x_b = (η0, s_i)         the leader's state (evaluated in every block) and the agent
                            block s_i of :class:`symbolic.closed_loop.StateLayout`
    ẋ_b = (η̇0, ṡ_i)         eq. (3) and the agent's own equations, exactly as in the
                            whole closed loop (:func:`symbolic.closed_loop.agent_function`)

with the neighbourhood output of eq. (6) split into the follower's own term, the
leader's and the neighbours':

    ψ_i = l̄_ii C0 η_i − a_i0 h_i y0 + Σ_{j≠i} (L+B)_ij C0 η_j.

The last sum and, for the oracle derivatives (docs/fidelity.md, D9), its first two time derivatives
are the block's input ``nb`` (3n numbers), and ``cpl`` = (l̄_ii, a_i0 h_i) with their first two
time derivatives (6 numbers: nonzero while links fade, ``graph.link_fade``, where the
derivatives of eq. (6) take the weights' rates by the product rule); the block outputs the jets
``(C0 η_i, C0 η̇_i, C0 η̈_i)`` its listeners sum into their ``nb``; the level-l jet reads
only the levels < l of ``nb``, so passes by jet level over all followers give the whole
closed loop's right-hand side on any graph (tests/test_agents.py). The per-agent engine
compiles it once per follower model (:mod:`generated.agent_kernels`).

Every number a scenario may vary without changing the model's equations is an input: the
block's ``prm`` is its follower's row of :func:`symbolic.parameters.agent_rows` (the
per-agent numbers, the observer's gains Q, λ1, λ2 and the UIO's matrices on their
patterns, the leader's u0 literals, the follower's fault template and literals),
from which it evaluates u0(t), g_i(t) and f_i(t) itself.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from core.scenario import Scenario
from symbolic.closed_loop import StateLayout, agent_function, saturated
from symbolic.derivatives import flow_jets
from symbolic.leader import leader_function
from symbolic.observer import ObserverGains, observer_function
from symbolic.parameters import RowLayout, param_layout, row_layout


def agent_block(sc: Scenario, og: ObserverGains, lay: StateLayout, model_index: int) -> ca.Function:
    """Follower i's block ``(t, xb, nb, cpl, prm) -> (xbdot, jets)`` (module docstring).

    ``prm`` is a row of :func:`symbolic.parameters.agent_rows` (layout
    :func:`symbolic.parameters.row_layout` of ``sc`` and ``og``).
    Only the patterns of ``og``'s matrices are compiled in, never their values.

    Parameters
    ----------
    sc : Scenario
    og : ObserverGains
    lay : StateLayout
    model_index : int
        0-based follower whose model and parameters the block uses (the per-agent
        kernels of :mod:`generated.agents`, one per model).
    """
    m, n = sc.m, sc.n
    filtered = sc.options.derivatives == "filtered"
    C0 = ca.DM(np.atleast_2d(sc.leader.C0))
    poff, _ = param_layout(n, saturated(sc))
    rows = row_layout(sc, og)
    t = ca.SX.sym("t")
    xb = ca.SX.sym("xb", m + lay.agent_size)
    nb = ca.SX.sym("nb", 3 * n)
    cpl = ca.SX.sym("cpl", 6)  # (l̄_ii, a_i0 h_i) and their first two time derivatives
    prm = ca.SX.sym("prm", rows.size)
    eta0, s = xb[:m], xb[m:]
    lii, a0h = cpl[0], cpl[1]
    dlii, da0h, ddlii, dda0h = cpl[2], cpl[3], cpl[4], cpl[5]
    u0c = ca.vertcat(*(prm[sl] for sl in rows.u0)) if rows.u0 else ca.SX(0, 1)
    lead = leader_function(sc.leader, parametric=True)
    eta0dot, _, y0, y0dot, y0ddot, _, _ = lead(t, eta0, u0c)  # eq. (3)
    so = s[: 2 * m + 1]  # (μ_i, η_i, φ_i)
    eta = s[lay.agent_offsets["eta"]]
    # eq. (6), follower i's row of ψ = C0 E (L+B)ᵀ − y0 (a0 ∘ h)ᵀ
    psi = lii * ca.mtimes(C0, eta) + nb[:n] - a0h * y0
    if filtered:
        dpsi = ddpsi = ca.SX.zeros(n)
    else:  # the oracle's time derivatives of the same row (symbolic.closed_loop._network)
        obs = observer_function(og, parametric=True)
        D1, _ = flow_jets(obs)
        Pobs = ca.vertcat(prm[poff["obs"]], prm[rows.gains])  # (α1+ᾱ1, φ_min), the gains
        sod = obs(so, psi, Pobs)[0]
        C0eta, C0etad = ca.mtimes(C0, eta), ca.mtimes(C0, sod[m : 2 * m])
        # ψ̇_i = l̄_ii C0η̇_i + nb' − a_i0 h_i ẏ0, plus the fading weights' rates (eq. (6))
        dpsi = lii * C0etad + nb[n : 2 * n] - a0h * y0dot + dlii * C0eta - da0h * y0
        sodd = D1(so, psi, Pobs, sod, dpsi)
        # ψ̈_i: the weights' W, 2Ẇ, Ẅ on the second, first and zeroth derivatives
        ddpsi = lii * ca.mtimes(C0, sodd[m : 2 * m]) + nb[2 * n :] - a0h * y0ddot
        ddpsi = ddpsi + 2 * (dlii * C0etad - da0h * y0dot) + ddlii * C0eta - dda0h * y0
    agent = agent_function(sc, og, model_index, parametric_gains=True)
    P = prm[: rows.gains.stop]  # the per-agent numbers and the observer's gains
    res = dict(
        zip(
            agent.name_out(),
            agent(s, psi, dpsi, ddpsi, fault_values(rows, t, prm), ca.SX.zeros(n), P),
            strict=True,
        )
    )
    xbdot = ca.vertcat(eta0dot, res["sdot"])
    etaddot = ca.SX.zeros(m) if filtered else res["etaddot"]  # filtered: ψ alone is used
    jets = ca.vertcat(*(ca.mtimes(C0, v) for v in (eta, res["etadot"], etaddot)))
    return ca.Function(
        "cascade_block",
        [t, xb, nb, cpl, prm],
        [xbdot, jets],
        ["t", "xb", "nb", "cpl", "prm"],
        ["xbdot", "jets"],
        {"cse": True},
    )


def fault_values(rows: RowLayout, t: ca.SX, prm: ca.SX) -> ca.SX:
    """(g_i(t), f_i(t)) from a follower's row: its template of each component, its literals.

    A component with several templates in the scenario sums each template's value where
    the row's index chooses it (``if_else`` to 0 elsewhere: an unchosen template's value,
    even a NaN of its empty literal slot, never enters).

    Parameters
    ----------
    rows : RowLayout
    t : casadi.SX
        Time.
    prm : casadi.SX
        The row.
    """
    out = []
    for sel, slots, tpl in zip(rows.select, rows.slots, rows.templates, strict=True):
        vals = [
            ca.SX(e.casadi(t, prm[sl])) if sl.stop > sl.start else ca.SX(e.casadi(t))
            for e, sl in zip(tpl, slots, strict=True)
        ]
        if len(vals) == 1:
            out.append(vals[0])
        else:
            out.append(sum(ca.if_else(prm[sel] == k, v, 0.0) for k, v in enumerate(vals)))
    return ca.vertcat(*out)
