"""The native CVODE driver's toolchain, loading and calling convention (``hitl_native.h``).

Its libraries link the SUNDIALS 7.9 of the ``scikit-sundae`` wheel, whose headers are
vendored (``native/README.md``); :func:`open_library` refuses one whose SUNDIALS or structs
differ from the headers and the ctypes mirror: a clear error, never corrupt memory.
"""

from __future__ import annotations

import ctypes
import importlib.util
from pathlib import Path

from core.artifacts import sha256_file
from core.errors import BuildError
from core.memo import MEMO
from generated.compiler import Toolchain
from generated.shared_library import preload

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
_DP = ctypes.POINTER(ctypes.c_double)


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

    Its key holds the SHA-256 of every header and library. A built library names the
    libraries by soname only and they are preloaded before it: the same key means the same
    files, so an entry built from another checkout's environment loads here.

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
        If it cannot be loaded, or its SUNDIALS or structs differ from the headers'.
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
