"""Compiled libraries loaded in this process, from bytes their cache entry vouches for.

A build-cache entry (:mod:`generated.codegen`) is loaded from a private copy of its
library's bytes, checked against its manifest (:func:`verified_bytes`), so that a
rewrite of the entry can never change code this process runs. :data:`BUILDS` keeps,
per (structure key, method, codegen settings), the loaded library of a build for later
scenarios of that structure; an entry is used only while its files are the ones it was
loaded from (:func:`library_stamp`), else it is checked and loaded again
(:func:`current`).
"""

from __future__ import annotations

import ctypes
import dataclasses
import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca

from core.build_cache import (
    MANIFEST_NAME,
    TMP_PREFIX,
    check_entry,
    entry_bytes,
)
from core.errors import BuildError
from core.memo import MEMO
from generated import native
from generated.codegen import Library
from generated.shared_library import preload

#: the names of the closed loop's Functions in every library (ODE or DAE form, outputs)
ODE_NAME, DAE_NAME, OUT_NAME = "cl_ode", "cl_dae", "cl_out"


@dataclass(frozen=True)
class Image:
    """A library loaded from a private copy of the bytes its cache entry vouches for.

    Attributes
    ----------
    stamp : tuple of int
        :func:`library_stamp` of the cache entry when those bytes were read.
    dyn_p, outputs_p : casadi.Function
        The closed loop's right-hand side and outputs, p an input.
    """

    stamp: tuple[int, ...]
    dyn_p: ca.Function
    outputs_p: ca.Function


def library_stamp(lib: Library) -> tuple[int, ...] | None:
    """Identity of a cache entry's library and manifest files (None if one is missing).

    Device, inode, size, modification and change time: rewriting, replacing or touching
    either file changes it (the change time cannot be set back).

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
    """The library's bytes, checked against its manifest (:func:`entry_bytes`).

    Parameters
    ----------
    lib : Library

    Raises
    ------
    BuildError
        If the entry someone else could have written (:func:`check_entry`), does not
        check out, or changed while it was read.
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

    A loaded library's file must not change: its pages are mapped from the file, so an
    in-place rewrite of the cache entry would change code this process runs (and crash
    it, at the latest when the Functions are released at exit). The copy lives in a
    folder named like a build's temporary folder (removed with the build leftovers if
    this process dies before removing it).

    Parameters
    ----------
    lib : Library
    form : str
        ``"ode"`` or ``"dae"``: which right-hand side to load.
    """
    data, stamp = verified_bytes(lib)
    names = (DAE_NAME if form == "dae" else ODE_NAME, OUT_NAME)
    for name in names:
        if name not in lib.names:
            raise BuildError(
                f"library {lib.path}: no function {name!r} (it has {', '.join(lib.names)})"
            )

    def load(copy: Path) -> tuple[Any, Any]:
        try:
            preload(lib.preload)  # the libraries it names by soname (native: SUNDIALS)
            return tuple(ca.external(name, str(copy)) for name in names)
        except (OSError, RuntimeError) as exc:
            first = str(exc).strip().splitlines()
            raise BuildError(
                f"build cache {lib.folder}: cannot be loaded ({first[0] if first else exc})"
            ) from None

    dyn_p, outputs_p = _from_private_copy(lib, data, load)
    return Image(stamp, dyn_p, outputs_p)


def _from_private_copy(lib: Library, data: bytes, load: Callable[[Path], Any]) -> Any:
    """``load`` of a private copy of ``data`` (the entry's verified bytes), removed after.

    The copy lives in a fresh folder of the cache root (a read-only root: of the system's
    temporary folder), named with the process id so a crash leaves a folder a later build
    can recognise and remove.
    """
    try:
        tmp = Path(
            tempfile.mkdtemp(
                dir=lib.folder.parent, prefix=f"{TMP_PREFIX}{lib.key[:12]}-{os.getpid()}-"
            )
        )
    except OSError:  # a read-only cache root
        tmp = Path(tempfile.mkdtemp(prefix=f"hitl-{lib.key[:12]}-"))
    try:
        copy = tmp / lib.path.name
        copy.write_bytes(data)
        return load(copy)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


#: per-agent kernel libraries loaded in this process, by (path, stamp) (core/memo.py)
_KERNELS = MEMO.namespace("kernel-images", 32)


def open_kernels(path: Path) -> ctypes.CDLL:
    """A per-agent kernel library (``generated/agents.py``) loaded from a private copy of
    the bytes its cache entry vouches for, once per entry and stamp.

    As :func:`open_image`: the process never maps the cache file itself, so an in-place
    rewrite of the entry cannot change code it runs; an entry that changed since it was
    built does not check out (:func:`verified_bytes`) and is refused.

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
    data, stamp = verified_bytes(lib)
    cdll = _from_private_copy(lib, data, native.open_library)
    _KERNELS[(str(path), stamp)] = cdll
    return cdll


@dataclass(frozen=True)
class Compiled:
    """What a process keeps of a build for later scenarios of its structure.

    Its loaded library (:class:`Image`) is used only while the cache entry is the file
    it was loaded from (same :func:`library_stamp`); a changed entry is checked and loaded
    again, or rebuilt.
    """

    closed_loop: Any
    library: Library
    form: str
    image: Image


#: compiled builds of this process by (structure key, method, codegen settings)
BUILDS = MEMO.namespace("compiled-builds", 32)  # core/memo.py


def current(c: Compiled) -> Compiled | None:
    """``c``, loaded again if its cache entry changed on disk; None if it no longer checks out.

    Parameters
    ----------
    c : Compiled
    """
    if library_stamp(c.library) == c.image.stamp:
        return c
    try:
        return dataclasses.replace(c, image=open_image(c.library, c.form))
    except BuildError:
        return None
