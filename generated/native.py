"""The native integrator: generated C + SUNDIALS CVODE, with Python out of the loop.

``integration.method = "native"`` compiles, next to the closed loop's generated code,

* ``nat_rhs(t, x)``: the right-hand side (SX, common subexpressions eliminated),
* ``nat_jac(t, x)``: its Jacobian on the pattern of ``M = I − γJ`` (J's pattern plus
  the diagonal),
* ``nat_lu_factor``/``nat_lu_solve``: a sparse LU of M without pivoting, unrolled into
  straight-line code (:mod:`generated.sparse_lu`),

and a hand-written driver (``generated/native/driver.c``) that runs CVODE's BDF method
with these: a custom direct ``SUNLinearSolver`` on a ``SUNSparseMatrix``. The run is one
call from Python (ctypes). What this buys over CasADi's CVODES interface (measured in
docs/performance.md): CVODE re-evaluates J only when its heuristics ask for it (CasADi
recomputes it at every linear-solver setup), the factorisation has no symbolic phase
and no pivot search, and there is no per-output-time call overhead.

SUNDIALS comes from the ``scikit-sundae`` wheel (SUNDIALS 7.9 shared libraries, built
with 32-bit indices). Its wheel has no headers, so the 31 headers the driver needs are
vendored in ``generated/native/include`` (SUNDIALS 7.9.0, BSD-3-Clause, from the
official ``sundials4py`` 7.9.0 wheel; only ``sundials_config.h``'s index type is changed
to match scikit-sundae's build). Before every run ``hitl_native_check`` compares the
library's version with the headers' and reads back a matrix's dimensions, so a
mismatched SUNDIALS fails with a clear error instead of corrupting memory.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib.util
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import casadi as ca
import numpy as np

from core.errors import BuildError, IntegrationError
from generated.codegen import CodegenSettings, Library, Toolchain, build_library
from generated.integrate import IntegratorSettings, Trajectory, flag_reason, schedule
from generated.largescale import DIRECT_MAX_AGENTS
from generated.sparse_lu import SparseLU, sparse_lu

NATIVE_DIR = Path(__file__).resolve().parent / "native"
INCLUDE_DIR = NATIVE_DIR / "include"
COMMON = NATIVE_DIR / "common.c"
DRIVER = NATIVE_DIR / "driver.c"
#: the SUNDIALS libraries the driver links, from the scikit-sundae wheel
SUNDIALS_LIBRARIES = (
    "sundials_core",
    "sundials_cvode",
    "sundials_nvecserial",
    "sundials_sunmatrixsparse",
)
RHS_NAME, JAC_NAME, LU_PREFIX = "nat_rhs", "nat_jac", "nat_lu"
#: largest N the closed loop is built natively for (the direct plan's crossover): the
#: build is flat SX code; N = 20: 4.4 MB of C, gcc -O1 150–165 s; N = 50: 13 MB, gcc
#: unfinished after 13 min and 6 GB (docs/performance.md)
MAX_AGENTS = DIRECT_MAX_AGENTS
#: the driver's stats[] layout (enum in driver.c)
STATS = (
    "steps",
    "rhs_evals",
    "jac_evals",
    "lin_setups",
    "error_test_fails",
    "newton_iters",
    "newton_fails",
    "last_step",
    "lu_factorizations",
    "pivot_failures",
    "restarts",
    "flag",
    "t_reached",
)
MSG_LEN = 1024


def _sha256_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@functools.lru_cache(maxsize=2)
def toolchain(driver: Path = DRIVER) -> Toolchain:
    """The driver source, the vendored headers and scikit-sundae's SUNDIALS libraries.

    Parameters
    ----------
    driver : Path
        The driver appended after ``common.c`` (the shared linear solver and checks):
        ``driver.c`` (method ``native``) or ``dag.c`` (method ``native`` above the flat build's size, :mod:`generated.dag`).

    Returns
    -------
    Toolchain
        Its key holds the SHA-256 of every header and library, so a change to any of
        them rebuilds the native library.

    Raises
    ------
    BuildError
        If scikit-sundae (or one of its SUNDIALS libraries) is missing.
    """
    spec = importlib.util.find_spec("sksundae")
    if spec is None or spec.origin is None:
        raise BuildError(
            "integration.method 'native': scikit-sundae is not installed (it provides the "
            "SUNDIALS libraries; pip install -e '.[native]' as the Makefile does, or use "
            "method 'cvodes')"
        )
    libdir = Path(spec.origin).resolve().parent.parent / "scikit_sundae.libs"
    libs = []
    for name in SUNDIALS_LIBRARIES:
        found = sorted(libdir.glob(f"lib{name}-*.so*")) + sorted(libdir.glob(f"lib{name}.so*"))
        if not found:
            raise BuildError(
                f"integration.method 'native': lib{name} not found in {libdir} "
                "(reinstall scikit-sundae==1.2.*, or use method 'cvodes')"
            )
        libs.append(found[0])
    headers = sorted(p for p in INCLUDE_DIR.rglob("*.h"))
    key = {
        "headers": {str(p.relative_to(INCLUDE_DIR)): _sha256_file(p) for p in headers},
        "libraries": {p.name: _sha256_file(p) for p in libs},
    }
    source = COMMON.read_text() + "\n" + Path(driver).read_text()
    return Toolchain(source, (INCLUDE_DIR,), tuple(libs), key)


def native_functions(
    ode_dyn: ca.Function, *, cse: bool = True
) -> tuple[list[ca.Function], SparseLU]:
    """The four Functions the driver calls, built from the closed loop's ODE.

    Parameters
    ----------
    ode_dyn : casadi.Function
        Integrator form ``(t, x, z, p, u) -> (ode, alg, quad, zero)`` with empty z, p, u
        (``ClosedLoop.ode_dyn``); expanded to SX.
    cse : bool
        Common-subexpression elimination in the generated code.

    Returns
    -------
    (list of casadi.Function, SparseLU)
        ``nat_rhs``, ``nat_jac``, ``nat_lu_factor``, ``nat_lu_solve`` and the LU record.

    Raises
    ------
    BuildError
        If ``ode_dyn`` has algebraic states, parameters or controls, or cannot be expanded.
    """
    for i, what in ((2, "algebraic states z"), (3, "parameters p"), (4, "controls u")):
        if ode_dyn.nnz_in(i):
            raise BuildError(f"native integrator: {ode_dyn.name()} has {what} (needs an ODE)")
    try:
        f = ode_dyn if ode_dyn.is_a("SXFunction") else ode_dyn.expand()
    except RuntimeError:
        raise BuildError(
            f"native integrator: {ode_dyn.name()} cannot be expanded to SX "
            "(it calls an external function or a linear solver; use method 'cvodes')"
        ) from None
    nx = int(f.size1_in(1))
    t = ca.SX.sym("t")
    x = ca.SX.sym("x", nx)
    empty = ca.SX(0, 1)
    xdot = f(t, x, empty, empty, empty)[0]
    J = ca.jacobian(xdot, x)
    pattern = J.sparsity() + ca.Sparsity.diag(nx)
    jac = ca.project(J, pattern)  # structural zeros on the diagonal
    opts = {"cse": True} if cse else {}
    rhs_f = ca.Function(RHS_NAME, [t, x], [xdot], ["t", "x"], ["xdot"], opts)
    jac_f = ca.Function(JAC_NAME, [t, x], [jac], ["t", "x"], ["J"], opts)
    lu = sparse_lu(pattern, LU_PREFIX, cse=cse)
    return [rhs_f, jac_f, lu.factor, lu.solve], lu


def build(ode_dyn: ca.Function, settings: CodegenSettings | None = None) -> Library:
    """Compile (or reuse from the cache) the native library of any ODE.

    Parameters
    ----------
    ode_dyn : casadi.Function
        Integrator form with empty z, p, u (see :func:`native_functions`).
    settings : CodegenSettings, optional
        Compiler, flags, cache root and ``cse``.

    Returns
    -------
    Library
        Pass ``Library.path`` to :func:`run`.
    """
    settings = settings or CodegenSettings()
    functions, _ = native_functions(ode_dyn, cse=settings.cse)
    return build_library(functions, settings, toolchain=toolchain())


@functools.lru_cache(maxsize=16)
def load(path: Path) -> ctypes.CDLL:
    """Load a native (whole-loop or graph-ordered) library once per process and check its SUNDIALS.

    The path names a content-hashed cache entry, so what is loaded there never changes.

    Parameters
    ----------
    path : Path
        ``Library.path`` of a library built with :func:`toolchain`.

    Raises
    ------
    BuildError
        If the SUNDIALS it runs against differs from the vendored headers.
    """
    lib = ctypes.CDLL(str(path))
    lib.hitl_native_check.restype = ctypes.c_int
    lib.hitl_native_check.argtypes = [ctypes.c_char_p, ctypes.c_int]
    dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
    if hasattr(lib, "hitl_native_run"):
        lib.hitl_native_run.restype = ctypes.c_int
        lib.hitl_native_run.argtypes = [
            ctypes.c_int, dp, ctypes.c_int, dp, ctypes.c_int, dp, ctypes.c_double,
            ctypes.c_double, ctypes.c_long, dp, dp, ctypes.c_char_p, ctypes.c_int,
        ]  # fmt: skip
    if hasattr(lib, "hitl_dag_run"):
        ci = ctypes.c_int
        lib.hitl_dag_run.restype = ci
        lib.hitl_dag_run.argtypes = [
            ci, ci, ci, ci, ip, ip, ip, dp, dp, ci, dp, ip, dp, ci, dp, ci, dp,
            ctypes.c_double, ctypes.c_double, ctypes.c_long, dp, dp, ctypes.c_char_p, ci,
        ]  # fmt: skip
        lib.hitl_dag_probe.restype = ci
        lib.hitl_dag_probe.argtypes = [
            ci, ci, ci, ci, ip, ip, ip, dp, dp, ci, dp, ip, ctypes.c_double, dp,
            ctypes.c_double, dp, dp, dp, ctypes.c_char_p, ci,
        ]  # fmt: skip
    msg = ctypes.create_string_buffer(MSG_LEN)
    if not lib.hitl_native_check(msg, MSG_LEN):
        raise BuildError(
            f"native integrator: {msg.value.decode(errors='replace')} "
            "(install scikit-sundae==1.2.*, whose SUNDIALS 7.9 the vendored headers match)"
        )
    return lib


def run(
    library: Path,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    *,
    breakpoints: Sequence[float] = (),
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate with the native driver of a library built with :func:`toolchain`.

    Parameters
    ----------
    library : Path
        The shared library (``Library.path``) holding ``hitl_native_run``.
    x0 : ndarray
        Initial state at ``t_out[0]``.
    t_out : ndarray
        Increasing output times.
    settings : IntegratorSettings
        ``rtol``, ``atol`` and ``max_steps`` (steps allowed between two output times,
        as CVODES' ``max_num_steps``) are used.
    breakpoints : sequence of float
        The run restarts exactly at these times (CVODE stops there, then re-initialises),
        reconciled with ``t_out`` by :func:`generated.integrate.schedule`: an output time
        within its tolerance of a breakpoint is integrated to the breakpoint.
    progress : callable, optional
        Called once with the time reached (the run is one C call).

    Returns
    -------
    Trajectory
        Incomplete (not raised) when CVODE gives up; ``stats`` as for CVODES plus
        ``lu_factorizations`` and ``pivot_failures``.
    """
    wall0 = time.perf_counter()
    lib = load(Path(library))
    sched = schedule(t_out, breakpoints)  # rows keep t_out; the driver runs to the targets
    t_out, tq = sched.t_out, np.ascontiguousarray(sched.targets)
    bps = np.ascontiguousarray(sched.breaks)
    x = np.ascontiguousarray(x0, dtype=float).ravel()
    nx, nt = x.size, len(t_out)
    X = np.full((nt, nx), np.nan)
    stats = np.zeros(len(STATS))
    msg = ctypes.create_string_buffer(MSG_LEN)

    def ptr(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    filled = lib.hitl_native_run(
        nx, ptr(x), nt, ptr(tq), len(bps), ptr(bps), float(settings.rtol),
        float(settings.atol), int(settings.max_steps), ptr(X), ptr(stats), msg, MSG_LEN,
    )  # fmt: skip
    return driver_trajectory(
        "native", filled, t_out, X, dict(zip(STATS, stats.tolist(), strict=True)),
        msg.value.decode(errors="replace"), wall0, progress,
    )  # fmt: skip


def driver_trajectory(
    method: str,
    filled: int,
    t_out: np.ndarray,
    X: np.ndarray,
    stats: dict[str, float],
    text: str,
    wall0: float,
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """A :class:`Trajectory` from what a C driver returned (the native drivers).

    Parameters
    ----------
    method : str
        ``"native"``.
    filled : int
        Rows of ``X`` the driver filled (< 1: it could not start).
    t_out, X : ndarray
        Output times and the driver's output rows.
    stats : dict
        The driver's stats by name (:data:`STATS` and any extras).
    text : str
        The driver's message (``"FLAG_NAME: SUNDIALS message"`` on a failure).
    wall0 : float
        ``time.perf_counter()`` when the run began.
    progress : callable, optional
        Called once with the time reached.

    Raises
    ------
    IntegrationError
        If the driver could not start.
    """
    text = text.strip()
    nt = len(t_out)
    if filled < 1:
        raise IntegrationError(f"{method} integrator could not start: {text or 'unknown error'}")
    st = dict(stats)
    flag = int(st.pop("flag"))
    t_reached = float(t_out[filled - 1])
    st.pop("t_reached")
    out = {k: (v if k == "last_step" else int(v)) for k, v in st.items()}
    out.update(integrator_calls=1, jtimes_evals=0, wall_seconds=time.perf_counter() - wall0)
    message = ""
    if filled < nt:
        name, _, detail = text.partition(":")
        message = (
            f"{method} failed after t = {t_reached:.6g} s (working towards t = "
            f"{float(t_out[filled]):.6g} s): {flag_reason(name.strip() or str(flag))}"
            + (f" ({detail.strip()})" if detail.strip() else "")
        )
    if progress is not None:
        progress(t_reached)
    return Trajectory(
        t=t_out[:filled].copy(),
        x=X[:filled],
        z=None,
        method=method,
        complete=filled == nt,
        t_reached=t_reached,
        message=message,
        stats=out,
    )
