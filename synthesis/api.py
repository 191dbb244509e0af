"""``synthesize(scenario) -> Gains``: assumptions, Lemma 3, LMIs (15)–(16), gains, certificate.

One function per step of the design: :func:`_lmi15` (T and Q), :func:`_lmi16` (Ω and
Θ), :func:`_theorem1_gains` (λ1, λ2), :func:`_with_k1` (V1's k1), :func:`_info` (what
the run used) and :func:`_certified` (the certificate and its verdict).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from core.errors import SynthesisError
from core.graph import NetworkCheck, check_network
from core.scenario import Observer, Scenario
from synthesis.assumptions import LeaderCheck, check_leader, uio_matrices
from synthesis.certificate import certify, k1_bound
from synthesis.gains import Gains, given_by
from synthesis.lemma3 import Lemma3Result, lemma3
from synthesis.lmi import (
    LMI_EPS,
    SOLVER_TOL,
    OmegaResult,
    TResult,
    check_given_Q,
    check_given_Theta,
    min_lambda_bar1_for_Q,
    synth_Omega_Theta,
    synth_T,
)
from synthesis.switching import check_topologies, switched_w_min

MIN_REL_MARGIN = 1e-3  # strict inequalities (λ1 > λ̄1/w, k1 > bound) keep at least this margin


@dataclass(frozen=True)
class _Lmi15:
    """LMI (15)'s answer: T and Q, and (Q given) the smallest admissible λ̄1."""

    result: TResult
    lb1_min: float | None = None
    notes: list[str] = field(default_factory=list)


def _lmi15(obs: Observer, A0: np.ndarray, B0: np.ndarray) -> _Lmi15:
    """Q synthesised from T, or the given Q checked (an LMI in T⁻¹), eq. (15)."""
    lb1, d1 = obs.lambda_bar1, obs.delta1
    if obs.Q is None:
        return _Lmi15(synth_T(A0, B0, lb1, d1))
    Qg = np.array(obs.Q, dtype=float)
    tr = check_given_Q(A0, B0, Qg, lb1, d1)
    lb1_min = min_lambda_bar1_for_Q(A0, B0, Qg, d1)
    note = (
        f"given Q satisfies LMI (15) with delta1 = {d1:g} exactly for lambda_bar1 > {lb1_min:.6g}"
        f" (solver bound; lambda1 = {obs.lambda1 if obs.lambda1 is not None else 'synth'}"
        f" then needs w > {lb1_min / obs.lambda1 if obs.lambda1 else math.nan:.4g})"
    )
    return _Lmi15(tr, lb1_min, [note])


def _lmi16(
    obs: Observer, Phi: np.ndarray, A0: np.ndarray, C0: np.ndarray, margin: float
) -> OmegaResult:
    """Ω and Θ jointly, or Ω for the given Θ, eq. (16)."""
    if obs.Theta is None:
        return synth_Omega_Theta(Phi, A0, C0, obs.delta2, rel_margin=margin)
    return check_given_Theta(Phi, A0, C0, np.array(obs.Theta, dtype=float), obs.delta2)


def relative_margin(obs: Observer) -> float:
    """The relative margin every strict inequality keeps: the scenario's, at least
    :data:`MIN_REL_MARGIN`.

    Parameters
    ----------
    obs : Observer
        The scenario's observer settings (its ``margin``).
    """
    return max(obs.margin, MIN_REL_MARGIN)


def theorem1_lambda2(obs: Observer, alpha: float) -> float:
    """λ2 ≥ α (Theorem 1): the scenario's, else (1 + margin)α.

    Parameters
    ----------
    obs : Observer
        The scenario's observer settings (its ``lambda2`` and ``margin``).
    alpha : float
        The bound on ‖u0‖.
    """
    return (1.0 + relative_margin(obs)) * alpha if obs.lambda2 is None else float(obs.lambda2)


def _theorem1_gains(
    obs: Observer, alpha: float, w: float, margin: float
) -> tuple[float, float, list[str]]:
    """λ1 > λ̄1/w and λ2 ≥ α (Theorem 1), given ones kept; the notes they raise."""
    lambda1 = (1.0 + margin) * obs.lambda_bar1 / w if obs.lambda1 is None else float(obs.lambda1)
    lambda2 = theorem1_lambda2(obs, alpha)
    if obs.lambda2 is None:
        return lambda1, lambda2, []
    notes = []
    if lambda2 == alpha:
        notes.append(
            "lambda2 = alpha: admissible only in the non-strict reading ||u0|| <= alpha <= lambda2"
            " (docs/fidelity.md, D6)"
        )
    return lambda1, lambda2, notes


def _solvers(t15: _Lmi15, orr: OmegaResult) -> dict[str, Any]:
    """Solver name(s), version(s), the tolerance of the loosest, and each LMI's record."""
    solvers = {"lmi15": asdict(t15.result.info), "lmi16": asdict(orr.info)}
    used = [s["solver"] for s in solvers.values()]
    solver = "CLARABEL" if all(s == "CLARABEL" for s in used) else "+".join(sorted(set(used)))
    version = "; ".join(sorted({f"{s['solver']} {s['version']}" for s in solvers.values()}))
    tol = max(SOLVER_TOL.get(s, max(SOLVER_TOL.values())) for s in used)
    return {"solver": solver, "solver_version": version, "solver_tol": tol, "lmi_solvers": solvers}


