"""Reading a file only when it is a regular file of bounded size (never a FIFO or a device)."""

from __future__ import annotations

import json
import os
import re
import stat
from pathlib import Path
from typing import Any

import numpy as np


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
        st = os.fstat(fd)
        check(st)
        # a buffer of the file's size, not of the limit (a read of n bytes allocates n)
        data = fh.read(st.st_size + 1)
        if len(data) > st.st_size:  # it grows: read on, still no further than the limit
            data += fh.read(limit + 1 - len(data))
    if len(data) > limit:  # grew after the stat
        raise FileRefused(f"has more than {limit} bytes")
    return data


#: strings of a JSON text (their brackets do not nest)
_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)


def json_depth(data: bytes) -> int:
    """How deep the arrays and objects of a JSON text nest (0 for a scalar), without parsing.

    Counted over the text with its strings removed, without recursion: a file of a
    million nested brackets costs a linear scan, not a ``RecursionError``.

    Parameters
    ----------
    data : bytes
        The JSON text.
    """
    skeleton = np.frombuffer(_JSON_STRING.sub(b'""', data), dtype=np.uint8)
    if not len(skeleton):
        return 0
    step = np.isin(skeleton, _OPEN).astype(np.int64) - np.isin(skeleton, _CLOSE)
    return int(max(np.cumsum(step).max(), 0))


_OPEN = np.frombuffer(b"[{", dtype=np.uint8)
_CLOSE = np.frombuffer(b"]}", dtype=np.uint8)


def parse_json(data: bytes, max_depth: int) -> Any:
    """Parse a JSON text nested at most ``max_depth`` deep (depth checked before parsing).

    Parameters
    ----------
    data : bytes
        UTF-8 JSON text (already bounded in size, e.g. by :func:`read_regular_file`).
    max_depth : int
        Deepest accepted nesting of arrays and objects.

    Raises
    ------
    FileRefused
        Nested deeper than ``max_depth``.
    ValueError
        Not UTF-8 (``UnicodeDecodeError``) or not JSON (``json.JSONDecodeError``).
    """
    depth = json_depth(data)
    if depth > max_depth:
        raise FileRefused(f"nests {depth} levels deep, above the limit of {max_depth}")
    try:
        return json.loads(data.decode("utf-8"))
    except RecursionError:  # unreachable below a sane max_depth; the last guard
        raise FileRefused(f"nests too deep (limit {max_depth})") from None


def read_json_file(path: str | Path, limit: int, max_depth: int) -> Any:
    """The JSON value of a regular file of at most ``limit`` bytes nested at most ``max_depth``.

    Parameters
    ----------
    path : str or Path
        File to read (:func:`read_regular_file`).
    limit : int
        Largest accepted size in bytes.
    max_depth : int
        Deepest accepted nesting (:func:`parse_json`).

    Raises
    ------
    FileRefused
        Not a regular file, too large or too deep.
    ValueError
        Not UTF-8 or not JSON.
    OSError
        The file cannot be opened or read.
    """
    return parse_json(read_regular_file(path, limit), max_depth)
