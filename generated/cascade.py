"""The cascade integrator: the closed loop follower by follower, in C.

``integration.method = "cascade"`` integrates each follower's block
(:mod:`symbolic.cascade`) with its own CVODE (BDF) steps, along a topological order of
the (acyclic) graph; a follower reads the followers it hears through cubic Hermite
interpolation of the jets they stored at their steps (``generated/native/cascade.c``).

Why (measured, docs/performance.md): the whole closed loop's step count grows with N
(20k steps at N = 50, 52k at N = 2,000), because one global step must resolve every
follower's transients and the observers' turn-overs at their own moments. Follower by
follower, each block takes the steps its own solution needs, so the cost is the sum
of the followers' costs: linear in N for a fixed per-follower step count, and the
generated code is one block, the same for every N.

The library holds ``cas_rhs`` (the block, with its jets), ``cas_jac`` (its Jacobian
on the pattern of M = I − γJ), the sparse LU of M (:mod:`generated.sparse_lu`) and
``cas_faults``; it links SUNDIALS like the native integrator (:func:`generated.native.toolchain`).

What it does not do: graphs with cycles (a follower would hear one that hears it) and
followers with different models are refused with a one-line error naming the
alternatives; the interpolation adds an error of the order of the upstream steps'
local error (measured against the whole-loop reference in ``generated.precision``).
"""

from __future__ import annotations

import ctypes
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import casadi as ca
import numpy as np

from generated import native
from generated.codegen import CodegenSettings, Library, build_library
from generated.integrate import IntegratorSettings, Trajectory
from generated.sparse_lu import sparse_lu
from symbolic.cascade import Cascade

DRIVER = native.NATIVE_DIR / "cascade.c"
RHS_NAME, JAC_NAME, FAULTS_NAME = "cas_rhs", "cas_jac", "cas_faults"
#: the cascade driver's stats: the native ones, then its own (enum in cascade.c)
STATS = (*native.STATS, "jets_evals", "max_agent_steps", "peak_stored_rows", "failed_agent")


def cascade_functions(cas: Cascade, *, cse: bool = True) -> list[ca.Function]:
    """The Functions the cascade driver calls.

    Parameters
    ----------
    cas : Cascade
        From :func:`symbolic.cascade.build_cascade`.
    cse : bool
        Common-subexpression elimination in the generated code.

    Returns
    -------
    list of casadi.Function
        ``cas_rhs``, ``cas_jac``, ``nat_lu_factor``, ``nat_lu_solve``, ``cas_faults``.
    """
    b = cas.block
    args = b.sx_in()
    xbdot, jets = b.call(args)
    xb = args[1]
    J = ca.jacobian(xbdot, xb)
    pattern = J.sparsity() + ca.Sparsity.diag(xb.numel())
    opts = {"cse": True} if cse else {}
    names = b.name_in()
    rhs = ca.Function(RHS_NAME, args, [xbdot, jets], names, ["xbdot", "jets"], opts)
    jac = ca.Function(JAC_NAME, args, [ca.project(J, pattern)], names, ["J"], opts)
    lu = sparse_lu(pattern, native.LU_PREFIX, cse=cse)
    faults = cas.faults
    t = ca.SX.sym("t")
    flt = ca.Function(FAULTS_NAME, [t], [faults(t)], ["t"], ["values"], opts)
    return [rhs, jac, lu.factor, lu.solve, flt]


def build(cas: Cascade, settings: CodegenSettings | None = None) -> Library:
    """Compile (or reuse from the cache) the cascade library of a :class:`Cascade`.

    Parameters
    ----------
    cas : Cascade
    settings : CodegenSettings, optional
        Compiler, flags, cache root and ``cse``.

    Returns
    -------
    Library
        Pass ``Library.path`` to :func:`run`.
    """
    settings = settings or CodegenSettings()
    return build_library(
        cascade_functions(cas, cse=settings.cse), settings, toolchain=native.toolchain(DRIVER)
    )


def run(
    library: Path,
    cas: Cascade,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    *,
    breakpoints: Sequence[float] = (),
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate the closed loop follower by follower with the cascade driver.

    Parameters
    ----------
    library : Path
        The shared library (``Library.path``) built by :func:`build` for ``cas``.
    cas : Cascade
        Order, graph lists, per-agent numbers and the layout.
    x0 : ndarray
        The whole closed loop's initial state at ``t_out[0]``.
    t_out : ndarray
        Increasing output times.
    settings : IntegratorSettings
        ``rtol``, ``atol`` (every follower's CVODE) and ``max_steps`` (steps allowed
        between two output times, per follower).
    breakpoints : sequence of float
        Every follower restarts exactly at these times.
    progress : callable, optional
        Called once with the time reached.

    Returns
    -------
    Trajectory
        The whole state at ``t_out`` (the leader's from the first follower's run);
        incomplete (not raised) when a follower's CVODE gives up — every follower then
        stops where that one did. ``stats`` sums CVODE's counters over the followers and
        adds ``jets_evals``, ``max_agent_steps``, ``peak_stored_rows``, ``failed_agent``
        and ``agent_steps`` (a list, per follower).
    """
    wall0 = time.perf_counter()
    lib = native.load(Path(library))
    lay = cas.layout
    t_out = np.ascontiguousarray(t_out, dtype=float)
    x = np.ascontiguousarray(x0, dtype=float).ravel()
    nx, nt = x.size, len(t_out)
    if nx != lay.nx:
        raise ValueError(f"x0: {nx} entries, the cascade's layout has {lay.nx}")
    bps = np.ascontiguousarray(
        sorted(b for b in breakpoints if t_out[0] < b < t_out[-1]), dtype=float
    )
    X = np.full((nt, nx), np.nan)
    stats = np.zeros(len(STATS))
    steps = np.zeros(lay.N)
    msg = ctypes.create_string_buffer(native.MSG_LEN)

    def dptr(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def iptr(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_int))

    ints = [np.ascontiguousarray(a, dtype=np.int32) for a in
            (cas.order, cas.upstream_ptr, cas.upstream_idx, cas.fault_index.ravel())]  # fmt: skip
    w = np.ascontiguousarray(cas.upstream_weight, dtype=float)
    cpl = np.ascontiguousarray(cas.coupling, dtype=float)
    prm = np.ascontiguousarray(cas.params.T, dtype=float)  # agent-major
    filled = lib.hitl_cascade_run(
        lay.N, lay.m, lay.agent_size, cas.n, iptr(ints[0]), iptr(ints[1]), iptr(ints[2]),
        dptr(w), dptr(cpl), prm.shape[1], dptr(prm), iptr(ints[3]), dptr(x), nt,
        dptr(t_out), len(bps), dptr(bps), float(settings.rtol), float(settings.atol),
        int(settings.max_steps), dptr(X), dptr(stats), dptr(steps), msg, native.MSG_LEN,
    )  # fmt: skip
    return native.driver_trajectory(
        "cascade", filled, t_out, X, dict(zip(STATS, stats.tolist(), strict=True)),
        msg.value.decode(errors="replace"), wall0, progress,
        agent_steps=[int(v) for v in steps],
    )  # fmt: skip
