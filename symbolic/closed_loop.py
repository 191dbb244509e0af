"""The closed loop of the paper as one CasADi model (docs/reading.md, 'Network' to 'Formation').

Data flow: Scenario + Gains -> :func:`build_closed_loop` -> :class:`ClosedLoop`,
which the ``generated/`` stage turns into C and integrates.

Assembly (``assembly="map"``, the default): every block local to a follower
(UIO, observer, formation, derivative filters, controller, adaptive laws,
dynamics) is one SX Function of that agent's own inputs, applied to all agents
with ``Function.map``; the coupling through the graph is a sparse matrix product
(:func:`symbolic.network.coupling`). The number of instructions of the closed-loop
Function therefore does not depend on N. ``assembly="flat"`` calls the same
per-agent Function once per agent in one SX expression, for comparison.

State vector: ``x = (η0, s_1, …, s_N)`` with agent block
``s_i = (μ_i, η_i, φ_i, p_i, q_i, θ̂_i, ĝ_i[, w_i, z_i])`` (``w``, ``z``: the
derivative filters of the ``filtered`` option). :class:`StateLayout` maps names to
slices and back.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from core.errors import ScenarioError, SynthesisError
from core.memo import MEMO
from core.scenario import Scenario
from symbolic.agent import AGENT_INPUTS, AGENT_OUTPUTS, agent_function, saturated  # noqa: F401
from symbolic.derivatives import flow_jets
from symbolic.layout import AGENT_STATES, StateLayout, make_layout  # noqa: F401
from symbolic.leader import leader_function
from symbolic.network import ASSEMBLIES, GraphMatrices, apply_agents, coupling, graph_matrices
from symbolic.observer import ObserverGains, observer_function
from symbolic.parameters import (
    ParamLayout,
    graph_pattern,
    layout_of,
    param_layout,
    param_values,
    structure_key,
)
from symbolic.uio import uio_of
from synthesis.gains import Gains


@dataclass(frozen=True)
class ClosedLoop:
    """The symbolic closed loop.

    Attributes
    ----------
    layout : StateLayout
    ode : casadi.Function
        ``(t, x) -> xdot``.
    ode_dyn : casadi.Function
        The same in integrator form: inputs ``ca.dyn_in()`` = (t, x, z, p, u), outputs
        ``ca.dyn_out()`` = (ode, alg, quad, zero); z, p, u empty.
    dae_dyn : casadi.Function
        Semi-explicit DAE for IDAS, same inputs/outputs, with z = accelerations of all
        followers and alg = M(p)a + C(p,q)q + G(p) − g u − f; built on first use (only
        the DAE methods read it: :attr:`Parametric.dae_dyn`).
    outputs : casadi.Function
        ``(t, x) -> named outputs`` (e_t, chi, u, b, ehat, ebar, V1, V2, ...).
    x0 : ndarray
    z0 : ndarray
        Consistent initial accelerations for the DAE.
    breakpoints : tuple of float
        Known discontinuity times in (0, horizon).
    assembly : str
        ``"map"`` or ``"flat"``.
    blocks : dict
        The per-agent and leader Functions the loop is assembled from.
    """

    layout: StateLayout
    ode: ca.Function
    ode_dyn: ca.Function
    outputs: ca.Function
    x0: np.ndarray
    z0: np.ndarray
    breakpoints: tuple[float, ...]
    parametric: Parametric = field(repr=False)
    p0: np.ndarray
    assembly: str = "map"
    blocks: dict[str, ca.Function] = field(default_factory=dict, repr=False)

    @cached_property
    def dae_dyn(self) -> ca.Function:
        """The DAE in integrator form with this loop's p filled in (built on first use)."""
        return fix_parameters(self.parametric.dae_dyn, self.p0)


