"""Artifacts: where each stage writes, and how (atomically, never half-written)."""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import time
from pathlib import Path

OUT_ROOT = Path(os.environ.get("HITL_OUT", "out"))
#: a leftover temporary file or folder whose name carries no PID is stale after this long
STALE_SECONDS = 600.0


def out_dir(name: str) -> Path:
    """``out/<scenario name>/`` (created).

    Parameters
    ----------
    name : str
        Scenario name.
    """
    d = OUT_ROOT / name
    d.mkdir(parents=True, exist_ok=True)
    return d


def atomic_write_bytes(path: str | Path, data: bytes, mode: int | None = None) -> Path:
    """Write ``data`` to ``path`` via a temporary file in the same folder and :func:`os.replace`.

    Leftover temporary files of killed writers of the same destination are removed
    first (:func:`remove_stale_temps`).

    Parameters
    ----------
    path : str or Path
        Destination; its folder is created.
    data : bytes
        Contents.
    mode : int, optional
        The file's permission bits (e.g. 0o600 in the build cache); default those a
        plain ``open()`` gives under the umask.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(path)
    # the PID in the name lets a later run tell a killed writer's leftover from a live one
    fd, tmp = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp"
    )
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        # mkstemp creates 0600; give the result the permissions a plain open() would
        os.chmod(tmp, 0o666 & ~_umask() if mode is None else mode)
        os.replace(tmp, path)
    except OSError as exc:  # a full disk surfaces in write/close, without a file name
        Path(tmp).unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror, str(path)) from exc
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str, mode: int | None = None) -> Path:
    """Text version of :func:`atomic_write_bytes` (UTF-8).

    Parameters
    ----------
    path : str or Path
        Destination; its folder is created.
    text : str
        Contents.
    mode : int, optional
        As for :func:`atomic_write_bytes`.
    """
    return atomic_write_bytes(path, text.encode("utf-8"), mode)


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 digest of ``data``.

    Parameters
    ----------
    data : bytes
        Bytes to hash.
    """
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 digest of the file at ``path``.

    Parameters
    ----------
    path : str or Path
        File to hash (read whole).
    """
    return sha256_bytes(Path(path).read_bytes())


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def pid_alive(pid: int) -> bool:
    """Whether a process with this PID exists (on this machine).

    Parameters
    ----------
    pid : int
        Process id.
    """
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by another user
        return True
    return True


def stale_temp(path: Path, pid: int | None, min_age: float = STALE_SECONDS) -> bool:
    """Whether a temporary file or folder was left by a writer that is gone.

    Parameters
    ----------
    path : Path
        The temporary file or folder.
    pid : int or None
        The writer's PID from the name: stale exactly when that process is not running
        (a live writer's file is kept whatever its age). None (an older name without a
        PID): stale when not modified for ``min_age`` seconds.
    min_age : float
        Seconds.
    """
    if pid is not None:
        return not pid_alive(pid)
    try:
        return time.time() - path.lstat().st_mtime > min_age
    except FileNotFoundError:
        return False


def remove_stale_temps(path: str | Path, min_age: float = STALE_SECONDS) -> list[Path]:
    """Remove the stale ``.<name>.[<pid>.]<random>.tmp`` leftovers of writes to ``path``.

    Parameters
    ----------
    path : str or Path
        The destination whose leftovers are looked for (in its folder).
    min_age : float
        See :func:`stale_temp`.

    Returns
    -------
    list of Path
        The files removed.
    """
    path = Path(path)
    removed = []
    pattern = re.compile(re.escape(f".{path.name}.") + r"(?:(\d+)\.)?[^/]*\.tmp")
    try:
        candidates = list(path.parent.glob(f".{path.name}.*.tmp"))
    except OSError:
        return removed
    for f in candidates:
        m = pattern.fullmatch(f.name)
        if m is None or not f.is_file():
            continue
        if stale_temp(f, int(m.group(1)) if m.group(1) else None, min_age):
            f.unlink(missing_ok=True)
            removed.append(f)
    return removed
