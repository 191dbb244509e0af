"""One follower's closed-loop block as one SX Function of its own inputs (eqs. (6)-(30)).

:func:`agent_function` builds it from the blocks of ``symbolic/`` (UIO, observer,
formation, derivatives, controller, adaptive laws, dynamics); the assembly in
:mod:`symbolic.closed_loop` maps it over the agents of one model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca

from core.models import ELModel, build_model
from core.scenario import Scenario
from symbolic.adaptive import adaptive_function
from symbolic.controller import controller_function, saturate
from symbolic.derivatives import filter_function, flow_jets
from symbolic.formation import formation_function
from symbolic.layout import agent_offsets
from symbolic.observer import ObserverGains, gain_values, observer_function
from symbolic.parameters import (
    param_layout,
)


def saturated(sc: Scenario) -> bool:
    """Whether ``sc`` limits the applied torque (``controller.u_max`` given).

    Parameters
    ----------
    sc : Scenario
        The scenario.
    """
    return sc.controller.u_max is not None


AGENT_INPUTS = ("s", "psi", "dpsi", "ddpsi", "gf", "a", "prm")
AGENT_OUTPUTS = (
    "sdot",
    "sdot_dae",
    "res",
    "et",
    "etdot",
    "chi",
    "Psi",
    "u",
    "b",
    "bdot",
    "bddot",
    "ehat",
    "v",
    "etadot",
    "etaddot",
    "eta3dot",
    "qdot",
    "V2",
)


@dataclass(frozen=True)
class _AgentSymbols:
    """The inputs of one follower's Function (:data:`AGENT_INPUTS`) and named views.

    ``S`` names the parts of the agent block ``s``, ``P`` those of the per-agent
    numbers ``prm``; ``g``, ``f`` are the fault values in ``gf``.
    """

    inputs: dict[str, ca.SX]
    S: dict[str, ca.SX]
    P: dict[str, ca.SX]

    @classmethod
    def make(cls, sc: Scenario, gains: int = 0) -> _AgentSymbols:
        """Symbols sized for ``sc``'s leader, coordinates and derivative option; ``gains``
        more numbers after the per-agent ones, the observer's (``P["obs"]`` then ends
        with them: :func:`symbolic.observer.gain_values`)."""
        m, n = sc.m, sc.n
        off, na = agent_offsets(m, n, sc.options.derivatives == "filtered")
        poff, npar = param_layout(n, saturated(sc))
        s = ca.SX.sym("s", na)
        psi, dpsi, ddpsi = (ca.SX.sym(k, n) for k in ("psi", "dpsi", "ddpsi"))
        gf = ca.SX.sym("gf", 1 + n)
        a = ca.SX.sym("a", n)
        prm = ca.SX.sym("prm", npar + gains)
        inputs = dict(zip(AGENT_INPUTS, (s, psi, dpsi, ddpsi, gf, a, prm), strict=True))
        P = {k: prm[sl] for k, sl in poff.items()}
        if gains:
            P["obs"] = ca.vertcat(P["obs"], prm[npar:])
        S = {k: s[sl] for k, sl in off.items()}
        return cls(inputs, S, P)

    @property
    def g(self) -> ca.SX:
        return self.inputs["gf"][0]

    @property
    def f(self) -> ca.SX:
        return self.inputs["gf"][1:]


def _reference_signals(sc: Scenario, og: ObserverGains, sym: _AgentSymbols) -> dict[str, Any]:
    """Observer flow, η̇_i and its derivatives, and the formation offset b_i with its own.

    Oracle derivatives differentiate the observer flow along ψ's jets; ``filtered``
    derivatives take them from the filter states (``extra`` holds their rates).
    """
    m, n, opts = sc.m, sc.n, sc.options
    S, P, inp = sym.S, sym.P, sym.inputs
    psi = inp["psi"]
    obs = observer_function(og, parametric=P["obs"].numel() > 2)
    so = ca.vertcat(S["mu"], S["eta"], S["phi"])
    sodot, v, ehat = obs(so, psi, P["obs"])  # eqs. (7), (9)
    etadot = sodot[m : 2 * m]
    form = formation_function(m, n, opts.tau_threshold)
    extra = []
    if opts.derivatives == "filtered":
        filt = filter_function(m, n, opts.filter_bandwidth)
        b = form(etadot, ca.SX.zeros(m), ca.SX.zeros(m), P["b0"])[0]
        wdot, zdot, etaddot, bdot, bddot = filt(S["w"], S["z"], etadot, b)
        eta3dot = ca.SX.zeros(m)
        extra = [wdot, zdot]
    else:
        D1, D2 = flow_jets(obs)
        ddso = D1(so, psi, P["obs"], sodot, inp["dpsi"])
        dddso = D2(so, psi, P["obs"], sodot, inp["dpsi"], ddso, inp["ddpsi"])
        etaddot, eta3dot = ddso[m : 2 * m], dddso[m : 2 * m]
        b, bdot, bddot = form(etadot, etaddot, eta3dot, P["b0"])  # section 7
    return dict(
        sodot=sodot,
        v=v,
        ehat=ehat,
        etadot=etadot,
        etaddot=etaddot,
        eta3dot=eta3dot,
        b=b,
        bdot=bdot,
        bddot=bddot,
        extra=extra,
    )


def _control(sc: Scenario, model: ELModel, sym: _AgentSymbols, r: dict[str, Any]) -> dict:
    """The control law (eqs. (28)–(29), (42)) and the adaptive laws (eq. (30))."""
    S, P, opts = sym.S, sym.P, sc.options
    bdot_c, bddot_c = (
        (r["bdot"], r["bddot"]) if opts.feedforward else (0 * r["bdot"], 0 * r["bddot"])
    )
    ctrl = controller_function(
        model, sc.leader.C0, sign=opts.sign, sign_width=opts.sign_width, ablation=opts.ablation
    )
    et, etdot, chi, Psi, u = ctrl(
        S["p"],
        S["q"],
        S["eta"],
        r["etadot"],
        r["etaddot"],
        r["b"],
        bdot_c,
        bddot_c,
        S["thetahat"],
        S["ghat"],
        P["Lambda"],
        P["k1"],
    )  # eqs. (28)-(29), (42)
    if saturated(sc):
        u = saturate(u, P["u_max"])  # the applied (and logged) torque; Ψ and (30) unchanged
    adap = adaptive_function(sc.n, opts.ghat_law, sc.controller.g_min)
    thd, ghd = adap(
        chi, Psi, S["thetahat"], S["ghat"], P["k2"], P["gamma"], P["sigma"], P["ghat_ref"]
    )  # eq. (30)
    return dict(et=et, etdot=etdot, chi=chi, Psi=Psi, u=u, thd=thd, ghd=ghd)


def _dynamics(model: ELModel, sym: _AgentSymbols, r: dict[str, Any], c: dict) -> dict:
    """Eq. (2) as an ODE (q̇) and as a DAE residual, the agent's rates and V2 (eq. (32))."""
    S, P, g = sym.S, sym.P, sym.g
    M, Cm = model.M(S["p"]), model.C(S["p"], S["q"])
    G = model.forces(S["p"], S["q"])  # G, and the dissipative D beside it (core/models)
    force = g * c["u"] + sym.f - Cm @ S["q"] - G  # eq. (2): M p̈ = g u + f − C q − G
    qdot = ca.solve(M, force)
    res = M @ sym.inputs["a"] - force  # eq. (2) as a DAE residual: M a + C q + G − g u − f
    head = [r["sodot"], S["q"]]
    tail = [c["thd"], c["ghd"], *r["extra"]]
    sdot = ca.vertcat(*head, qdot, *tail)
    sdot_dae = ca.vertcat(*head, sym.inputs["a"], *tail)
    gam = P["gamma"]
    V2 = (
        0.5 * ca.bilin(M, c["chi"], c["chi"])
        + 0.5 * ca.sumsqr(S["thetahat"] - P["d"])
        + g / (2 * gam) * (S["ghat"] - 1 / g) ** 2
    )  # eq. (32), ĝ term weighted g/(2γ)
    return dict(sdot=sdot, sdot_dae=sdot_dae, res=res, qdot=qdot, V2=V2)


