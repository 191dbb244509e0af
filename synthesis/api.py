"""``synthesize(scenario) -> Gains``: assumptions, Lemma 3, LMIs (15)–(16), gains, certificate."""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from typing import Any

import numpy as np

from core.errors import SynthesisError
from core.graph import check_network
from core.scenario import Scenario
from synthesis.assumptions import check_leader, uio_matrices
from synthesis.certificate import certify, k1_bound
from synthesis.gains import Gains
from synthesis.lemma3 import lemma3
from synthesis.lmi import (
    LMI_EPS,
    SOLVER_TOL,
    check_given_Q,
    check_given_Theta,
    min_lambda_bar1_for_Q,
    synth_Omega_Theta,
    synth_T,
)

MIN_REL_MARGIN = 1e-3  # strict inequalities (λ1 > λ̄1/w, k1 > bound) keep at least this margin


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
    lead, graph, obs = scenario.leader, scenario.graph, scenario.observer
    A0 = np.array(lead.A0, dtype=float)
    B0 = np.array(lead.B0, dtype=float)
    C0 = np.array(lead.C0, dtype=float)
    lb1, d1, d2 = obs.lambda_bar1, obs.delta1, obs.delta2
    margin = max(obs.margin, MIN_REL_MARGIN)

    # Assumptions 2 and 1
    lc = check_leader(A0, B0, C0)
    net = check_network(graph.adjacency, graph.pinning)
    # Lemma 3 (both variants; the larger w is used)
    l3 = lemma3(net.L_bar)
    z, w = l3.used.z, l3.used.w
    Gamma, Phi = uio_matrices(B0, C0)  # eq. (7)

    given: list[str] = []
    solvers: dict[str, dict[str, Any]] = {}
    notes: list[str] = []
    # LMI (15): Q synthesised from T, or the given Q checked (an LMI in T⁻¹)
    if obs.Q is None:
        tr = synth_T(A0, B0, lb1, d1)
        lb1_min = None
    else:
        given.append("Q")
        Qg = np.array(obs.Q, dtype=float)
        tr = check_given_Q(A0, B0, Qg, lb1, d1)
        lb1_min = min_lambda_bar1_for_Q(A0, B0, Qg, d1)
        notes.append(
            f"given Q satisfies LMI (15) with delta1 = {d1:g} exactly for lambda_bar1 > {lb1_min:.6g}"
            f" (solver bound; lambda1 = {obs.lambda1 if obs.lambda1 is not None else 'synth'}"
            f" then needs w > {lb1_min / obs.lambda1 if obs.lambda1 else math.nan:.4g})"
        )
    solvers["lmi15"] = asdict(tr.info)
    # LMI (16): Ω and Θ jointly, or Ω for the given Θ
    if obs.Theta is None:
        orr = synth_Omega_Theta(Phi, A0, C0, d2, rel_margin=margin)
    else:
        given.append("Theta")
        orr = check_given_Theta(Phi, A0, C0, np.array(obs.Theta, dtype=float), d2)
    solvers["lmi16"] = asdict(orr.info)

    # Theorem 1's gains
    if obs.lambda1 is None:
        lambda1 = (1.0 + margin) * lb1 / w  # λ1 > λ̄1/w
    else:
        given.append("lambda1")
        lambda1 = float(obs.lambda1)
    if obs.lambda2 is None:
        lambda2 = (1.0 + margin) * lead.alpha  # λ2 ≥ α
    else:
        given.append("lambda2")
        lambda2 = float(obs.lambda2)
        if lambda2 == lead.alpha:
            notes.append(
                "lambda2 = alpha: admissible only in the non-strict reading ||u0|| <= alpha <= lambda2"
                " (docs/fidelity.md, D6)"
            )

    used = [s["solver"] for s in solvers.values()]
    solver = "CLARABEL" if all(s == "CLARABEL" for s in used) else "+".join(sorted(set(used)))
    version = "; ".join(sorted({f"{s['solver']} {s['version']}" for s in solvers.values()}))
    tol = max(SOLVER_TOL.get(s, max(SOLVER_TOL.values())) for s in used)
    info: dict[str, Any] = {
        "solver": solver,
        "solver_version": version,
        "solver_tol": tol,
        "lmi_eps": LMI_EPS,
        "lmi_solvers": solvers,
        "scenario_sha256": scenario.sha256,
        "scenario_path": scenario.path,
        "scenario_name": scenario.name,
        "given": given,
        "margin": margin,
        "lemma3": {
            "used": l3.used.name,
            "variants": {
                v.name: {"w": v.w, "z": v.z.tolist(), "detail": v.detail} for v in l3.variants
            },
            "skipped": l3.skipped,
        },
        "invariant_zeros": [[float(s.real), float(s.imag)] for s in lc.zeros],
        "zeros_cross_check": lc.cross_check,
        "signed_graph": net.signed,
        "lambda_bar1_min_for_given_Q": lb1_min,
        "lmi15_given_Q_feasible": tr.feasible,
        "lmi15_cap": tr.cap,
        "lmi16_given_Theta_feasible": orr.feasible,
        "notes": notes,
    }
    N = net.L_bar.shape[0]
    base = Gains(
        A0=A0,
        B0=B0,
        C0=C0,
        Gamma=Gamma,
        Phi=Phi,
        Theta=orr.Theta,
        Omega=orr.Omega,
        T=tr.T,
        Q=tr.Q,
        lambda_bar1=float(lb1),
        delta1=float(d1),
        delta2=float(d2),
        delta1_hat=float(obs.delta1_hat),
        delta2_hat=float(obs.delta2_hat),
        L_bar=net.L_bar.toarray(),
        H=np.diag(net.h),
        Z=np.diag(z) if N else np.zeros((0, 0)),
        w=float(w),
        lambda1=float(lambda1),
        lambda2=float(lambda2),
        alpha=float(lead.alpha),
        k1=0.0,
        certificate={},
        info=info,
    )
    kb = k1_bound(base)
    k1 = (1.0 + margin) * kb  # k1 > λ_max(...)/(δ̂1δ̂2), eq. (17)
    info["k1_bound"] = kb
    g = replace(base, k1=float(k1))
    cert = certify(g, tol=tol, given=tuple(given))
    cert["notes"] = notes
    g = replace(g, certificate=cert)
    if cert["failures"]:
        raise SynthesisError(
            f"synthesis of {scenario.name}: certificate fails: " + "; ".join(cert["failures"])
        )
    if strict and cert["warnings"]:
        raise SynthesisError(
            f"synthesis of {scenario.name} (strict): given gains violate: "
            + "; ".join(cert["warnings"])
        )
    return g
