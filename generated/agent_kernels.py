"""The per-agent kernels: one follower model's compiled library, whatever the graph.

The kernels of ONE agent (:func:`symbolic.cascade.agent_block`) as C, with
``generated/native/agents.c`` appended (its header lists them); what is compiled in, and
so the library's identity, is :func:`kernel_key` (docs/performance.md).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from itertools import accumulate

import casadi as ca
import numpy as np

from core.memo import MEMO
from core.scenario import Scenario
from generated import native
from generated.codegen import Library, build_library
from generated.compiler import Toolchain
from generated.loaded import library_stamp
from generated.sparse_lu import sparse_lu
from generated.values import CodegenSettings
from symbolic.cascade import agent_block
from symbolic.closed_loop import make_layout, model_groups, observer_gains
from symbolic.parameters import row_layout, structure
from synthesis.gains import Gains

#: the kernels, in the order of the driver's table (``AG_*`` in agents.c)
KERNELS = ("ag_jet0", "ag_jet1", "ag_jet2", "ag_rhs", "ag_jac", "ag_nfac", "ag_nsol", "ag_gmat")


def kernel_functions(
    sc: Scenario, gains: Gains, model_index: int, *, cse: bool = True
) -> list[ca.Function]:
    """The kernels of one follower model (:data:`KERNELS`), as CasADi Functions.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    model_index : int
        0-based follower whose model and parameters the kernels use.
    cse : bool
    """
    lay = make_layout(sc.m, sc.n, 1, sc.options.derivatives == "filtered")
    block = agent_block(sc, observer_gains(sc, gains), lay, model_index)
    args = block.sx_in()
    xbdot, jets = block.call(args)
    n = sc.n
    xb, nb = args[1], args[2]
    # K's structural nonzeros only: the driver stores and reads them contiguously
    K = ca.jacobian(ca.vertcat(xbdot, jets), ca.vertcat(xb, nb))
    opts = {"cse": True} if cse else {}
    names = block.name_in()
    fns = [
        ca.Function(f"ag_jet{lev}", args, [jets[lev * n : (lev + 1) * n]], names, ["jet"], opts)
        for lev in range(3)
    ]
    fns.append(ca.Function("ag_rhs", args, [xbdot, jets], names, ["xbdot", "jets"], opts))
    fns.append(ca.Function("ag_jac", args, [jets, K], names, ["jets", "K"], opts))
    return fns + _newton_functions(K.sparsity(), sc.m, 3 * n, opts)


def _newton_functions(pattern: ca.Sparsity, m: int, n3: int, opts: dict) -> list[ca.Function]:
    """``ag_nfac``, ``ag_nsol``, ``ag_gmat`` on K's structural ``pattern`` (agents.c, header).

    K's rows are (leader's rates, agent's rates, jets), its columns (leader's state,
    agent's state, neighbour sums): blocks A_s0, A_ss, B_s and C_0, C_s, E. The
    factorisation packs all a solve reads into one vector P, the LU of D = I + c A_ss
    without pivoting and with U's diagonal inverted (the driver checks the pivots),
    followed by c A_s0, c B_s, C_0, C_s and E: a solve then reads one contiguous block per
    agent and divides nowhere.
    """
    k = pattern.size1()
    na = k - m - n3
    st, jt = slice(m, m + na), slice(m + na, k)
    sub = ca.SX.sym("K", pattern)  # K's nonzeros, as ag_jac writes them
    c = ca.SX.sym("c")
    A_ss = sub[st, st]
    lu = sparse_lu(
        A_ss.sparsity() + ca.Sparsity.diag(na), "ag_dlu", cse=bool(opts), reciprocal=True
    )
    LU, pivots = lu.factor(ca.project(ca.SX.eye(na) + c * A_ss, lu.pattern))
    blocks = [LU, c * sub[st, :m], c * sub[st, jt], sub[jt, :m], sub[jt, st], sub[jt, jt]]
    P = ca.vertcat(*(blk.nz[:] for blk in blocks))
    Ps = ca.SX.sym("P", P.numel())
    at = [0, *accumulate(blk.nnz() for blk in blocks)]  # the blocks' slices of P
    LUs, cA_s0, cB_s, C_0, C_s, E = (
        ca.SX(blk.sparsity(), Ps[at[q] : at[q + 1]]) for q, blk in enumerate(blocks)
    )
    x0, s, b = ca.SX.sym("x0", m), ca.SX.sym("s", n3), ca.SX.sym("b", na)
    x = lu.solve(LUs, b - (cA_s0 @ x0 + cB_s @ s))
    dj = C_0 @ x0 + C_s @ x + E @ s
    H = ca.densify(-ca.horzcat(*(lu.solve(LUs, ca.densify(cB_s[:, q])) for q in range(n3))))
    G = ca.densify(E + C_s @ H)  # x = D⁻¹ (b − c A_s0 x0) + H s
    return [
        ca.Function("ag_nfac", [c, sub], [P, pivots], ["c", "K"], ["P", "pivots"], opts),
        ca.Function("ag_nsol", [Ps, x0, s, b], [x, dj], ["P", "x0", "s", "b"], ["x", "dj"], opts),
        ca.Function("ag_gmat", [Ps], [G, H], ["P"], ["G", "H"], opts),
    ]


def _kernel_settings(settings: CodegenSettings | None, openmp: bool) -> CodegenSettings:
    """``settings`` for the kernels: at their optimisation, with OpenMP's flags if threaded
    (a serial build has no OpenMP region: at small N entering one costs more than a pass)."""
    s = settings or CodegenSettings()
    extra = tuple(s.extra_cflags)
    if openmp and "-fopenmp" not in extra:
        extra += ("-fopenmp",)
    return dataclasses.replace(
        s,
        optimization=s.kernel_optimization,
        extra_cflags=extra,
        jacobian="sparse",
        expand=True,
    )


#: kernel libraries built in this process, by :func:`kernel_key` (core/memo.py)
_BUILT = MEMO.namespace("agent-kernels", 64)
#: the gains the kernels compile in: the leader's matrices (the observer's Q, λ1, λ2 and
#: UIO are runtime numbers on their patterns, symbolic.parameters.row_layout)
KERNEL_GAINS = ("A0", "B0", "C0")


def kernel_key(
    sc: Scenario,
    gains: Gains,
    model_index: int,
    settings: CodegenSettings | None = None,
    openmp: bool = False,
) -> str:
    """SHA-256 of everything the kernels of one model compile in (never the graph, never N).

    Two scenarios with equal keys compile to the same library: this process builds it once
    (the build cache keys it again by its source).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    model_index : int
    settings : CodegenSettings, optional
    openmp : bool
    """
    st = structure(sc, gains)
    fo = sc.followers[model_index]
    desc = {
        # the leader's u0 as templates (its literals are row columns); the observer's
        # settings enter only through the gains (their patterns: "rows")
        "structure": {
            k: v for k, v in st.items() if k not in ("graph", "followers", "gains", "observer")
        },
        "gains": {k: np.asarray(getattr(gains, k), float).tolist() for k in KERNEL_GAINS},
        "model": [fo.model, sorted(fo.params.items())],
        # the fault templates, the gains' patterns, the row's sizes
        "rows": row_layout(sc, observer_gains(sc, gains)).key(),
        "driver": hashlib.sha256(
            (native.COMMON.read_text() + native.DRIVER.read_text()).encode()
        ).hexdigest(),
        "settings": repr(_kernel_settings(settings, openmp)),
    }
    return hashlib.sha256(json.dumps(desc, sort_keys=True, default=str).encode()).hexdigest()


def _driver_toolchain(sc: Scenario) -> Toolchain:
    """The driver compiled for one follower's sizes (``HITL_AG_*`` in agents.c: gcc unrolls
    the per-agent loops; the driver refuses a problem of other sizes)."""
    tc = native.toolchain()
    na = make_layout(sc.m, sc.n, sc.N, sc.options.derivatives == "filtered").agent_size
    sizes = (
        f"#define HITL_AG_N_LEADER {sc.m}\n#define HITL_AG_N_STATE {na}\n"
        f"#define HITL_AG_N_OUT {sc.n}\n"
    )
    return dataclasses.replace(tc, appended_source=sizes + tc.appended_source)


def build_models(
    sc: Scenario, gains: Gains, settings: CodegenSettings | None = None, openmp: bool = False
) -> tuple[list[Library], np.ndarray]:
    """Compile (or reuse from this process or the cache) one kernel library per follower model.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    settings : CodegenSettings, optional
    openmp : bool
        A threaded build, needed for ``LinearSettings.threads`` above 1.

    Returns
    -------
    libraries : list of Library
        One per model group (:func:`symbolic.closed_loop.model_groups`), in group order.
    model : ndarray
        N ints: the library of each follower.
    """
    s = _kernel_settings(settings, openmp)
    groups = model_groups(sc)
    model = np.zeros(sc.N, dtype=np.int32)
    libs = []
    for g, members in enumerate(groups):
        model[members] = g
        key = kernel_key(sc, gains, members[0], settings, openmp)
        lib, stamp = _BUILT.get(key) or (None, None)
        if lib is None or library_stamp(lib) != stamp:  # its entry changed: check, rebuild
            fns = kernel_functions(sc, gains, members[0], cse=s.cse)
            lib = build_library(fns, s, toolchain=_driver_toolchain(sc))
            _BUILT[key] = (lib, library_stamp(lib))
        else:
            lib = dataclasses.replace(lib, cache_hit=True, codegen_seconds=0.0, compile_seconds=0.0)
        libs.append(lib)
    return libs, model
