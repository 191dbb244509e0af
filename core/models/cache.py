"""JSON entries of pure functions' results in the build cache (model derivations, gains).

An entry is ``<cache root>/<kind>/<key>.json``: ``{"kind", "key", "body", "body_sha256"}``
with ``body`` plain JSON (numbers, strings, lists, objects). Reading never evaluates
or pickles anything: an entry whose kind, key or checksum does not match, or that is
not JSON at all, reads as missing, so the caller recomputes and rewrites it. Entries are
read only as regular files of bounded size and nesting, and only when the cache root,
the kind's folder and the file are the user's own (:mod:`core.private_files`: an
entry someone else could have written is refused in one line); they are written 0600
in 0700 folders whatever the umask.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

from core.artifacts import atomic_write_text
from core.build_cache import default_build_root
from core.files import FileRefused, read_json_file
from core.private_files import check_trusted, make_private_dir

#: largest entry read (a model's derivation is some 100 kB) and its deepest nesting
MAX_ENTRY_BYTES = 64 << 20
MAX_ENTRY_DEPTH = 64


def entry_path(kind: str, key: str, root: Path | None = None) -> Path:
    """Where the entry ``key`` of ``kind`` lives.

    Parameters
    ----------
    kind : str
        Sub-folder (``"models"``, ``"gains"``).
    key : str
        Hex SHA-256 of the inputs.
    root : Path, optional
        Default :func:`core.build_cache.default_build_root`.
    """
    return (root if root is not None else default_build_root()) / kind / f"{key}.json"


def _digest(body: Any) -> str:
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def read_entry(kind: str, key: str, root: Path | None = None) -> dict[str, Any] | None:
    """The body stored for ``key``, or None when it is missing, malformed or not this key's.

    Parameters
    ----------
    kind, key, root :
        As in :func:`entry_path`.

    Raises
    ------
    BuildError
        The cache root, the kind's folder or the entry is another user's or writable by
        its group or others (:func:`core.private_files.check_trusted`).
    """
    top = root if root is not None else default_build_root()
    path = entry_path(kind, key, top)
    try:
        check_trusted(path, top)
        d = read_json_file(path, MAX_ENTRY_BYTES, MAX_ENTRY_DEPTH)
    except (OSError, ValueError, FileRefused):
        return None
    if not isinstance(d, dict) or d.get("kind") != kind or d.get("key") != key:
        return None
    body = d.get("body")
    ok = isinstance(body, dict) and d.get("body_sha256") == _digest(body)
    return body if ok else None


def write_entry(kind: str, key: str, body: dict[str, Any], root: Path | None = None) -> Path:
    """Store ``body`` for ``key`` atomically (temporary file, then ``os.replace``).

    Parameters
    ----------
    kind, key, root :
        As in :func:`entry_path`.
    body : dict
        Plain JSON values (readers check the numbers they use).
    """
    d = {"kind": kind, "key": key, "body": body, "body_sha256": _digest(body)}
    path = entry_path(kind, key, root)
    make_private_dir(path.parent)
    return atomic_write_text(path, json.dumps(d, sort_keys=True), mode=0o600)


def finite_pair(v: Any) -> tuple[float, float] | None:
    """``v`` as two finite floats, or None (a cache body's numbers are checked before use).

    Parameters
    ----------
    v : Any
        A value read from a cache entry's JSON.
    """
    if not isinstance(v, list) or len(v) != 2:
        return None
    if not all(isinstance(x, float | int) and not isinstance(x, bool) for x in v):
        return None
    lo, hi = float(v[0]), float(v[1])
    return (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else None
