"""Artifacts: where each stage writes, and how (atomically, never half-written)."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

OUT_ROOT = Path(os.environ.get("HITL_OUT", "out"))


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


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` via a temporary file in the same folder and :func:`os.replace`.

    Parameters
    ----------
    path : str or Path
        Destination; its folder is created.
    data : bytes
        Contents.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        # mkstemp creates 0600; give the result the permissions a plain open() would
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Text version of :func:`atomic_write_bytes` (UTF-8).

    Parameters
    ----------
    path : str or Path
        Destination; its folder is created.
    text : str
        Contents.
    """
    return atomic_write_bytes(path, text.encode("utf-8"))


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
