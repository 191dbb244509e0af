"""Switching topology: every graph a run reaches re-checked against the certified gains.

Outside the paper's theorems (docs/fidelity.md, 'Switching topology'). The gains are
certified for the base graph (Assumption 1, Lemma 3, λ1 > λ̄1/w). For each topology of
``scenario.graph.topologies()`` after the first, the same conditions are checked with
the same observer gains:

* Assumption 1: every follower reachable from the leader, the signed graph structurally
  balanced, and its gauge h equal to the gains' H (the observer's sign convention);
* Lemma 3 on that topology's L̄_k = H(L_k + B_k)H, and λ1·w_k > λ̄1 (the condition of
  Theorem 1 for a V1 built on that topology's Z_k).

Each holds segment by segment only: a common Lyapunov function for all topologies is
not claimed (docs/verification.md, 'Switching topology').
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from core.errors import SynthesisError
from core.graph import Topology, pinned_laplacian, topology_violation
from core.scenario import Scenario
from synthesis.lemma3 import BEST_Z_MAX_N, lemma3, lemma3_z, w_of


@dataclass(frozen=True)
class TopologyCheck:
    """One switched topology that passed.

    Attributes
    ----------
    t_start : float
        When it starts to hold (s).
    w : float
        Lemma 3's w of its L̄_k (the paper's z, or the best diagonal Z when that is needed).
    need : float
        λ̄1/λ1: Theorem 1's condition is w > need.
    """

    t_start: float
    w: float
    need: float


def _switch_key(scenario: Scenario, t: float) -> str:
    """``graph.switches[k]`` of the first switch (1-based, file order) acting at ``t``."""
    k = next(k for k, s in enumerate(scenario.graph.switches) if s.time == t)
    return f"graph.switches[{k + 1}]"


def topology_L_bar(top: Topology, h: np.ndarray) -> sp.csr_matrix:
    """L̄_k = H(L_k + B_k)H of one topology (Lemma 3, Remark 2).

    Parameters
    ----------
    top : Topology
        From ``Graph.topologies()``.
    h : ndarray
        The gauge (the gains' H).
    """
    Hs = sp.diags(np.asarray(h, dtype=float))
    return sp.csr_matrix(Hs @ pinned_laplacian(top.adjacency, top.pinning) @ Hs)


def topology_w(L_bar: sp.csr_matrix, need: float = np.inf) -> float:
    """Lemma 3's w of ``L_bar``: the paper's z first, the best diagonal Z when w <= ``need``.

    Parameters
    ----------
    L_bar : sparse matrix
        N×N, a nonsingular M-matrix (Assumption 1 checked before).
    need : float
        The w to exceed; the cvxpy maximisation runs only when the paper's z falls short
        (``inf``: always, up to N = BEST_Z_MAX_N).
    """
    w = w_of(L_bar, lemma3_z(L_bar))
    if w > need or L_bar.shape[0] > BEST_Z_MAX_N:
        return w
    return max(w, lemma3(L_bar).used.w)


def switched_w_min(scenario: Scenario, h: np.ndarray) -> float:
    """The smallest Lemma 3 w over the switched topologies (``inf`` without switches).

    Used to synthesise λ1 > λ̄1/w for every topology at once.

    Parameters
    ----------
    scenario : Scenario
        Its graph and switches.
    h : ndarray
        The base graph's gauge.

    Raises
    ------
    SynthesisError
        A topology breaks Assumption 1 or changes the gauge (named by its switch and time).
    """
    w_min = np.inf
    for top in scenario.graph.topologies()[1:]:
        _assumption1(scenario, top, h)
        w_min = min(w_min, topology_w(topology_L_bar(top, h)))
    return float(w_min)


def _assumption1(scenario: Scenario, top: Topology, h: np.ndarray) -> None:
    why = topology_violation(top.adjacency, top.pinning, h)
    if why is not None:
        raise SynthesisError(
            f"{_switch_key(scenario, top.t_start)}: from t = {top.t_start:g} s {why}; "
            "every topology must keep a spanning tree rooted at the leader and the gauge"
        )


def check_topologies(
    scenario: Scenario, h: np.ndarray, lambda1: float, lambda_bar1: float
) -> tuple[TopologyCheck, ...]:
    """Assumption 1, the gauge and λ1·w_k > λ̄1 for every switched topology of the run.

    Parameters
    ----------
    scenario : Scenario
        Its graph and switches (nothing is checked without switches).
    h : ndarray
        The certified gauge (diagonal of the gains' H).
    lambda1, lambda_bar1 : float
        The observer gain and the LMI (15) parameter the gains are certified with.

    Returns
    -------
    tuple of TopologyCheck
        One per switched topology, in time order.

    Raises
    ------
    SynthesisError
        One line naming the switch, its time and what broke.
    """
    need = lambda_bar1 / lambda1
    out = []
    for top in scenario.graph.topologies()[1:]:
        _assumption1(scenario, top, h)
        w = topology_w(topology_L_bar(top, h), need)
        if not w > need:  # Theorem 1: λ1 > λ̄1/w
            raise SynthesisError(
                f"{_switch_key(scenario, top.t_start)}: from t = {top.t_start:g} s Lemma 3 "
                f"gives w = {w:.4g}, so lambda1 = {lambda1:g} is not above "
                f"lambda_bar1 / w = {lambda_bar1 / w:.4g} (Theorem 1); give observer.lambda1 > "
                f"{lambda_bar1 / w:.4g} (or 'synthesize') or keep more links"
            )
        out.append(TopologyCheck(top.t_start, w, need))
    return tuple(out)