@dataclass(frozen=True)
class Parametric:
    """The closed loop's Functions with the parameter vector p as an input.

    What the generated code is made of: equal :attr:`structure_key`, equal code.

    Attributes
    ----------
    layout : ParamLayout
        Named slices of p (:mod:`symbolic.parameters`).
    ode : casadi.Function
        ``(t, x, p) -> xdot``.
    ode_dyn : casadi.Function
        Integrator form ``(t, x, z, p, u)`` (see :class:`ClosedLoop`), p not empty.
    outputs : casadi.Function
        ``(t, x, p) -> named outputs``.
    structure_key : str
        :func:`symbolic.parameters.structure_key` of the scenario it was built from.
    build_dae : callable
        Builds :attr:`dae_dyn` (the same integrator form of the DAE) when first read: the
        ODE methods never read it, and it costs as much to build as the ODE.
    """

    layout: ParamLayout
    ode: ca.Function
    ode_dyn: ca.Function
    outputs: ca.Function
    structure_key: str
    build_dae: Callable[[], ca.Function] = field(repr=False, compare=False)

    @cached_property
    def dae_dyn(self) -> ca.Function:
        """``(t, x, z, p, u)``: the semi-explicit DAE (see :class:`ClosedLoop`)."""
        return self.build_dae()


# ----------------------------------------------------------------------------- helpers


def fault_function(sc: Scenario) -> tuple[ca.Function, list[int]]:
    """Distinct fault expressions g_i(t), f_ir(t) evaluated once; index list to (1+n)×N.

    Followers sharing an expression share its evaluation, so with identical
    faults the graph size does not grow with N.

    Parameters
    ----------
    sc : Scenario
    """
    t = ca.SX.sym("t")
    texts: dict[str, int] = {}
    vals: list[ca.SX] = []
    idx: list[int] = []
    for fo in sc.followers:
        for e in (fo.g.expr, *fo.f):
            if e.text not in texts:
                texts[e.text] = len(vals)
                vals.append(ca.SX(e.casadi(t)))
            idx.append(texts[e.text])
    return ca.Function("faults", [t], [ca.vertcat(*vals)], ["t"], ["values"]), idx


def fault_values(sc: Scenario, lay: ParamLayout) -> ca.Function:
    """``(t, p) -> (1+n)×N``: g_i(t) and f_i(t) of every follower, literals read from p.

    Parameters
    ----------
    sc : Scenario
    lay : ParamLayout
        The layout of p (:func:`symbolic.parameters.layout_of`).
    """
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", lay.size)
    cols = []
    for i, fo in enumerate(sc.followers):
        g = fo.g.expr.casadi(t, lay.get(p, f"expr:followers[{i}].g"))
        f = [e.casadi(t, lay.get(p, f"expr:followers[{i}].f[{r}]")) for r, e in enumerate(fo.f)]
        cols.append(ca.vertcat(g, *f))
    return ca.Function("faults", [t, p], [ca.horzcat(*cols)], ["t", "p"], ["GF"])


