"""Loading compiled shared libraries: their dependencies first, by absolute path.

A build-cache library names the SUNDIALS libraries it links only by soname (no rpath,
:class:`generated.compiler.Toolchain`), so it loads from any checkout or environment once
those are loaded (:func:`preload`).
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from pathlib import Path

from core.memo import MEMO


@MEMO.memoize("preloaded-libraries", 8)
def preload(libraries: tuple[Path, ...]) -> None:
    """Load shared libraries by absolute path, once per process, so that the dynamic loader
    matches a NEEDED soname of a library linked against them.

    Locally (RTLD_LOCAL): loaded globally, their symbols would take precedence over those
    of the SUNDIALS that CasADi's own CVODES and IDAS plugins bring (the same names).

    Parameters
    ----------
    libraries : tuple of Path
        In dependency order (a library before those that need it).
    """
    for lib in libraries:
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_LOCAL)


def load_problem(path: Path, libraries: Sequence[Path] = ()) -> str | None:
    """Why the shared library ``path`` cannot be loaded in this process (None: it can).

    Opened with every symbol bound at once (ctypes' ``RTLD_NOW``) after ``libraries`` and
    closed again: a missing NEEDED library, an unresolved symbol or bytes that are no
    shared library are reported here instead of as a traceback of the first load.

    Parameters
    ----------
    path : Path
    libraries : sequence of Path
        What it needs loaded first (:attr:`generated.compiler.Toolchain.libraries`).
    """
    try:
        preload(tuple(libraries))
        handle = ctypes.CDLL(str(path))._handle
    except OSError as exc:
        return str(exc).replace(f"{path}: ", "")
    import _ctypes  # dlclose: the check keeps no mapping of the cache file

    _ctypes.dlclose(handle)
    return None
