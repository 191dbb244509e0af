"""Reading a file only when it is a regular file of bounded size (never a FIFO or a device)."""

from __future__ import annotations

import os
import stat
from pathlib import Path


class FileRefused(Exception):
    """A path that is not a regular file of bounded size; the message says what it is."""


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def read_regular_file(path: str | Path, limit: int) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, checked before reading.

    The path is stat'ed before it is opened, so a FIFO (which would block), a device
    such as ``/dev/zero`` (endless) or a directory is refused without being opened;
    the open file is checked again and read no further than ``limit + 1`` bytes.

    Parameters
    ----------
    path : str or Path
        File to read (symbolic links are followed).
    limit : int
        Largest accepted size in bytes.

    Raises
    ------
    FileRefused
        Not a regular file, or larger than ``limit``.
    OSError
        The file cannot be opened or read.
    """

    def check(st: os.stat_result) -> None:
        for is_kind, kind in _KINDS:
            if is_kind(st.st_mode):
                raise FileRefused(f"is {kind}, not a regular file")
        if not stat.S_ISREG(st.st_mode):
            raise FileRefused("is not a regular file")
        if st.st_size > limit:
            raise FileRefused(f"has {st.st_size} bytes, above the limit of {limit}")

    check(os.stat(path))
    # O_NONBLOCK: a file swapped for a FIFO after the stat cannot block the open
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as fh:
        check(os.fstat(fd))
        data = fh.read(limit + 1)
    if len(data) > limit:  # grew after the stat
        raise FileRefused(f"has more than {limit} bytes")
    return data