def graph_coupling(
    sc: Scenario, lay: ParamLayout, t: Any, p: Any
) -> tuple[tuple[Any, Any], tuple[Any, Any], tuple[Any, Any]]:
    """``L_Bᵀ`` and ``(a0 ∘ h)ᵀ`` at time t and their first two time derivatives.

    Sparse matrices whose nonzeros are read from p. The pattern is the union of the
    topologies the graph reaches (structure); the weights of topology k, its start time
    and the fade time T are parameters. With switching times s_1 < … < s_{K−1} the weights
    are v_0 + Σ_k σ_k(t)(v_k − v_{k−1}): with T = 0, σ_k = step(t − s_k) (piecewise
    constant and right-continuous, the new graph holds from s_k on; derivatives 0); with
    T > 0, σ_k = σ((t − s_k)/T), the C² fade of :func:`core.graph.fade_jets`, so ψ of
    eq. (6) and the oracle's ψ̇, ψ̈ stay continuous through a switch (docs/verification.md,
    'Link losses').

    Parameters
    ----------
    sc : Scenario
    lay : ParamLayout
    t : casadi.SX or casadi.MX
        Time.
    p : casadi.SX or casadi.MX
        The parameter vector.

    Returns
    -------
    W, dW, ddW : tuple of (L_Bᵀ, (a0 ∘ h)ᵀ)
        The weights and their first and second time derivatives (None without switches).
    """
    L, a = graph_pattern(sc, lay.dense)
    nw = int(L.sum() + a.sum())
    w = lay.get(p, "graph")
    times = lay.get(p, "graph_times")
    v = w[0:nw]
    if not times.numel():  # one topology: constant weights (no derivative terms)
        return _sparse_pair(L, a, p, v), None, None
    dv = ddv = 0 * v
    if times.numel():
        T = lay.get(p, "graph_fade")[0]
        pos = T > 0
        Ts = ca.if_else(pos, T, 1.0)  # no division by 0 in the branch not taken
    for k in range(times.numel()):
        jump = w[(k + 1) * nw : (k + 2) * nw] - w[k * nw : (k + 1) * nw]
        x = ca.fmin(ca.fmax((t - times[k]) / Ts, 0.0), 1.0)
        inside = ca.logic_and(t > times[k], t < times[k] + Ts)
        sig = x**3 * (10 - 15 * x + 6 * x**2)  # core.graph.fade_jets
        dsig = ca.if_else(inside, 30 * x**2 * (1 - x) ** 2, 0.0) / Ts
        ddsig = ca.if_else(inside, 60 * x * (1 - x) * (1 - 2 * x), 0.0) / Ts**2
        raw = ca.if_else(t >= times[k], 1.0, 0.0)
        v = v + ca.if_else(pos, sig, raw) * jump
        dv = dv + ca.if_else(pos, dsig, 0.0) * jump
        ddv = ddv + ca.if_else(pos, ddsig, 0.0) * jump
    return _sparse_pair(L, a, p, v), _sparse_pair(L, a, p, dv), _sparse_pair(L, a, p, ddv)


def _sparse_pair(L: np.ndarray, a: np.ndarray, p: Any, vec: Any) -> tuple[Any, Any]:
    """``(L_Bᵀ, (a0 ∘ h)ᵀ)`` on the patterns ``L``, ``a`` with nonzeros ``vec`` (in order)."""
    out, k = [], 0
    for mask in (L, a):
        cols, rows = np.nonzero(mask.T)
        sp = ca.Sparsity.triplet(mask.shape[0], mask.shape[1], rows.tolist(), cols.tolist())
        out.append(type(p)(sp, vec[k : k + sp.nnz()]))
        k += sp.nnz()
    return out[0], out[1]


def observer_gains(sc: Scenario, gains: Gains) -> ObserverGains:
    """Eq. (9)'s gains and the UIO, read from ``gains`` (checked against the leader).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    """
    L = sc.leader
    for name, a, b in (("A0", gains.A0, L.A0), ("B0", gains.B0, L.B0), ("C0", gains.C0, L.C0)):
        a = np.atleast_2d(np.asarray(a, dtype=float))
        if a.shape != b.shape or not np.allclose(a, b, rtol=1e-12, atol=1e-12):
            raise SynthesisError(
                f"gains.{name} differs from the scenario's leader.{name}; re-run make synth"
            )
    Q = np.atleast_2d(np.asarray(gains.Q, dtype=float)).reshape(L.p, L.m)
    return ObserverGains(
        A0=np.asarray(L.A0),
        B0=np.asarray(L.B0),
        Q=Q,
        lambda1=float(gains.lambda1),
        lambda2=float(gains.lambda2),
        uio=uio_of(gains),  # Γ, Φ of eq. (7) as synthesis certified them
    )


# ----------------------------------------------------------------------------- assembly
def model_groups(sc: Scenario) -> list[list[int]]:
    """Agents grouped by (model, parameters): one per-agent Function per group.

    Parameters
    ----------
    sc : Scenario
    """
    keys: dict[tuple, list[int]] = {}
    for i, fo in enumerate(sc.followers):
        keys.setdefault((fo.model, tuple(sorted(fo.params.items()))), []).append(i)
    return list(keys.values())


