"""The build cache's folders: where the root is, what an entry holds, how entries come and go.

A cache entry is ``<root>/<sha256 key>/`` with the generated C (:data:`SOURCE_NAME`), the
library (:data:`LIBRARY_NAME`) and, written last, the manifest (:data:`MANIFEST_NAME`)
that records the library's SHA-256; an entry without a valid manifest is never trusted.
Builds happen in ``.tmp-*`` folders renamed into place (:func:`install_entry`), so an
entry is either complete or absent. What is built and how it is keyed is
:mod:`generated.codegen`.

The cache holds code this process runs, so only its user may write it
(:mod:`core.private_files`): the root and its folders are created 0700 and the files
0600 (the library 0700) whatever the umask; a root, entry folder or file that another
user owns or that its group or others may write is refused before anything of it is
read (:func:`private_root`, :func:`check_entry`).
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import tempfile
from pathlib import Path

from platformdirs import user_cache_dir

from core import artifacts
from core.artifacts import sha256_bytes
from core.errors import BuildError
from core.files import FileRefused, read_json_file, read_regular_file
from core.private_files import check_trusted, make_private_dir

#: default cache root: the user's cache folder (``$XDG_CACHE_HOME`` or ``~/.cache`` on
#: Linux), outside the package, so an installed package never writes into site-packages;
#: ``HITL_BUILD_DIR`` overrides it
DEFAULT_BUILD_ROOT = Path(user_cache_dir("hitl-formation")) / "build"
#: names of what a cache root holds: entries (64 hex digits), failed sources, the start-up
#: caches of core/models/cache.py (gains, models), temp folders
ENTRY_PATTERN = re.compile(r"[0-9a-f]{64}|failed|gains|models|\.tmp-.*")
SOURCE_NAME = "model.c"
LIBRARY_NAME = "model.so"
MANIFEST_NAME = "manifest.json"
#: temporary build folders: ``.tmp-<key[:12]>-<pid>-<random>``
TMP_PREFIX = ".tmp-"
#: largest manifest read (a real one has a few kB) and its deepest nesting (a real one: 3)
MAX_MANIFEST_BYTES = 1 << 20
MAX_MANIFEST_DEPTH = 16
#: largest library read and hashed (the N = 50 whole-loop library has tens of MB)
MAX_LIBRARY_BYTES = 1 << 31


def default_build_root() -> Path:
    """The cache root without settings: ``$HITL_BUILD_DIR``, else :data:`DEFAULT_BUILD_ROOT`."""
    env = os.environ.get("HITL_BUILD_DIR")
    return Path(env) if env else DEFAULT_BUILD_ROOT


def clear_cache(root: Path | None = None) -> list[Path]:
    """Remove the build cache's entries, failed sources and temporary folders.

    Only names the cache itself creates (:data:`ENTRY_PATTERN`) are removed, so a
    root pointed at a folder with other content loses nothing else; the root itself
    is removed when it is left empty.

    Parameters
    ----------
    root : Path, optional
        Default :func:`default_build_root`.

    Returns
    -------
    list of Path
        What was removed.
    """
    root = root if root is not None else default_build_root()
    if not root.is_dir():
        return []
    removed = []
    for d in sorted(root.iterdir()):
        if d.is_dir() and not d.is_symlink() and ENTRY_PATTERN.fullmatch(d.name):
            shutil.rmtree(d, ignore_errors=True)
            removed.append(d)
    if not any(root.iterdir()):
        root.rmdir()
    return removed


def entry_problem(folder: Path, key: str) -> str | None:
    """Why the cache entry ``folder`` cannot be loaded for ``key`` (None: it can).

    Parameters
    ----------
    folder : Path
        ``<root>/<key>/``.
    key : str
        The key this build needs.
    """
    return entry_bytes(folder, key)[1]


def entry_bytes(folder: Path, key: str) -> tuple[bytes, str | None]:
    """The bytes of the entry's library and None, or ``b""`` and why they cannot be trusted.

    The manifest must name ``key`` and record the SHA-256 of ``model.so``, and the
    library's bytes must have that hash: a truncated or corrupt file, or a library
    copied in from another build, is caught before it is ever loaded.

    Parameters
    ----------
    folder : Path
        ``<root>/<key>/``.
    key : str
        The key this build needs.
    """
    info, why = _read_manifest(folder)
    if why is not None:
        return b"", why
    if not isinstance(info, dict) or not isinstance(info.get("library_sha256"), str):
        return b"", "manifest records no library SHA-256"
    if info.get("key") != key:
        return b"", f"manifest is for key {str(info.get('key'))[:12]}…, not this build"
    try:
        data = read_regular_file(folder / LIBRARY_NAME, MAX_LIBRARY_BYTES)
    except (OSError, FileRefused):
        return b"", f"{LIBRARY_NAME} missing, unreadable or not a regular file"
    if sha256_bytes(data) != info["library_sha256"]:
        return b"", (
            f"{LIBRARY_NAME} does not have the SHA-256 its manifest records "
            "(truncated, corrupt or replaced)"
        )
    return data, None


def _read_manifest(folder: Path) -> tuple[object, str | None]:
    """The parsed manifest and None, or None and why it cannot be read (a huge or absurdly
    nested one is a corrupt entry, rebuilt, never a ``RecursionError``)."""
    try:
        return read_json_file(folder / MANIFEST_NAME, MAX_MANIFEST_BYTES, MAX_MANIFEST_DEPTH), None
    except FileNotFoundError:
        return None, "no manifest (incomplete entry)"
    except FileRefused as exc:
        return None, f"manifest {exc} (corrupt)"
    except (OSError, ValueError):
        return None, "manifest unreadable"


def private_root(root: Path) -> Path:
    """The cache root, created 0700 if missing; refused when someone else could write it.

    Parameters
    ----------
    root : Path
        ``$HITL_BUILD_DIR`` or :data:`DEFAULT_BUILD_ROOT` (or a settings' ``build_root``).

    Raises
    ------
    BuildError
        The root is owned by another user or writable by its group or others (e.g. a
        ``1777`` folder), or it cannot be created: one line with the fix.
    """
    try:
        make_private_dir(root)
        check_trusted(root, root)
    except OSError as exc:
        raise cache_write_error(root, exc) from None
    return root


def check_entry(folder: Path, root: Path) -> None:
    """Refuse an entry someone else could have written, before any of it is read.

    The root, the entry's folder, its library and its manifest must each be owned by
    the calling user (or root) and writable by no group or other user; none may be a
    symbolic link.

    Parameters
    ----------
    folder : Path
        ``<root>/<key>/`` (existing).
    root : Path
        The cache root.

    Raises
    ------
    BuildError
        One line naming the path, why, and the fix (remove the entry).
    """
    for p in (folder / LIBRARY_NAME, folder / MANIFEST_NAME, folder):
        if os.path.lexists(p):
            check_trusted(p, root)


def cache_write_error(root: Path, exc: OSError) -> BuildError:
    """One line for a failed write to the build cache: the path, the reason and the fix.

    The fix names the cache and ``HITL_BUILD_DIR``, never the output folder: a full
    or read-only cache disk is not the outputs' disk.

    Parameters
    ----------
    root : Path
        The cache root.
    exc : OSError
        The failure (``exc.filename`` names the file when known).
    """
    reason = exc.strerror or type(exc).__name__
    what = f"cannot write {exc.filename}" if exc.filename else f"cannot write to {root}"
    if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        fix = f"free space on the disk of the build cache {root}"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = f"make the build cache {root} writable"
    else:
        fix = f"check the build cache {root}"
    return BuildError(
        f"{what}: {reason} ({fix}, or set HITL_BUILD_DIR to a folder of your own elsewhere)"
    )


def remove_stale_builds(root: Path, min_age: float = artifacts.STALE_SECONDS) -> list[Path]:
    """Remove ``.tmp-<key>-<pid>-*`` build folders whose process is gone.

    A folder is stale when the PID in its name is not running, or (a name without a
    PID) when it is older than ``min_age`` seconds. A live build's folder is kept
    whatever its age (compiling N = 50 takes over ten minutes).

    Parameters
    ----------
    root : Path
        The cache root.
    min_age : float
        Age in seconds after which a folder without a PID counts as stale.

    Returns
    -------
    list of Path
        The folders removed.
    """
    removed = []
    for d in root.glob(f"{TMP_PREFIX}*"):
        m = re.fullmatch(re.escape(TMP_PREFIX) + r"[0-9a-f]+-(\d+)-.*", d.name)
        if artifacts.stale_temp(d, int(m.group(1)) if m else None, min_age):
            shutil.rmtree(d, ignore_errors=True)
            removed.append(d)
    return removed


def install_entry(tmp: Path, folder: Path) -> None:
    """Rename a complete build into place; a concurrent identical build may have won.

    Parameters
    ----------
    tmp : Path
        The complete build (manifest written).
    folder : Path
        ``<root>/<key>/``.
    """
    for _ in range(2):
        try:
            os.rename(tmp, folder)
            return
        except OSError:
            if entry_problem(folder, folder.name) is None:  # complete entry, other process
                shutil.rmtree(tmp, ignore_errors=True)
                return
            shutil.rmtree(folder, ignore_errors=True)  # incomplete or bad entry: never trusted
    os.rename(tmp, folder)


def discard_entry(folder: Path) -> None:
    """Remove a cache entry: renamed to a temporary name first, so it vanishes at once.

    Parameters
    ----------
    folder : Path
        ``<root>/<key>/``.
    """
    prefix = f"{TMP_PREFIX}{folder.name[:12]}-{os.getpid()}-"
    try:
        aside = Path(tempfile.mkdtemp(dir=folder.parent, prefix=prefix))
        os.rename(folder, aside)  # onto the empty folder just made
    except OSError:  # another process moved or replaced it
        return
    shutil.rmtree(aside, ignore_errors=True)
