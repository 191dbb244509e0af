"""One run at a time in a study's folder: an exclusive lock on ``<folder>/.lock``.

The lock is the kernel's (``flock``) on the open file, so it ends with its process,
however that process ends: a lock file left by a dead run names a PID that holds
nothing, and the next run takes it. The file carries the holder's PID and host, for
the refusal's message. A run that created the folder and fails before writing results
removes the lock file while holding it; a run that locked the removed file meanwhile
sees it is no longer the folder's lock file and locks the new one.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from core.errors import ToolkitError

LOCK = ".lock"


class StudyLocked(ToolkitError):
    """Another process holds the study folder's lock."""


@contextmanager
def study_lock(folder: Path) -> Iterator[Path]:
    """Hold the lock of ``folder`` (created) while the block runs.

    Parameters
    ----------
    folder : Path
        The study's folder.

    Yields
    ------
    Path
        The lock file.

    Raises
    ------
    StudyLocked
        Another process holds it: one line naming its PID and the fix.
    """
    path = Path(folder) / LOCK
    for _ in range(_TRIES):
        # never through a symbolic link, never a FIFO or device planted under the name
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK
        try:
            fd = os.open(path, flags, 0o666)
        except OSError as exc:
            raise StudyLocked(
                f"{path}: cannot open the study's lock file ({exc.strerror}): remove it if it "
                "is not a regular file, or give another --out DIR"
            ) from None
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise StudyLocked(
                    f"{path} is not a regular file: remove it, or give another --out DIR"
                )
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise StudyLocked(
                f"{folder} is in use by another run of this study ({holder}, lock {path}): "
                "wait for it to finish, or give another --out DIR"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        if _same_file(fd, path):
            break
        os.close(fd)  # the holder removed the file before releasing it: lock the new one
    else:
        raise StudyLocked(f"{path} keeps being replaced: another run is starting; try again")
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {socket.gethostname()}\n".encode(), 0)
        yield path
    finally:
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
        os.close(fd)  # releases the lock


#: attempts to lock a lock file that its holder removes meanwhile
_TRIES = 10


def _same_file(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is still the file at ``path``."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


def _holder(fd: int) -> str:
    """``PID <pid> on <host>`` from the lock file (``PID unknown`` while it is written)."""
    words = os.pread(fd, 200, 0).decode("utf-8", "replace").split()
    if not words or not words[0].isdigit():
        return "PID unknown"
    return f"PID {words[0]}" + (f" on {words[1]}" if len(words) > 1 else "")