def _slim(f: ca.Function, keep: Sequence[str] | None) -> ca.Function:
    """``f`` with only the outputs ``keep`` (all when None).

    A mapped MX call evaluates every output of the per-agent SX Function, and its
    forward derivative differentiates all of them: the right-hand side needs only
    ``sdot`` (ODE) or ``sdot_dae``/``res`` (DAE). SX-expanded builds prune dead code
    anyway; for the large-N (MX map) plan this cut the generated right-hand side's
    work (docs/performance.md).
    """
    if keep is None:
        return f
    args = f.sx_in()
    res = dict(zip(f.name_out(), f.call(args), strict=True))
    return ca.Function(
        f"{f.name()}_{'_'.join(keep)}",
        args,
        [res[k] for k in keep],
        f.name_in(),
        list(keep),
        {"cse": True},
    )


def _parameters_at(
    sc: Scenario, play: ParamLayout, t: Any, pv: Any
) -> tuple[Any, dict, Any, Any, ca.Function]:
    """Per-agent numbers (npar×N) and their offsets, g/f values, graph weights, the leader."""
    poff, npar = param_layout(sc.n, saturated(sc))
    P = ca.reshape(play.get(pv, "agents"), npar, sc.N)
    GF = fault_values(sc, play)(t, pv)
    W = graph_coupling(sc, play, t, pv)  # (weights, their rate, their second derivative)
    return P, poff, GF, W, leader_function(sc.leader, parametric=True)


def _u0_literals(play: ParamLayout, pv: Any) -> Any:
    """The literals of the operator's u0 expressions, in input order."""
    lits = [play.get(pv, k) for k in play.slices if k.startswith("expr:leader.u0")]
    return ca.vertcat(*lits) if lits else type(pv)(0, 1)


def _oracle_psi(
    sc: Scenario,
    og: ObserverGains,
    assembly: str,
    gm: GraphMatrices,
    jets: tuple[Any, Any, Any, Any, tuple[Any, Any, Any]],
    weights: tuple[Any, Any, Any],
) -> tuple[Any, Any]:
    """ψ̇ and ψ̈ of every agent for the oracle derivatives (symbolic/derivatives.py).

    Passes over the network: η̇ of all agents -> ψ̇ -> η̈ of all agents -> ψ̈. ``jets`` is
    (E, the agents' (μ, η, φ), ψ, the observer's numbers, (y0, ẏ0, ÿ0)); ``weights`` the
    graph's weights and their two rates (None without switches,
    :func:`graph_coupling`).
    """
    m, N, C0 = sc.m, sc.N, sc.leader.C0
    E, SO, psi, Pobs, (y0, y0dot, y0ddot) = jets
    W, dW, ddW = weights
    obs = observer_function(og)
    D1, _ = flow_jets(obs)
    SOd = apply_agents(obs, N, [SO, psi, Pobs], assembly)[0]
    dpsi = coupling(C0, SOd[m : 2 * m, :], y0dot, gm, W)
    if dW is not None:  # fading weights (graph.link_fade): d/dt of eq. (6) has Ẇ's term
        dpsi = dpsi + coupling(C0, E, y0, gm, dW)
    SOdd = apply_agents(D1, N, [SO, psi, Pobs, SOd, dpsi], assembly)[0]
    ddpsi = coupling(C0, SOdd[m : 2 * m, :], y0ddot, gm, W)
    if ddW is not None:  # ψ̈ = C0Ë Wᵀ + 2 C0Ė Ẇᵀ + C0E Ẅᵀ (and the leader's terms)
        ddpsi = ddpsi + 2 * coupling(C0, SOd[m : 2 * m, :], y0dot, gm, dW)
        ddpsi = ddpsi + coupling(C0, E, y0, gm, ddW)
    return dpsi, ddpsi


