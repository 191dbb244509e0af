"""The C compiler: its identity (part of every cache key) and one compilation to a library."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core import artifacts
from core.build_cache import LIBRARY_NAME, SOURCE_NAME
from core.errors import BuildError
from core.memo import MEMO
from generated.values import CodegenSettings


@dataclass(frozen=True)
class Toolchain:
    """What a library needs beyond the generated code (the native integrator's driver)."""

    # C text appended to the generated code (one translation unit: it calls the generated
    # functions directly)
    appended_source: str = ""
    include_dirs: tuple[Path, ...] = ()
    # shared libraries linked after the source, in dependency order, recorded by soname
    # only (no rpath; shared_library.preload): a cache entry does not depend on the
    # checkout or environment that built it
    libraries: tuple[Path, ...] = ()
    # hashes of headers and libraries: part of the cache key, so that a changed header or
    # library is never served from the cache
    key: Mapping[str, Any] = field(default_factory=dict)


@MEMO.memoize("compiler-identities", 8)
def compiler_identity(compiler: str) -> str:
    """Resolved path and first ``--version`` line of ``compiler`` (part of the cache key).

    Parameters
    ----------
    compiler : str
        Executable name or path, looked up on ``PATH``.
    """
    path = shutil.which(compiler)
    if path is None:
        raise BuildError(
            f"CodegenSettings.compiler: {compiler!r} not found on PATH (install gcc or set compiler)"
        )
    try:
        out = subprocess.run(
            [path, "--version"], capture_output=True, text=True, timeout=60, check=False
        )
    except OSError as exc:
        raise BuildError(f"CodegenSettings.compiler: {path} cannot run ({exc.strerror})") from None
    first = (out.stdout or out.stderr).splitlines()
    return f"{os.path.realpath(path)} | {first[0] if first else 'unknown version'}"


def compile_source(
    source: str, settings: CodegenSettings, folder: Path, toolchain: Toolchain | None = None
) -> float:
    """Write ``source`` to ``folder/model.c``, compile ``folder/model.so``; the wall seconds.

    Parameters
    ----------
    source : str
    settings : CodegenSettings
    folder : Path
        Created if missing.
    toolchain : Toolchain, optional

    Raises
    ------
    BuildError
        With the compiler's first error lines and the source path.
    """
    folder.mkdir(parents=True, exist_ok=True)
    src = folder / SOURCE_NAME
    artifacts.atomic_write_text(src, source)  # a failed write names the file
    tc = toolchain or Toolchain()
    cmd = [
        settings.compiler,
        *settings.cflags,
        *(f"-I{d}" for d in tc.include_dirs),
        str(src),
        "-o",
        str(folder / LIBRARY_NAME),
        *(str(lib) for lib in tc.libraries),  # DT_NEEDED = their sonames; no rpath
        "-lm",
    ]
    t0 = time.perf_counter()
    try:
        res = subprocess.run(
            cmd, capture_output=True, text=True, timeout=settings.timeout, check=False
        )
    except FileNotFoundError:
        raise BuildError(
            f"CodegenSettings.compiler: {settings.compiler!r} not found (install gcc or set compiler)"
        ) from None
    except subprocess.TimeoutExpired:
        raise BuildError(
            f"compiling {src} took longer than {settings.timeout:.0f} s "
            "(raise CodegenSettings.timeout or use optimization='-O0')"
        ) from None
    if res.returncode != 0:
        lines = [ln for ln in res.stderr.splitlines() if "error" in ln.lower()] or (
            res.stderr.splitlines() or [f"exit status {res.returncode}"]
        )
        raise BuildError(f"compiling {src} failed: " + " | ".join(lines[:3]))
    return time.perf_counter() - t0
