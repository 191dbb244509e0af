"""A sample's gains certified on its base graph, and Theorem 1 on every topology as columns.

With ``[graph.losses] theorem1 = "measured"`` a sample's gains are certified on its base
graph (:func:`base_graph_gains`) and every topology's Theorem 1 condition λ1 w_k > λ̄1
(the paper's z) is a column (:func:`topology_columns`) instead of a refusal of the
sample: method ``native`` compiles the observer gains into its kernels, and a study of
many graphs on one library keeps the given λ1 (a synthesized λ1 compiles per sample).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from core.scenario import Scenario
    from synthesis.gains import Gains


def base_graph_gains(sc: Scenario, where: str) -> Gains:
    """Gains certified for ``sc`` on its base graph (its switches left out), for ``sc``.

    The given gains' conditions on the base graph are the certificate's warnings as for
    any scenario; the switched topologies' Theorem 1 condition is measured by
    :func:`topology_columns`, not required.

    Parameters
    ----------
    sc : Scenario
    where : str
        Names the gains in messages.
    """
    from generated import api

    base = dataclasses.replace(sc, graph=dataclasses.replace(sc.graph, switches=()))
    g = api.scenario_gains(base, where)
    return dataclasses.replace(g, info={**g.info, "scenario_sha256": sc.sha256})


def topology_columns(sc: Scenario, gains: Gains) -> dict[str, Any]:
    """Theorem 1's condition on every topology of ``sc``'s graph with ``gains``' λ1.

    Lemma 3's w of each topology with the paper's z = (L̄ᵀ)⁻¹1 (no optimisation: the
    synthesis stage's best diagonal Z may find a larger w, so ``False`` is "not shown
    with the paper's z", not a proof of failure).

    Parameters
    ----------
    sc : Scenario
    gains : Gains

    Returns
    -------
    dict
        ``topologies`` (the base graph and one per switching time), ``w_min`` (the
        smallest w over them) and ``theorem1`` (λ1 w_k > λ̄1 on every one).
    """
    from synthesis.lemma3 import lemma3_z, w_of
    from synthesis.switching import topology_L_bar

    tops = sc.graph.topologies()
    ws = []
    for top in tops:
        L = topology_L_bar(top, gains.h)
        ws.append(float(w_of(L, lemma3_z(L))))
    w = min(ws)
    return {
        "topologies": len(tops),
        "w_min": w,
        "theorem1": bool(gains.lambda1 * w > gains.lambda_bar1),
    }