def _network(
    sc: Scenario,
    gains: Gains,
    assembly: str,
    t: Any,
    x: Any,
    a: Any,
    pv: tuple[ParamLayout, Any],
    keep: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Symbolic evaluation of the whole network at (t, x, p) (and accelerations a).

    ``pv`` is the parameter vector's layout and symbol (:mod:`symbolic.parameters`);
    ``keep`` names the per-agent outputs needed (all when None, see :func:`_slim`).
    """
    play, pv = pv
    m, n, N = sc.m, sc.n, sc.N
    filtered = sc.options.derivatives == "filtered"
    lay = make_layout(m, n, N, filtered)
    gm: GraphMatrices = graph_matrices(sc.graph, gains)
    og = observer_gains(sc, gains)
    P, poff, GF, (W, dW, ddW), lead = _parameters_at(sc, play, t, pv)
    eta0dot, eta0ddot, y0, y0dot, y0ddot, u0, u0dot = lead(t, x[:m], _u0_literals(play, pv))
    eta0 = x[:m]
    X = ca.reshape(x[m:], lay.agent_size, N)
    E = X[lay.agent_offsets["eta"], :]
    SO = X[: 2 * m + 1, :]  # (μ, η, φ) of every agent
    psi = coupling(sc.leader.C0, E, y0, gm, W)  # eq. (6): ψ_i from neighbours' estimates and y0
    if filtered:
        dpsi = ddpsi = ca.DM.zeros(n, N)
    else:
        jets = (E, SO, psi, P[poff["obs"], :], (y0, y0dot, y0ddot))
        dpsi, ddpsi = _oracle_psi(sc, og, assembly, gm, jets, (W, dW, ddW))
    A = ca.reshape(a, n, N)
    groups = model_groups(sc)
    outs: list[Any] | None = None
    args = [X, psi, dpsi, ddpsi, GF, A, P]
    funs = {}
    if len(groups) == 1:
        f = agent_function(sc, og, 0)
        funs["agent"] = f
        outs = apply_agents(_slim(f, keep), N, args, assembly)
    else:
        parts, order = [], []
        for grp in groups:
            f = agent_function(sc, og, grp[0])
            funs[f"agent_{grp[0]}"] = f
            cols = [arg[:, grp] for arg in args]
            parts.append(apply_agents(_slim(f, keep), len(grp), cols, assembly))
            order += grp
        inv = list(np.argsort(order))
        outs = [ca.horzcat(*[p[k] for p in parts])[:, inv] for k in range(len(parts[0]))]
        f = funs[next(iter(funs))]
    named = dict(zip(f.name_out() if keep is None else keep, outs, strict=True))
    named.update(
        eta0=eta0,
        eta0dot=eta0dot,
        eta0ddot=eta0ddot,
        y0=y0,
        y0dot=y0dot,
        u0=u0,
        u0dot=u0dot,
        psi=psi,
        X=X,
        E=E,
        GF=GF,
        gm=gm,
        W=W,
        P=P,
        poff=poff,
        play=play,
        pv=pv,
        lay=lay,
        funs=funs,
        lead=lead,
    )
    return named


def build_closed_loop(
    scenario: Scenario, gains: Gains, *, assembly: str = "map", dense: bool = False
) -> ClosedLoop:
    """Build the closed loop of ``scenario`` with ``gains``.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario (:func:`core.scenario.load_scenario`).
    gains : Gains
        Synthesised (or hand-made) gains (:class:`synthesis.gains.Gains`).
    assembly : {"map", "flat"}
        ``map`` (default): per-agent Functions applied with ``Function.map`` (MX graph,
        size independent of N); ``flat``: one SX expression with one copy per agent.
    dense : bool
        The graph as data (:mod:`symbolic.parameters`): one structure, the same
        Functions, for every graph of N followers with up to
        :data:`~symbolic.parameters.DENSE_TOPOLOGIES` topologies (a study's random
        graphs); the same numbers as the graph's own loop (``tests/test_parameters.py``).

    Returns
    -------
    ClosedLoop

    Raises
    ------
    ScenarioError
        Unknown assembly, or a scenario the closed loop cannot represent.
    SynthesisError
        Gains designed for other leader matrices.
    """
    if assembly not in ASSEMBLIES:
        raise ScenarioError(
            "build_closed_loop", "assembly", f"{assembly!r} is unknown", "'map' or 'flat'"
        )
    sc = scenario
    m, n, N = sc.m, sc.n, sc.N
    filtered = sc.options.derivatives == "filtered"
    lay = make_layout(m, n, N, filtered)
    Sym = ca.MX if assembly == "map" else ca.SX
    play = layout_of(sc, dense)
    t, x, a = Sym.sym("t"), Sym.sym("x", lay.nx), Sym.sym("z", n * N)
    pv = Sym.sym("p", play.size)
    net = _network(sc, gains, assembly, t, x, ca.DM.zeros(n * N), (play, pv), keep=("sdot",))
    xdot = ca.vertcat(net["eta0dot"], ca.vec(net["sdot"]))  # eq. (3) and every agent
    e0 = Sym(0, 1)
    ode_p = ca.Function("ode", [t, x, pv], [xdot], ["t", "x", "p"], ["xdot"])
    ode_dyn_p = ca.Function(
        "ode_dyn", [t, x, e0, pv, e0], [xdot, e0, e0, e0], ca.dyn_in(), ca.dyn_out()
    )

    def build_dae() -> ca.Function:
        net_dae = _network(sc, gains, assembly, t, x, a, (play, pv), keep=("sdot_dae", "res"))
        xdot_dae = ca.vertcat(net_dae["eta0dot"], ca.vec(net_dae["sdot_dae"]))
        alg = ca.vec(net_dae["res"])
        return ca.Function(
            "dae_dyn", [t, x, a, pv, e0], [xdot_dae, alg, e0, e0], ca.dyn_in(), ca.dyn_out()
        )

    net_out = _network(sc, gains, assembly, t, x, ca.DM.zeros(n * N), (play, pv))  # every signal
    outputs_p = _outputs_function(sc, gains, net_out, t, x, pv)
    blocks = dict(net["funs"])
    blocks["leader"] = net["lead"]
    key = structure_key(sc, gains, dense)
    parametric = Parametric(play, ode_p, ode_dyn_p, outputs_p, key, build_dae)
    _remember_parametric((parametric.structure_key, assembly), parametric)
    return bind(parametric, sc, gains, lay, assembly, blocks, key=key)


#: how many structures' parametric loops a process keeps
PARAMETRIC_KEPT = 4
#: parametric loops built in this process, by (structure key, assembly) (core/memo.py)
_PARAMETRIC = MEMO.namespace("parametric-loops", PARAMETRIC_KEPT)


def _remember_parametric(key: tuple[str, str], par: Parametric) -> None:
    _PARAMETRIC[key] = par


def forget_parametric() -> None:
    """Forget the parametric loops :func:`closed_loop_for` would reuse."""
    _PARAMETRIC.clear()


def closed_loop_for(
    sc: Scenario, gains: Gains, assembly: str = "map", dense: bool = False
) -> ClosedLoop:
    """The closed loop of ``sc``: a parametric loop this process built for the same
    structure (:func:`build_closed_loop` keeps the newest few) bound to ``sc``'s numbers,
    else a new :func:`build_closed_loop`.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    assembly : {"map", "flat"}
        As for :func:`build_closed_loop`.
    dense : bool
        The graph as data (as for :func:`build_closed_loop`).
    """
    key = structure_key(sc, gains, dense)
    par = _PARAMETRIC.get((key, assembly))
    if par is None:
        return build_closed_loop(sc, gains, assembly=assembly, dense=dense)
    return bind(par, sc, gains, assembly=assembly, key=key)


def fix_parameters(f: ca.Function, p: np.ndarray) -> ca.Function:
    """``f`` with its input ``p`` filled in (kept, empty, in integrator form; else removed).

    Parameters
    ----------
    f : casadi.Function
        A Function with an input named ``p`` (symbolic, or loaded from a library).
    p : ndarray
        Its value.
    """
    names = list(f.name_in())
    k = names.index("p")
    ins = [ca.MX.sym(n, f.sparsity_in(i)) for i, n in enumerate(names)]
    args = list(ins)
    args[k] = ca.DM(np.asarray(p, dtype=float).reshape(-1, 1))
    if names == list(ca.dyn_in()):
        ins[k] = ca.MX.sym("p", 0, 1)  # integrator form keeps its five inputs, p empty
    else:
        del ins[k], names[k]
    return ca.Function(f.name(), ins, f.call(args), names, list(f.name_out()))


def bind(
    par: Parametric,
    sc: Scenario,
    gains: Gains,
    lay: StateLayout | None = None,
    assembly: str = "map",
    blocks: dict[str, ca.Function] | None = None,
    key: str | None = None,
) -> ClosedLoop:
    """The closed loop of ``sc``: the parametric Functions with ``sc``'s numbers.

    ``sc`` must have the structure ``par`` was built for (equal
    :func:`symbolic.parameters.structure_key`); only p, x(0) and the breakpoints
    are computed, nothing symbolic is rebuilt.

    Parameters
    ----------
    par : Parametric
        The parametric Functions.
    sc : Scenario
    gains : Gains
    lay : StateLayout, optional
        Default :func:`make_layout` of ``sc``.
    assembly : str
        Recorded on the result.
    blocks : dict, optional
        Recorded on the result.
    key : str, optional
        ``structure_key(sc, gains)`` when the caller has just computed it (a study's
        sample asks for it to find the build); default: computed here.

    Raises
    ------
    ScenarioError
        If ``sc`` has another structure.
    """
    dense = par.layout.dense
    key = key or structure_key(sc, gains, dense)
    if key != par.structure_key:
        raise ScenarioError(
            sc.path,
            "structure",
            "differs from the compiled closed loop's (graph, models, options, expression forms)",
            "build a closed loop for this scenario",
        )
    lay = lay or make_layout(sc.m, sc.n, sc.N, sc.options.derivatives == "filtered")
    p0 = param_values(sc, gains, dense)
    outputs = fix_parameters(par.outputs, p0)
    x0 = initial_state(sc, lay, outputs)
    qdd0 = np.array(outputs(0.0, x0)[outputs.name_out().index("qdot")]).reshape(-1)  # agent-major
    return ClosedLoop(
        layout=lay,
        ode=fix_parameters(par.ode, p0),
        ode_dyn=fix_parameters(par.ode_dyn, p0),
        outputs=outputs,
        x0=x0,
        z0=qdd0,
        breakpoints=sc.breakpoints(),
        parametric=par,
        p0=p0,
        assembly=assembly,
        blocks=blocks or {},
    )


def _outputs_function(
    sc: Scenario, gains: Gains, net: dict, t: Any, x: Any, pv: Any
) -> ca.Function:
    """Named outputs of (t, x); per-agent quantities as N×k matrices (row i = agent i)."""
    gm: GraphMatrices = net["gm"]
    lay: StateLayout = net["lay"]
    X, E, eta0 = net["X"], net["E"], net["eta0"]
    ehat = net["ehat"]
    h = ca.DM(gm.h.reshape(1, -1))
    ebar = E - ca.mtimes(eta0, h)  # ē_ηi = η_i − h_i η0
    e_eta = coupling(None, E, eta0, gm, net["W"])  # true neighbourhood error, eq. (6)
    etilde = ehat - e_eta  # UIO error, eq. (8)
    Tinv = ca.DM(np.linalg.inv(np.atleast_2d(gains.T)))
    Om = ca.DM(np.atleast_2d(gains.Omega))
    phi = X[lay.agent_offsets["phi"], :]
    eps = ca.mtimes(ehat, ca.DM(ca.Sparsity.diag(gm.N), gm.h.tolist()))  # ε_η = (H ⊗ I) ê_η
    abar = net["P"][net["poff"]["abar"], :].T  # ᾱ1i, a runtime parameter
    z, lbar, k1 = _v1_coefficients(net["play"], net["pv"], gains, gm)
    lam2 = float(gains.lambda2)
    V1 = (
        ca.mtimes(ca.sum1(eps * ca.mtimes(Tinv, eps)), z)
        + 2 * lam2 * ca.sum1(lbar * z * phi.T / abar)
        + k1 * ca.sum2(ca.sum1(etilde * ca.mtimes(Om, etilde)))
    )  # eq. (17)
    GF = net["GF"]
    # per-agent network signals, transposed to N×k (row i = follower i)
    items = {k: net[k].T for k in ("et", "etdot", "chi", "u", "Psi", "b", "bdot", "bddot")}
    items |= {
        "ehat": ehat.T,
        "ebar": ebar.T,
        "etilde": etilde.T,
        "e_eta": e_eta.T,
        **{k: net[k].T for k in ("psi", "v", "etadot", "etaddot", "eta3dot", "qdot")},
        "V1": V1,
        "V2": net["V2"].T,
        "thetahat": X[lay.agent_offsets["thetahat"], :].T,
        "ghat": X[lay.agent_offsets["ghat"], :].T,
        "phi": phi.T,
        "g": GF[0, :].T,
        "f": GF[1:, :].T,
        "eta0": eta0.T,
        "y0": net["y0"].T,
        "u0": net["u0"].T,
        "track": (X[lay.agent_offsets["p"], :] - ca.repmat(net["y0"], 1, sc.N) - net["b"]).T,
    }
    return ca.Function("outputs", [t, x, pv], list(items.values()), ["t", "x", "p"], list(items))


def _v1_coefficients(play: ParamLayout, pv: Any, gains: Gains, gm: GraphMatrices) -> tuple:
    """V1's z, l̄ (N×1) and k1 (eq. (17)): constants of the code, or read from p's ``v1``
    block with the graph as data (the same operations on the same numbers)."""
    if not play.dense:
        z = ca.DM(np.diag(np.atleast_2d(gains.Z)).reshape(-1, 1))
        return z, ca.DM(gm.l_bar.reshape(-1, 1)), float(gains.k1)
    v1, N = play.get(pv, "v1"), gm.N
    return v1[:N], v1[N : 2 * N], v1[2 * N]


def given_states(sc: Scenario) -> dict[str, np.ndarray]:
    """The states the scenario gives at t = 0 (Table 2's), by layout block; no filter states.

    Parameters
    ----------
    sc : Scenario
    """
    N = sc.N
    return {
        "eta0": sc.leader.eta0,
        "mu": sc.initial.mu,
        "eta": sc.initial.eta,
        "phi": sc.observer.phi0.reshape(N, 1),
        "p": np.array([fo.p0 for fo in sc.followers]),
        "q": np.array([fo.q0 for fo in sc.followers]),
        "thetahat": sc.initial.theta_hat,
        "ghat": sc.initial.ghat.reshape(N, 1),
    }


def initial_state(sc: Scenario, lay: StateLayout, outputs: ca.Function) -> np.ndarray:
    """x(0) from the scenario.

    Leader η0(0), μ_i(0), η_i(0), φ_i(0), q_i(0), θ̂_i(0), ĝ_i(0) as given. ``initial.start``:
    ``given`` uses Table 2's p_i(0); ``formation`` puts p_i(0) at C0 η_i(0) + b_i(0)
    (q_i(0) stays as given). Filter states start at the current signal with zero
    derivatives: w1 = η̇_i(0), z1 = b_i(0).

    Parameters
    ----------
    sc : Scenario
        The scenario (initial values and ``initial.start``).
    lay : StateLayout
        Layout of x.
    outputs : casadi.Function
        The closed loop's ``(t, x) -> outputs`` Function, used for η̇_i(0) and b_i(0).
    """
    m, n, N = sc.m, sc.n, sc.N
    parts = given_states(sc)
    filtered = "w" in lay.agent_offsets
    if filtered:
        parts["w"] = np.zeros((N, 2 * m))
        parts["z"] = np.zeros((N, 3 * n))
    x0 = lay.pack(parts)
    o = dict(zip(outputs.name_out(), outputs(0.0, x0), strict=True))
    etadot = np.array(o["etadot"])
    b = np.array(o["b"])
    if sc.initial.start == "formation":
        parts["p"] = sc.initial.eta @ np.asarray(sc.leader.C0).T + b
    if filtered:
        parts["w"][:, :m] = etadot
        parts["z"][:, :n] = b
    return lay.pack(parts)
