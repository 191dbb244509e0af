"""The native integrator at any N: the closed loop evaluated and solved in graph order.

The whole-loop native build (:mod:`generated.native`) is flat SX code: fine for a few
followers, but gcc needs minutes at N = 20 and does not finish at N = 50. This module
builds the same integration from *one follower's block* (:mod:`symbolic.cascade`), so
the generated C is the same size for every N:

* ``dag_rhs``: the block's right-hand side and the jets C0(η_i, η̇_i, η̈_i) its
  listeners need; the driver (``generated/native/dag.c``) evaluates the blocks in a
  topological order of the acyclic graph, each reading the jets computed before it in
  the same pass — the sum is the whole closed loop's right-hand side, nothing is
  interpolated;
* ``dag_jac``: the block's Jacobian with respect to its state and its neighbours' input;
  on an acyclic graph the closed loop's Jacobian is block lower triangular in that
  order, so CVODE's Newton systems are solved exactly by block forward substitution,
  factorising only the followers' diagonal blocks (linear in N, no fill-in);
* ``dag_faults``: every distinct fault expression once per evaluation.

One CVODE run (BDF) integrates the whole state with one step size, as the whole-loop
native driver does; the two agree to rounding in the right-hand side and the Jacobian
(tests/test_dag.py). Graphs with a cycle and followers of different models are refused
(:func:`symbolic.cascade.build_cascade`).
"""

from __future__ import annotations

import ctypes
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import casadi as ca
import numpy as np

from generated import native
from generated.codegen import Library, build_library
from generated.driver_probe import checked_state, probe_driver
from generated.values import CodegenSettings, IntegratorSettings, Trajectory
from symbolic.cascade import Cascade

DRIVER = native.NATIVE_DIR / "dag.c"
RHS_NAME, JAC_NAME, FAULTS_NAME = "dag_rhs", "dag_jac", "dag_faults"


def dag_functions(cas: Cascade, *, cse: bool = True) -> list[ca.Function]:
    """The three Functions the graph-ordered driver calls.

    Parameters
    ----------
    cas : Cascade
        From :func:`symbolic.cascade.build_cascade`.
    cse : bool
        Common-subexpression elimination in the generated code.

    Returns
    -------
    list of casadi.Function
        ``dag_rhs`` ``(t, xb, nb, cpl, prm, gf) -> (xbdot, jets)``, ``dag_jac``
        ``(...) -> (jets, K)`` with K = ∂(xbdot, jets)/∂(xb, nb) dense, and
        ``dag_faults`` ``t -> values``; ``jets`` (3n) are what ``nb`` sums.
    """
    b = cas.block
    args = b.sx_in()
    xbdot, jets = b.call(args)
    xb, nb = args[1], args[2]
    K = ca.densify(ca.jacobian(ca.vertcat(xbdot, jets), ca.vertcat(xb, nb)))
    opts = {"cse": True} if cse else {}
    names = b.name_in()
    rhs = ca.Function(RHS_NAME, args, [xbdot, jets], names, ["xbdot", "jets"], opts)
    jac = ca.Function(JAC_NAME, args, [jets, K], names, ["jets", "K"], opts)
    t = ca.SX.sym("t")
    flt = ca.Function(FAULTS_NAME, [t], [cas.faults(t)], ["t"], ["values"], opts)
    return [rhs, jac, flt]


def build(cas: Cascade, settings: CodegenSettings | None = None) -> Library:
    """Compile (or reuse from the cache) the graph-ordered native library.

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
        dag_functions(cas, cse=settings.cse), settings, toolchain=native.toolchain(DRIVER)
    )


def _problem(cas: Cascade) -> tuple[native.DagProblem, list[np.ndarray]]:
    """The driver's problem (``hitl_dag_problem``) and the arrays it points into (kept
    alive by the caller during the call)."""
    lay = cas.layout
    ints = [
        np.ascontiguousarray(a, dtype=np.int32)
        for a in (cas.order, cas.upstream_ptr, cas.upstream_idx, cas.fault_index.ravel())
    ]
    w = np.ascontiguousarray(cas.upstream_weight, dtype=float)
    cpl = np.ascontiguousarray(cas.coupling, dtype=float)
    prm = np.ascontiguousarray(cas.params.T, dtype=float)  # agent-major

    def ip(a: np.ndarray) -> ctypes._Pointer:
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_int))

    problem = native.DagProblem(
        N=lay.N,
        m=lay.m,
        na=lay.agent_size,
        n=cas.n,
        order=ip(ints[0]),
        up_ptr=ip(ints[1]),
        up_idx=ip(ints[2]),
        up_w=native.dptr(w),
        cpl=native.dptr(cpl),
        npar=prm.shape[1],
        prm=native.dptr(prm),
        fidx=ip(ints[3]),
    )
    return problem, [*ints, w, cpl, prm]


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
    """Integrate the closed loop with the graph-ordered native driver.

    Parameters
    ----------
    library : Path
        ``Library.path`` of :func:`build` for ``cas``.
    cas : Cascade
        Order, graph lists, per-agent numbers and the layout.
    x0 : ndarray
        The whole closed loop's initial state at ``t_out[0]``.
    t_out : ndarray
        Increasing output times.
    settings : IntegratorSettings
        ``rtol``, ``atol`` and ``max_steps`` (between two output times).
    breakpoints : sequence of float
        The run restarts exactly at these times, reconciled with ``t_out`` by
        :func:`generated.schedule.schedule`.
    progress : callable, optional
        Called once with the time reached.

    Returns
    -------
    Trajectory
        As :func:`generated.native.run` (method ``"native"``); ``lu_factorizations``
        counts the block set-ups and ``pivot_failures`` the singular diagonal blocks.

    Raises
    ------
    IntegrationError
        If ``x0`` has the wrong size or the driver could not start.
    """
    wall0 = time.perf_counter()
    lib = native.load(Path(library))
    x = checked_state(x0, cas.layout.nx)
    call = native.DriverCall.of(x.size, t_out, settings, breakpoints)
    problem, _keep = _problem(cas)
    lib.hitl_dag_run(
        ctypes.byref(problem),
        native.dptr(x),
        ctypes.byref(call.options),
        ctypes.byref(call.result),
    )
    return call.trajectory("native", wall0, progress)


def probe(
    library: Path, cas: Cascade, t: float, x: np.ndarray, gamma: float, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The driver's right-hand side at (t, x) and its solution of (I − γJ) sol = b.

    For tests: exactly what a run evaluates (one pass over the blocks) and solves
    (block forward substitution), to compare with the whole closed loop.

    Parameters
    ----------
    library : Path
        ``Library.path`` of :func:`build` for ``cas``.
    cas : Cascade
    t : float
    x, b : ndarray
        A state and a right-hand side of the Newton system (nx each).
    gamma : float
        CVODE's γ.

    Returns
    -------
    (xdot, sol) : (ndarray, ndarray)

    Raises
    ------
    IntegrationError
        Wrong sizes, or the driver failed (singular block, out of memory).
    """
    lib = native.load(Path(library))
    x, b = checked_state(x, cas.layout.nx), checked_state(b, cas.layout.nx)
    problem, _keep = _problem(cas)
    return probe_driver(lib.hitl_dag_probe, problem, t, x, gamma, b, "graph-ordered driver")