def agent_function(
    sc: Scenario, og: ObserverGains, model_index: int, parametric_gains: bool = False
) -> ca.Function:
    """Everything local to one follower as one SX Function.

    Inputs ``s`` (agent block), ``psi``, ``dpsi``, ``ddpsi`` (ψ_i and, for the oracle,
    its first two time derivatives), ``gf`` = (g_i(t), f_i(t)), ``a`` (acceleration,
    used only by the DAE residual) and ``prm`` (per-agent numbers, followed with
    ``parametric_gains`` by the observer's gains, :func:`symbolic.observer.gain_values`).
    Outputs ``sdot`` (ODE), ``sdot_dae`` (q̇ = a), ``res`` (DAE residual) and diagnostics
    (:data:`AGENT_OUTPUTS`).

    Parameters
    ----------
    sc : Scenario
        The scenario (options, controller settings, follower models).
    og : ObserverGains
        Observer gains shared by all agents.
    model_index : int
        0-based follower whose model (and parameters) the Function uses; followers
        with the same model and parameters share it.
    parametric_gains : bool
        The observer's gains as inputs (the per-agent kernels) instead of constants.
    """
    fo = sc.followers[model_index]
    model = build_model(fo.model, fo.params)
    ng = gain_values(og).size if parametric_gains else 0
    sym = _AgentSymbols.make(sc, ng)
    r = _reference_signals(sc, og, sym)
    c = _control(sc, model, sym, r)
    d = _dynamics(model, sym, r, c)
    named = {**r, **c, **d}
    return ca.Function(
        f"agent_{fo.model}_{model_index}",
        list(sym.inputs.values()),
        [named[k] for k in AGENT_OUTPUTS],
        list(AGENT_INPUTS),
        list(AGENT_OUTPUTS),
    )