def _info(
    scenario: Scenario,
    lc: LeaderCheck,
    net: NetworkCheck,
    l3: Lemma3Result,
    t15: _Lmi15,
    orr: OmegaResult,
    margin: float,
    notes: list[str],
) -> dict[str, Any]:
    """Everything the run used and found, for ``gains.json``'s ``info``."""
    variants = {v.name: {"w": v.w, "z": v.z.tolist(), "detail": v.detail} for v in l3.variants}
    return {
        **_solvers(t15, orr),
        "lmi_eps": LMI_EPS,
        "scenario_sha256": scenario.sha256,
        "scenario_path": scenario.path,
        "scenario_name": scenario.name,
        "given": list(given_by(scenario)),
        "margin": margin,
        "lemma3": {"used": l3.used.name, "variants": variants, "skipped": l3.skipped},
        "invariant_zeros": [[float(s.real), float(s.imag)] for s in lc.zeros],
        "zeros_cross_check": lc.cross_check,
        "signed_graph": net.signed,
        "lambda_bar1_min_for_given_Q": t15.lb1_min,
        "lmi15_given_Q_feasible": t15.result.feasible,
        "lmi15_cap": t15.result.cap,
        "lmi16_given_Theta_feasible": orr.feasible,
        "notes": notes,
    }


def _with_k1(g: Gains, margin: float) -> Gains:
    """``g`` with k1 > λ_max(...)/(δ̂1δ̂2) by the relative margin, eq. (17)."""
    kb = k1_bound(g)
    return replace(g, k1=float((1.0 + margin) * kb), info={**g.info, "k1_bound": kb})  # eq. (17)


def _certified(g: Gains, name: str, strict: bool) -> Gains:
    """``g`` with its certificate; failures (and, strict, warnings) raise."""
    cert = certify(g, tol=g.info["solver_tol"], given=tuple(g.info["given"]))
    cert = replace(cert, notes=tuple(g.info["notes"]))
    if cert.failures():
        raise SynthesisError(
            f"synthesis of {name}: certificate fails: " + "; ".join(cert.failures())
        )
    if strict and cert.warnings():
        raise SynthesisError(
            f"synthesis of {name} (strict): given gains violate: " + "; ".join(cert.warnings())
        )
    return replace(g, certificate=cert.to_json())


def synthesize(scenario: Scenario, *, strict: bool = False) -> Gains:
    """Synthesise (or check) every observer gain of the scenario and certify the result.

    Gains the scenario marks ``"synthesize"`` are computed; gains it gives are kept
    and checked, and every condition they violate becomes a named warning in the
    certificate (an error when ``strict``).

    Parameters
    ----------
    scenario : Scenario
        A loaded scenario (``core.scenario.load_scenario``).
    strict : bool
        Turn warnings about given gains into a :class:`SynthesisError`.

    Returns
    -------
    Gains
        With ``certificate`` (every check, its margin, pass/fail, warnings) and
        ``info`` (solvers, ε, the scenario's SHA-256, both Lemma 3 variants, the zeros).

    Raises
    ------
    SynthesisError
        An assumption fails, an LMI for a synthesised quantity is infeasible, a
        synthesised quantity fails its certificate, or (strict) a given gain violates
        a condition. The message names the check.
    """
    lead, obs = scenario.leader, scenario.observer
    A0, B0, C0 = (np.array(M, dtype=float) for M in (lead.A0, lead.B0, lead.C0))
    margin = relative_margin(obs)
    lc = check_leader(A0, B0, C0)  # Assumption 2
    net = check_network(scenario.graph.adjacency, scenario.graph.pinning)  # Assumption 1
    l3 = lemma3(net.L_bar)  # both variants; the larger w is used
    Gamma, Phi = uio_matrices(B0, C0)  # eq. (7)
    t15 = _lmi15(obs, A0, B0)
    orr = _lmi16(obs, Phi, A0, C0, margin)
    # a synthesised λ1 serves every topology of a switching graph: the smallest w
    w_all = min(l3.used.w, switched_w_min(scenario, net.h))
    lambda1, lambda2, notes2 = _theorem1_gains(obs, lead.alpha, w_all, margin)
    info = _info(scenario, lc, net, l3, t15, orr, margin, [*t15.notes, *notes2])
    N = net.L_bar.shape[0]
    base = Gains(
        A0=A0,
        B0=B0,
        C0=C0,
        Gamma=Gamma,
        Phi=Phi,
        Theta=orr.Theta,
        Omega=orr.Omega,
        T=t15.result.T,
        Q=t15.result.Q,
        lambda_bar1=float(obs.lambda_bar1),
        delta1=float(obs.delta1),
        delta2=float(obs.delta2),
        delta1_hat=float(obs.delta1_hat),
        delta2_hat=float(obs.delta2_hat),
        L_bar=net.L_bar.toarray(),
        H=np.diag(net.h),
        Z=np.diag(l3.used.z) if N else np.zeros((0, 0)),
        w=float(l3.used.w),
        lambda1=float(lambda1),
        lambda2=float(lambda2),
        alpha=float(lead.alpha),
        k1=0.0,
        certificate={},
        info=info,
    )
    g = _certified(_with_k1(base, margin), scenario.name, strict)
    return _with_topologies(g, scenario)


def _with_topologies(g: Gains, scenario: Scenario) -> Gains:
    """``g`` with each switched topology's Lemma 3 w in ``info``; one that fails raises."""
    if not scenario.graph.switches:
        return g
    checks = check_topologies(scenario, g.h, g.lambda1, g.lambda_bar1)
    tops = [{"t_start": c.t_start, "w": c.w} for c in checks]
    return replace(g, info={**g.info, "switched_topologies": tops})
