"""Compiled libraries loaded in this process, from bytes their cache entry vouches for.

A build-cache entry (:mod:`generated.codegen`) is loaded from a private copy of its
library's bytes, checked against its manifest, so that a rewrite of the entry can never
change code this process runs (docs/simulation.md).
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca

from core.build_cache import MANIFEST_NAME, TMP_PREFIX, check_entry, entry_bytes
from core.errors import BuildError
from core.memo import MEMO
from generated import native
from generated.codegen import Library
from generated.shared_library import preload

#: the names of the closed loop's Functions in every library (ODE or DAE form, outputs)
ODE_NAME, DAE_NAME, OUT_NAME = "cl_ode", "cl_dae", "cl_out"


@dataclass(frozen=True)
class Image:
    """A closed loop's library loaded from a private copy of verified bytes: its right-hand
    side and outputs (p an input), and the entry's :func:`library_stamp` when read."""

    library: Library
    form: str
    stamp: tuple[int, ...]
    dyn_p: ca.Function
    outputs_p: ca.Function


def library_stamp(lib: Library) -> tuple[int, ...] | None:
    """Identity of a cache entry's library and manifest files (None if one is missing):
    device, inode, size, modification and change time (which cannot be set back).

    Parameters
    ----------
    lib : Library
    """
    try:
        stats = [os.stat(f) for f in (lib.path, lib.folder / MANIFEST_NAME)]
    except OSError:
        return None
    return tuple(
        v for s in stats for v in (s.st_dev, s.st_ino, s.st_size, s.st_mtime_ns, s.st_ctime_ns)
    )


def verified_bytes(lib: Library) -> tuple[bytes, tuple[int, ...]]:
    """The library's bytes checked against its manifest, and the entry's stamp.

    Parameters
    ----------
    lib : Library

    Raises
    ------
    BuildError
        If someone else could have written the entry (:func:`check_entry`), it does not
        check out, or it changed while it was read.
    """
    try:
        check_entry(lib.folder, lib.folder.parent)
    except OSError:
        pass  # a missing file: entry_bytes below names it
    stamp = library_stamp(lib)
    data, why = entry_bytes(lib.folder, lib.key)
    if why is None and (stamp is None or library_stamp(lib) != stamp):
        why = "changed while it was loaded"
    if why is not None:
        raise BuildError(f"build cache {lib.folder}: {why}; build again to rebuild it")
    return data, stamp


def open_image(lib: Library, form: str) -> Image:
    """Load ``lib`` from a private copy of its verified bytes, removed once loaded.

    A loaded library's pages are mapped from its file: an in-place rewrite of the cache
    entry would change code this process runs (and crash it, at the latest at exit).

    Parameters
    ----------
    lib : Library
    form : str
        ``"ode"`` or ``"dae"``: which right-hand side to load.
    """
    names = (DAE_NAME if form == "dae" else ODE_NAME, OUT_NAME)

    def load(copy: Path) -> tuple[Any, Any]:
        for name in names:  # after the bytes checked out
            if name not in lib.names:
                raise BuildError(
                    f"library {lib.path}: no function {name!r} (it has {', '.join(lib.names)})"
                )
        try:
            preload(lib.preload)  # the libraries it names by soname (native: SUNDIALS)
            return tuple(ca.external(name, str(copy)) for name in names)
        except (OSError, RuntimeError) as exc:
            first = str(exc).strip().splitlines()
            raise BuildError(
                f"build cache {lib.folder}: cannot be loaded ({first[0] if first else exc})"
            ) from None

    (dyn_p, outputs_p), stamp = _load_private(lib, load)
    return Image(lib, form, stamp, dyn_p, outputs_p)


def _load_private(lib: Library, load: Callable[[Path], Any]) -> tuple[Any, tuple[int, ...]]:
    """``load`` of a private copy of the entry's verified bytes, and the entry's stamp.

    The copy, removed after, is in a fresh folder of the cache root named with the process id
    (a crash leaves a folder a later build removes), or of the system's temporary folder.
    """
    data, stamp = verified_bytes(lib)
    prefix = f"{TMP_PREFIX}{lib.key[:12]}-{os.getpid()}-"
    try:
        tmp = Path(tempfile.mkdtemp(dir=lib.folder.parent, prefix=prefix))
    except OSError:  # a read-only cache root
        tmp = Path(tempfile.mkdtemp(prefix=f"hitl-{lib.key[:12]}-"))
    try:
        copy = tmp / lib.path.name
        copy.write_bytes(data)
        return load(copy), stamp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


#: per-agent kernel libraries loaded in this process, by (path, stamp) (core/memo.py)
_KERNELS = MEMO.namespace("kernel-images", 32)


def open_kernels(path: Path) -> ctypes.CDLL:
    """A per-agent kernel library (``generated/agents.py``) loaded as :func:`open_image`
    loads a closed loop's, once per entry and stamp.

    Parameters
    ----------
    path : Path
        ``Library.path`` of a kernel library (``<root>/<key>/...``).

    Raises
    ------
    BuildError
        The entry does not check out or cannot be loaded.
    """
    folder = Path(path).parent
    lib = Library(folder.name, folder, folder, Path(path), (), True, 0.0, 0.0, 0)
    hit = _KERNELS.get((str(path), library_stamp(lib)))
    if hit is not None:
        return hit
    cdll, stamp = _load_private(lib, native.open_library)
    _KERNELS[(str(path), stamp)] = cdll
    return cdll


#: (closed loop, Image) of the builds of this process by (structure key, method, codegen
#: settings), for later scenarios of the structure (core/memo.py)
BUILDS = MEMO.namespace("compiled-builds", 32)


def current(image: Image) -> Image | None:
    """``image`` while its cache entry is the file it was loaded from (same
    :func:`library_stamp`), else loaded again; None if it no longer checks out.

    Parameters
    ----------
    image : Image
    """
    if library_stamp(image.library) == image.stamp:
        return image
    try:
        return open_image(image.library, image.form)
    except BuildError:
        return None
