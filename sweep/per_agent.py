"""A study's samples on the per-agent engine at every N (a study file's ``per_agent = true``).

Method ``native`` runs the per-agent engine (:mod:`generated.agents`) above
:data:`generated.native.MAX_AGENTS` followers and the whole-loop driver, compiled per
graph, up to it. A study of many graphs sets ``per_agent = true`` to run every sample on
the per-agent engine: one kernel library per follower model for the whole study (the
first sample compiles it), the sample's graph, N and switching as runtime data. The run's
outputs are the symbolic closed loop's, evaluated by CasADi's virtual machine, as for
``native`` above N = 20; the checks are those of every study.

With ``[graph.losses] theorem1 = "measured"`` a sample's gains are certified on its base
graph and every topology's Theorem 1 condition λ1 w_k > λ̄1 (the paper's z) is a column
(:func:`topology_columns`) instead of a refusal of the sample: the kernels compile the
given λ1 in, and a study on one library keeps it.
"""

from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from core.scenario import Scenario
    from generated.built import Built
    from generated.values import CodegenSettings
    from synthesis.gains import Gains


def build(sc: Scenario, gains: Gains, codegen: CodegenSettings) -> Built:
    """``sc`` bound to the per-agent kernels of its follower models (built or reused).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
        Certified for ``sc`` (the kernels compile the observer gains and the UIO in).
    codegen : CodegenSettings
        Compiler settings and cache root of the kernels.

    Returns
    -------
    Built
        Method ``native`` with :attr:`~generated.built.Built.agents` set: what
        :func:`generated.api.simulate` runs on the per-agent engine.
    """
    from generated import agents
    from generated.built import Built
    from symbolic.closed_loop import closed_loop_for, fix_parameters

    t0 = time.perf_counter()
    cl = closed_loop_for(sc, gains)
    libs, model = agents.build_models(sc, gains, codegen)
    prob = agents.problem(sc, gains, model)
    codegen_s = sum(lib.codegen_seconds for lib in libs)
    compile_s = sum(lib.compile_seconds for lib in libs)
    lib = dataclasses.replace(
        libs[0],
        cache_hit=all(lib.cache_hit for lib in libs),
        codegen_seconds=codegen_s,
        compile_seconds=compile_s,
    )
    timings = {
        "symbolic_build": time.perf_counter() - t0 - codegen_s - compile_s,
        "codegen": codegen_s,
        "compile": compile_s,
    }
    par = cl.parametric
    if par is None:
        return Built(cl, lib, cl.ode_dyn, cl.outputs, "ode", timings, agents=(tuple(libs), prob))
    p = np.asarray(cl.p0, dtype=float)
    return Built(
        cl,
        lib,
        fix_parameters(par.ode_dyn, p),
        fix_parameters(par.outputs, p),
        "ode",
        timings,
        agents=(tuple(libs), prob),
        p=p,
        dyn_p=par.ode_dyn,
        outputs_p=par.outputs,
    )


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
