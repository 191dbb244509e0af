"""A compiled library and its key: :func:`build_library` and the cache entry it fills.

The entry is ``<build root>/<sha256>/``, keyed by everything that produced it (C text,
compiler, flags, CasADi version, settings): an unchanged model is never rebuilt, a
changed one is never served stale. The C text is :mod:`generated.csource`'s.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca

from core import artifacts
from core.artifacts import sha256_file
from core.build_cache import (
    LIBRARY_NAME,
    MANIFEST_NAME,
    SOURCE_NAME,
    TMP_PREFIX,
    cache_write_error,
    check_entry,
    default_build_root,
    discard_entry,
    entry_problem,
    install_entry,
    private_root,
    remove_stale_builds,
)
from core.errors import BuildError
from core.private_files import make_private_dir, seal
from generated.compiler import Toolchain, compile_source, compiler_identity
from generated.csource import generate_source
from generated.shared_library import load_problem, preload
from generated.values import CodegenSettings


@dataclass(frozen=True)
class Library:
    """A compiled shared library and how it was obtained."""

    key: str  # SHA-256 cache key, the folder's name
    folder: Path
    source: Path  # the generated C
    path: Path  # the shared library
    names: tuple[str, ...]  # its functions, with their jac_/fwd1_ companions
    cache_hit: bool
    codegen_seconds: float
    compile_seconds: float  # 0 on a cache hit
    source_bytes: int
    preload: tuple[Path, ...] = ()  # libraries to load first (Toolchain.libraries)

    def function(self, name: str) -> ca.Function:
        """Load ``name``, one of :attr:`names`, with :func:`casadi.external`.

        Parameters
        ----------
        name : str
        """
        if name not in self.names:
            raise BuildError(
                f"library {self.path}: no function {name!r} (it has {', '.join(self.names)})"
            )
        preload(self.preload)
        return ca.external(name, str(self.path))


def cache_root(settings: CodegenSettings) -> Path:
    """``settings.build_root``, else :func:`core.build_cache.default_build_root`.

    Parameters
    ----------
    settings : CodegenSettings
    """
    return Path(settings.build_root) if settings.build_root is not None else default_build_root()


def cache_key(
    source: str, settings: CodegenSettings, extra: Mapping[str, Any] | None = None
) -> str:
    """SHA-256 of everything that produced a library.

    Parameters
    ----------
    source : str
        The complete C text.
    settings : CodegenSettings
    extra : mapping, optional
        Further inputs of the build (:attr:`Toolchain.key`).
    """
    ident = {"source_sha256": hashlib.sha256(source.encode()).hexdigest(), **_built_by(settings)}
    if extra:
        ident["extra"] = dict(extra)
    blob = json.dumps(ident, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()


def build_library(
    functions: Sequence[ca.Function],
    settings: CodegenSettings | None = None,
    with_derivatives: Sequence[str] = (),
    toolchain: Toolchain | None = None,
) -> Library:
    """Generate, compile (or reuse from the cache) and describe a shared library.

    Parameters
    ----------
    functions : sequence of casadi.Function
    settings : CodegenSettings, optional
    with_derivatives : sequence of str
        Names that also get their derivative companions (see :func:`generate_source`).
    toolchain : Toolchain, optional
        Hand-written C appended, include folders and libraries to link.
    """
    settings = settings or CodegenSettings()
    t0 = time.perf_counter()
    tc = toolchain or Toolchain()
    source, names = generate_source(functions, settings, with_derivatives)
    source += tc.appended_source
    t_codegen = time.perf_counter() - t0
    key = cache_key(source, settings, tc.key)
    root = private_root(cache_root(settings))
    folder = root / key
    remove_stale_builds(root)
    hit = _usable_entry(folder, key, tc)
    t_compile = 0.0 if hit else _compile_entry(root, key, source, names, settings, tc)
    return Library(
        key,
        folder,
        folder / SOURCE_NAME,
        folder / LIBRARY_NAME,
        names,
        hit,
        t_codegen,
        t_compile,
        len(source),
        tuple(tc.libraries),
    )


def _usable_entry(folder: Path, key: str, tc: Toolchain) -> bool:
    """Whether the cache entry ``folder`` exists and may be loaded for ``key``.

    An entry someone else could have written is refused (:func:`check_entry`, a
    ``BuildError``) before any of it is read. A bad entry is reported on stderr and never
    dlopen'ed: it would crash (truncated) or silently compute another model. An entry
    that checks out but cannot be loaded in this process (:func:`load_problem`) is
    reported in one line and moved aside, so that the rebuild replaces it.
    """
    if not os.path.lexists(folder):
        return False
    check_entry(folder, folder.parent)
    why = entry_problem(folder, key)
    if why is not None:
        print(f"build cache {folder}: {why}; rebuilding", file=sys.stderr)
        return False
    why = load_problem(folder / LIBRARY_NAME, tc.libraries)
    if why is None:
        return True
    print(f"cache entry {key[:12]}: cannot be loaded here ({why}); rebuilding", file=sys.stderr)
    discard_entry(folder)
    return False


def _compile_entry(
    root: Path,
    key: str,
    source: str,
    names: tuple[str, ...],
    settings: CodegenSettings,
    tc: Toolchain,
) -> float:
    """Compile ``source`` in a temporary folder, install it as ``root/key``, return the time.

    On a compile failure the source is kept under ``root/failed/key/`` and the error names
    it. Folders 0700, files 0600 (the library 0700) whatever the umask
    (:func:`core.private_files.seal`); a failed write (a full disk) names the cache.
    """
    try:
        tmp = Path(tempfile.mkdtemp(dir=root, prefix=f"{TMP_PREFIX}{key[:12]}-{os.getpid()}-"))
        folder = root / key
        try:
            try:
                t_compile = compile_source(source, settings, tmp, tc)
            except BuildError as exc:
                failed = root / "failed" / key
                shutil.rmtree(failed, ignore_errors=True)
                make_private_dir(failed.parent)
                seal(tmp)
                os.replace(tmp, failed)
                raise BuildError(str(exc).replace(str(tmp), str(failed))) from None
            seal(tmp)
            info = {
                "key": key,
                "library_sha256": sha256_file(tmp / LIBRARY_NAME),
                "source_sha256": sha256_file(tmp / SOURCE_NAME),
                "names": list(names),
                **_built_by(settings),
                "toolchain": dict(tc.key),
                "source_bytes": len(source),
                "compile_seconds": t_compile,
            }
            # the manifest is written last: its presence marks a complete entry
            text = json.dumps(info, indent=2, sort_keys=True, default=str)
            artifacts.atomic_write_text(tmp / MANIFEST_NAME, text, mode=0o600)
            install_entry(tmp, folder)
        finally:
            if tmp.exists() and tmp != folder:
                shutil.rmtree(tmp, ignore_errors=True)
    except OSError as exc:
        raise cache_write_error(root, exc) from None
    return t_compile


def _built_by(settings: CodegenSettings) -> dict[str, Any]:
    """What built a library besides its source: compiler, flags, CasADi, settings."""
    return {
        "compiler": compiler_identity(settings.compiler),
        "cflags": list(settings.cflags),
        "casadi": ca.__version__,
        "settings": settings.key_fields(),
    }
