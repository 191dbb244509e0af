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

The drivers take one options struct and fill one result struct, defined once in
``generated/native/hitl_native.h`` and mirrored here (:class:`Options`,
:class:`Result`); a library reports the sizes it was compiled
with (``hitl_struct_size``) and :func:`load` refuses one that differs from the mirror.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import casadi as ca
import numpy as np

from core.errors import BuildError, IntegrationError
from core.memo import MEMO
from generated.codegen import Library, Toolchain, build_library, preload
from generated.largescale import DIRECT_MAX_AGENTS
from generated.schedule import Schedule, schedule
from generated.sparse_lu import SparseLU, sparse_lu
from generated.sundials_log import new_sundials_log, take_sundials_log
from generated.values import (
    CodegenSettings,
    IntegratorSettings,
    Status,
    Trajectory,
    flag_reason,
    flag_status,
)

NATIVE_DIR = Path(__file__).resolve().parent / "native"
INCLUDE_DIR = NATIVE_DIR / "include"
COMMON = NATIVE_DIR / "common.c"
DRIVER = NATIVE_DIR / "driver.c"
#: the drivers' calling convention (options, result)
HEADER = NATIVE_DIR / "hitl_native.h"
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
#: the result's message buffer (HITL_MSG_LEN in hitl_native.h)
MSG_LEN = 1024
_DP, _IP = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)


class Options(ctypes.Structure):
    """``hitl_options`` of ``hitl_native.h``: what a driver run is asked to do."""

    _fields_ = [
        ("rtol", ctypes.c_double),
        ("atol", ctypes.c_double),
        ("max_steps", ctypes.c_long),
        ("nt", ctypes.c_int),
        ("t_out", _DP),
        ("nb", ctypes.c_int),
        ("breaks", _DP),
        ("np", ctypes.c_int),
        ("p", _DP),
        ("log_path", ctypes.c_char_p),
    ]


#: the result's counters, in ``hitl_result`` order (Trajectory.stats keys)
COUNTERS = (
    "steps",
    "rhs_evals",
    "jac_evals",
    "lin_setups",
    "error_test_fails",
    "newton_iters",
    "newton_fails",
    "lu_factorizations",
    "pivot_failures",
    "restarts",
)


class Result(ctypes.Structure):
    """``hitl_result`` of ``hitl_native.h``: the output rows, counters, flag and message."""

    _fields_ = [
        ("x_out", _DP),
        ("x_stop", _DP),
        ("filled", ctypes.c_int),
        ("flag", ctypes.c_int),
        ("t_reached", ctypes.c_double),
        ("t_stop", ctypes.c_double),
        ("last_step", ctypes.c_double),
        *((name, ctypes.c_long) for name in COUNTERS),
        ("msg", ctypes.c_char * MSG_LEN),
    ]


#: the mirrored structs, by ``hitl_struct_size``'s argument (HITL_*_SIZE)
STRUCTS = (Options, Result)


