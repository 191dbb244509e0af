"""Folders and files only their user can write: how the build cache is created and trusted.

The build cache holds compiled libraries this process loads and runs, so it is trusted
as ssh trusts a key: a folder or file is trusted when it is owned by the calling user
(or by root) and writable by neither its group nor others. Folders are created 0700 and
files 0600 (0700 for a library) whatever the umask (:func:`make_private_dir`,
:func:`seal`); anything else is refused before it is read (:func:`untrusted`).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from core.errors import BuildError

#: mode bits that let someone other than the owner replace or rewrite a file
_OTHERS_WRITE = stat.S_IWGRP | stat.S_IWOTH


def make_private_dir(path: Path) -> Path:
    """Create ``path`` and its missing parents with mode 0700, whatever the umask.

    Folders that already exist are left as they are (:func:`untrusted` judges them).

    Parameters
    ----------
    path : Path
        The folder.

    Returns
    -------
    Path
        ``path``.
    """
    missing = []
    p = Path(path)
    while not os.path.lexists(p):
        missing.append(p)
        if p.parent == p:
            break
        p = p.parent
    for d in reversed(missing):
        try:
            os.mkdir(d, 0o700)
        except FileExistsError:  # another process made it meanwhile
            continue
        os.chmod(d, 0o700)  # exactly 0700: mkdir's mode went through the umask
    return Path(path)


def seal(folder: Path) -> None:
    """Give a folder built by this process and everything in it private modes.

    Folders 0700, executable files 0700 (a library), other files 0600; symbolic links
    are left alone (nothing in a build makes one, and :func:`untrusted` refuses them).

    Parameters
    ----------
    folder : Path
        A folder this process created (a build's temporary folder).
    """
    os.chmod(folder, 0o700)
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in dirnames:
            p = os.path.join(dirpath, name)
            if not os.path.islink(p):
                os.chmod(p, 0o700)
        for name in filenames:
            p = os.path.join(dirpath, name)
            st = os.lstat(p)
            if stat.S_ISREG(st.st_mode):
                os.chmod(p, 0o700 if st.st_mode & stat.S_IXUSR else 0o600)


def _owner_name(uid: int) -> str:
    try:
        import pwd

        return f"{pwd.getpwuid(uid).pw_name} (uid {uid})"
    except (ImportError, KeyError):
        return f"uid {uid}"


def _problem(path: Path, st: os.stat_result) -> str | None:
    """Why ``path`` with status ``st`` is not trusted (None: it is)."""
    me = os.getuid()
    if st.st_uid not in (me, 0):
        return f"{path} is owned by {_owner_name(st.st_uid)}, not by you ({_owner_name(me)})"
    if st.st_mode & _OTHERS_WRITE:
        who = " and ".join(
            w
            for bit, w in ((stat.S_IWGRP, "its group"), (stat.S_IWOTH, "others"))
            if st.st_mode & bit
        )
        return f"{path} is writable by {who} (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def untrusted(path: Path, root: Path) -> tuple[Path, str] | None:
    """Whether ``path`` (at or below ``root``) may have been written by someone else.

    ``root`` and every folder from it down to ``path`` (inclusive), checked in that
    order, must be owned by the calling user or root and writable by no group and no
    other user; below ``root`` none may be a symbolic link. ``root`` itself is followed
    if it is a link (a link given as ``HITL_BUILD_DIR``).

    Parameters
    ----------
    path : Path
        A file or folder at or below ``root``.
    root : Path
        The trusted tree's top (the cache root).

    Returns
    -------
    (Path, str) or None
        The first path refused and why, e.g. ``/tmp/c is writable by others (mode 0777)``;
        None when all are trusted.

    Raises
    ------
    OSError
        A path cannot be examined (missing, permission denied).
    ValueError
        ``path`` is not at or below ``root``.
    """
    path, root = Path(path), Path(root)
    rel = path.relative_to(root)
    why = _problem(root, os.stat(root))
    if why is not None:
        return root, why
    p = root
    for part in rel.parts:
        p = p / part
        st = os.lstat(p)
        why = f"{p} is a symbolic link" if stat.S_ISLNK(st.st_mode) else _problem(p, st)
        if why is not None:
            return p, why
    return None


def check_trusted(path: Path, root: Path) -> None:
    """Refuse, in one line with the fix, a build-cache path someone else could have written.

    Parameters
    ----------
    path : Path
        A file or folder at or below ``root`` (missing ones raise ``OSError``).
    root : Path
        The cache root.

    Raises
    ------
    BuildError
        ``root`` or a folder or file on the way to ``path`` is not trusted
        (:func:`untrusted`); the message names it and says what to do.
    OSError
        A path cannot be examined.
    """
    found = untrusted(path, root)
    if found is None:
        return
    bad, why = found
    if bad == Path(root):
        raise BuildError(
            f"build cache refused: {why}; whoever can write there could plant code this "
            f"process runs (chmod 700 {root} if it is yours, or set HITL_BUILD_DIR to a "
            "folder only you can write)"
        )
    entry = Path(root) / Path(path).relative_to(root).parts[0]
    raise BuildError(
        f"build cache entry refused, not loaded: {why} (remove it: rm -rf {entry}, or "
        "empty the cache: python -m generated cache --clear; a rebuild is private, folders "
        "0700 and files 0600)"
    )
