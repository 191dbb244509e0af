"""The native CVODE driver's Python side: its toolchain, loading and calling convention.

Method ``native`` is the per-agent engine (:mod:`generated.agents`): its libraries are one
follower model's kernels with ``native/common.c`` and ``native/agents.c`` appended, linked
against the SUNDIALS 7.9 of the ``scikit-sundae`` wheel, whose missing headers are
vendored in ``native/include`` (``native/README.md``). :func:`toolchain` hashes everything
a library is built from; :func:`open_library` refuses a library whose SUNDIALS (version,
index type) differs from the headers or whose structs differ from the ctypes mirror
(:class:`Options`, :class:`Result`) of ``hitl_native.h``, so a mismatch is a clear error,
never corrupt memory; :class:`DriverCall` holds one run's options, result and buffers.
"""

from __future__ import annotations

import ctypes
import importlib.util
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.artifacts import sha256_file
from core.errors import BuildError, IntegrationError
from core.memo import MEMO
from generated.compiler import Toolchain
from generated.schedule import Schedule, schedule
from generated.shared_library import preload
from generated.sundials_log import new_sundials_log, take_sundials_log
from generated.values import (
    IntegratorSettings,
    Status,
    Trajectory,
    flag_reason,
    flag_status,
)

NATIVE_DIR = Path(__file__).resolve().parent / "native"
INCLUDE_DIR = NATIVE_DIR / "include"
COMMON = NATIVE_DIR / "common.c"
#: the C appended after common.c: the per-agent driver (generated/agent_kernels.py)
DRIVER = NATIVE_DIR / "agents.c"
#: the driver's calling convention (options, result)
HEADER = NATIVE_DIR / "hitl_native.h"
#: the SUNDIALS libraries the driver links, from the scikit-sundae wheel
SUNDIALS_LIBRARIES = (
    "sundials_core",
    "sundials_cvode",
    "sundials_nvecserial",
    "sundials_sunmatrixsparse",
)
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


@MEMO.memoize("native-toolchain", 1)
def toolchain() -> Toolchain:
    """The driver source, the vendored headers and scikit-sundae's SUNDIALS libraries.

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
        "headers": {str(p.relative_to(INCLUDE_DIR)): sha256_file(p) for p in headers},
        "libraries": {p.name: sha256_file(p) for p in libs},
        "interface": {HEADER.name: sha256_file(HEADER)},
    }
    source = COMMON.read_text() + "\n" + DRIVER.read_text()
    return Toolchain(source, (NATIVE_DIR, INCLUDE_DIR), tuple(libs), key)


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
    lib.hitl_native_check.restype = ctypes.c_int
    lib.hitl_native_check.argtypes = [ctypes.c_char_p, ctypes.c_int]
    lib.hitl_struct_size.restype = ctypes.c_long
    lib.hitl_struct_size.argtypes = [ctypes.c_int]
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
    log: Path | None = None

    @classmethod
    def of(
        cls,
        nx: int,
        t_out: np.ndarray,
        settings: IntegratorSettings,
        breakpoints: Sequence[float],
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
        """
        sched = schedule(t_out, breakpoints)
        log = new_sundials_log()
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
            log_path=str(log).encode(),
        )
        result = Result(x_out=dptr(X), x_stop=dptr(x_stop))
        return cls(sched, options, result, X, x_stop, (tq, bps), log)

    def trajectory(
        self, method: str, wall0: float, progress: Callable[[float], None] | None = None
    ) -> Trajectory:
        """A :class:`Trajectory` from what the driver filled in.

        Parameters
        ----------
        method : str
            ``"native"``.
        wall0 : float
            ``time.perf_counter()`` when the run began.
        progress : callable, optional
            Called once with the time reached.

        Raises
        ------
        IntegrationError
            If the driver could not start (``result.filled`` < 1).
        """
        log = take_sundials_log(self.log)  # SUNDIALS' messages; the temporary file removed
        result, t_out = self.result, self.sched.t_out
        text = result.msg.decode(errors="replace").strip()
        filled = int(result.filled)
        if filled < 1:
            raise IntegrationError(
                f"{method} integrator could not start: {text or 'unknown error'}"
            )
        stats: dict[str, float | int] = {k: int(getattr(result, k)) for k in COUNTERS}
        stats.update(last_step=float(result.last_step), integrator_calls=1, jtimes_evals=0)
        stats["wall_seconds"] = time.perf_counter() - wall0
        t_reached = float(t_out[filled - 1])
        message, status = "", Status.OK
        if filled < len(t_out):  # "FLAG_NAME: SUNDIALS message"
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
            x=self.X[:filled],
            z=None,
            method=method,
            status=status,
            t_reached=t_reached,
            message=message,
            stats=stats,
            sundials_log=log,
            t_stop=float(result.t_stop),
            x_stop=self.x_stop.copy(),
        )