def _sha256_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@MEMO.memoize("native-toolchain", 2)
def toolchain(driver: Path = DRIVER) -> Toolchain:
    """The driver source, the vendored headers and scikit-sundae's SUNDIALS libraries.

    Parameters
    ----------
    driver : Path
        The driver appended after ``common.c`` (the shared linear solver and checks):
        ``driver.c`` (the whole loop) or ``agents.c`` (the per-agent engine,
        :mod:`generated.agent_kernels`).

    Returns
    -------
    Toolchain
        Its key holds the SHA-256 of every header and library, so a change to any of
        them rebuilds the native library. The libraries are those of the running
        interpreter's scikit-sundae, in dependency order (``sundials_core`` first); a
        built library names them by soname only and they are preloaded before it
        (:func:`generated.codegen.preload`): the same key means the same files, so an
        entry built from another checkout's environment loads here.

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
        "interface": {HEADER.name: _sha256_file(HEADER)},
    }
    source = COMMON.read_text() + "\n" + Path(driver).read_text()
    return Toolchain(source, (NATIVE_DIR, INCLUDE_DIR), tuple(libs), key)


def native_functions(
    ode_dyn: ca.Function, *, cse: bool = True
) -> tuple[list[ca.Function], SparseLU]:
    """The four Functions the driver calls, built from the closed loop's ODE.

    Parameters
    ----------
    ode_dyn : casadi.Function
        Integrator form ``(t, x, z, p, u) -> (ode, alg, quad, zero)`` with empty z and u
        (``ClosedLoop.parametric.ode_dyn``); expanded to SX. Its parameters p become the
        third input of ``nat_rhs`` and ``nat_jac``, given to :func:`run` at run time.
    cse : bool
        Common-subexpression elimination in the generated code.

    Returns
    -------
    (list of casadi.Function, SparseLU)
        ``nat_rhs``, ``nat_jac``, ``nat_lu_factor``, ``nat_lu_solve`` and the LU record.

    Raises
    ------
    BuildError
        If ``ode_dyn`` has algebraic states or controls, or cannot be expanded.
    """
    for i, what in ((2, "algebraic states z"), (4, "controls u")):
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
    p = ca.SX.sym("p", f.nnz_in(3))  # runtime parameters, passed by the driver on every call
    empty = ca.SX(0, 1)
    xdot = f(t, x, empty, p, empty)[0]
    J = ca.jacobian(xdot, x)
    pattern = J.sparsity() + ca.Sparsity.diag(nx)
    jac = ca.project(J, pattern)  # structural zeros on the diagonal
    opts = {"cse": True} if cse else {}
    rhs_f = ca.Function(RHS_NAME, [t, x, p], [xdot], ["t", "x", "p"], ["xdot"], opts)
    jac_f = ca.Function(JAC_NAME, [t, x, p], [jac], ["t", "x", "p"], ["J"], opts)
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


@MEMO.memoize("native-libraries", 16)
def load(path: Path) -> ctypes.CDLL:
    """Load a native (whole-loop or per-agent) library once per path and check it.

    The per-agent driver loads its libraries from private copies instead
    (:func:`generated.loaded.open_kernels`). The path names a
    content-hashed cache entry: the cache builds an entry in a temporary folder and
    renames it into place, so a handle loaded before keeps the code of that key. A file
    rewritten in place behind the cache's back is not detected here; ``api.build``
    loads its libraries from checked private copies instead (docs/simulation.md).

    Parameters
    ----------
    path : Path
        ``Library.path`` of a library built with :func:`toolchain`.

    Raises
    ------
    BuildError
        As :func:`open_library`.
    """
    return open_library(path)


def open_library(path: Path) -> ctypes.CDLL:
    """Load a native library (not cached) and check it against the headers and the mirror.

    Parameters
    ----------
    path : Path
        A library built with :func:`toolchain`.

    Raises
    ------
    BuildError
        If it cannot be loaded, the SUNDIALS it runs against differs from the vendored
        headers, or its structs differ in size from the ctypes mirror (:data:`STRUCTS`).
    """
    try:
        preload(toolchain().libraries)  # its NEEDED sonames, from this environment
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise BuildError(f"native integrator: {path.name} cannot be loaded ({exc})") from None
    _declare(lib)
    for which, struct in enumerate(STRUCTS):
        size = lib.hitl_struct_size(which)
        if size != ctypes.sizeof(struct):
            raise BuildError(
                f"native integrator: {path.name} has a {size}-byte {struct.__name__}, "
                f"generated/native.py expects {ctypes.sizeof(struct)} "
                "(hitl_native.h and its ctypes mirror disagree; update the mirror)"
            )
    msg = ctypes.create_string_buffer(MSG_LEN)
    if not lib.hitl_native_check(msg, MSG_LEN):
        raise BuildError(
            f"native integrator: {msg.value.decode(errors='replace')} "
            "(install scikit-sundae==1.2.*, whose SUNDIALS 7.9 the vendored headers match)"
        )
    return lib


def _declare(lib: ctypes.CDLL) -> None:
    """The entry points' signatures (hitl_native.h's structs passed by pointer)."""
    ci = ctypes.c_int
    opts, res = ctypes.POINTER(Options), ctypes.POINTER(Result)
    lib.hitl_native_check.restype = ci
    lib.hitl_native_check.argtypes = [ctypes.c_char_p, ci]
    lib.hitl_struct_size.restype = ctypes.c_long
    lib.hitl_struct_size.argtypes = [ci]
    if hasattr(lib, "hitl_native_run"):
        lib.hitl_native_run.restype = ci
        lib.hitl_native_run.argtypes = [ci, _DP, opts, res]


def dptr(a: np.ndarray) -> ctypes._Pointer:
    """A ``double *`` into a C-contiguous float64 array (the caller keeps it alive).

    Parameters
    ----------
    a : ndarray
    """
    return a.ctypes.data_as(_DP)


@dataclass
class DriverCall:
    """The options and result of one driver run, with the arrays they point into.

    Attributes
    ----------
    sched : Schedule
        The run's output times, targets and restart times.
    options : Options
    result : Result
        ``result.x_out`` points into :attr:`X`, ``result.x_stop`` into :attr:`x_stop`.
    X : ndarray, shape (len(t_out), nx)
        The output rows, NaN where not filled.
    x_stop : ndarray, shape (nx,)
        The state CVODE held when it returned (at ``result.t_stop``).
    log : Path or None
        The temporary file the driver appends SUNDIALS' messages to; read into
        ``Trajectory.sundials_log`` and removed by :meth:`trajectory`.
    """

    sched: Schedule
    options: Options
    result: Result
    X: np.ndarray
    x_stop: np.ndarray
    _keep: tuple[np.ndarray, ...]
    #: the temporary file the driver appends SUNDIALS' messages to (``options.log_path``)
    log: Path | None = None

    @classmethod
    def of(
        cls,
        nx: int,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float],
        p: np.ndarray | None = None,
    ) -> DriverCall:
        """Options from the settings and the schedule; a result with an empty output buffer.

        Parameters
        ----------
        nx : int
            States per row.
        t_out : ndarray
            Output times (rows keep them; the driver runs to the schedule's targets).
        settings : IntegratorSettings
            ``rtol``, ``atol`` and ``max_steps``.
        breakpoints : sequence of float
            Restart times, reconciled with ``t_out`` by :func:`~generated.schedule.schedule`.
        p : ndarray, optional
            The closed loop's parameters (whole-loop driver); default none.
        """
        sched = schedule(t_out, breakpoints)
        pv = np.ascontiguousarray(np.zeros(0) if p is None else p, dtype=float).ravel()
        tq = np.ascontiguousarray(sched.targets, dtype=float)
        bps = np.ascontiguousarray(sched.breaks, dtype=float)
        X = np.full((len(sched.t_out), nx), np.nan)
        x_stop = np.full(nx, np.nan)
        options = Options(
            rtol=float(settings.rtol),
            atol=float(settings.atol),
            max_steps=int(settings.max_steps),
            nt=len(tq),
            t_out=dptr(tq),
            nb=len(bps),
            breaks=dptr(bps),
            np=len(pv),
            p=dptr(pv),
        )
        log = new_sundials_log()
        options.log_path = str(log).encode()
        result = Result(x_out=dptr(X), x_stop=dptr(x_stop))
        return cls(sched, options, result, X, x_stop, (tq, bps, pv), log)

    def trajectory(
        self, method: str, wall0: float, progress: Callable[[float], None] | None = None
    ) -> Trajectory:
        """:func:`driver_trajectory` of the filled result.

        Parameters
        ----------
        method, wall0, progress
            As :func:`driver_trajectory`.
        """
        log = take_sundials_log(self.log)  # SUNDIALS' messages; the temporary file removed
        tr = driver_trajectory(method, self.sched.t_out, self.X, self.result, wall0, progress)
        t_stop = float(self.result.t_stop)
        return replace(tr, sundials_log=log, t_stop=t_stop, x_stop=self.x_stop.copy())


def run(
    library: Path,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    *,
    breakpoints: Sequence[float] = (),
    progress: Callable[[float], None] | None = None,
    p: np.ndarray | None = None,
    driver: ctypes.CDLL | None = None,
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
        reconciled with ``t_out`` by :func:`generated.schedule.schedule`: an output time
        within its tolerance of a breakpoint is integrated to the breakpoint.
    progress : callable, optional
        Called once with the time reached (the run is one C call).
    p : ndarray, optional
        The closed loop's runtime parameters (as many as the library takes; default none).
    driver : ctypes.CDLL, optional
        ``library`` already loaded and checked (:func:`open_library`); default: loaded
        from ``library`` once per process (:func:`load`).

    Returns
    -------
    Trajectory
        Incomplete (not raised) when CVODE gives up; ``stats`` as for CVODES plus
        ``lu_factorizations`` and ``pivot_failures``.
    """
    wall0 = time.perf_counter()
    lib = driver if driver is not None else load(Path(library))
    x = np.ascontiguousarray(x0, dtype=float).ravel()
    call = DriverCall.of(x.size, t_out, settings, breakpoints, p)
    lib.hitl_native_run(x.size, dptr(x), ctypes.byref(call.options), ctypes.byref(call.result))
    return call.trajectory("native", wall0, progress)


def driver_trajectory(
    method: str,
    t_out: np.ndarray,
    X: np.ndarray,
    result: Result,
    wall0: float,
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """A :class:`Trajectory` from what a C driver returned (the native drivers).

    Parameters
    ----------
    method : str
        ``"native"``.
    t_out, X : ndarray
        Output times and the driver's output rows.
    result : Result
        The driver's counters, last flag and message (``"FLAG_NAME: SUNDIALS message"``
        on a failure); ``filled`` < 1: it could not start.
    wall0 : float
        ``time.perf_counter()`` when the run began.
    progress : callable, optional
        Called once with the time reached.

    Raises
    ------
    IntegrationError
        If the driver could not start.
    """
    text = result.msg.decode(errors="replace").strip()
    filled, nt = int(result.filled), len(t_out)
    if filled < 1:
        raise IntegrationError(f"{method} integrator could not start: {text or 'unknown error'}")
    stats: dict[str, float | int] = {k: int(getattr(result, k)) for k in COUNTERS}
    stats.update(last_step=float(result.last_step), integrator_calls=1, jtimes_evals=0)
    stats["wall_seconds"] = time.perf_counter() - wall0
    t_reached = float(t_out[filled - 1])
    message, status = "", Status.OK
    if filled < nt:
        name, _, detail = text.partition(":")
        flag = name.strip() or str(int(result.flag))
        status = flag_status(flag)
        message = (
            f"{method} failed after t = {t_reached:.6g} s (working towards t = "
            f"{float(t_out[filled]):.6g} s): {flag_reason(flag)}"
            + (f" ({detail.strip()})" if detail.strip() else "")
        )
    if progress is not None:
        progress(t_reached)
    return Trajectory(
        t=t_out[:filled].copy(),
        x=X[:filled],
        z=None,
        method=method,
        status=status,
        t_reached=t_reached,
        message=message,
        stats=stats,
    )
