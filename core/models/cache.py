"""JSON entries of pure functions' results in the build cache (model derivations, gains).

An entry is ``<cache root>/<kind>/<key>.json``: ``{"kind", "key", "body", "body_sha256"}``
with ``body`` plain JSON (numbers, strings, lists, objects). Reading never evaluates
or pickles anything: an entry whose kind, key or checksum does not match, or that is
not JSON at all, reads as missing, so the caller recomputes and rewrites it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

from core.artifacts import atomic_write_text

#: the build cache root unless ``HITL_BUILD_DIR`` is set (the rule of
#: ``generated.codegen.default_build_root``, which core may not import)
APP_NAME = "hitl-formation"


def cache_root() -> Path:
    """``$HITL_BUILD_DIR``, else the user cache folder's ``hitl-formation/build``."""
    env = os.environ.get("HITL_BUILD_DIR")
    if env:
        return Path(env)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir(APP_NAME)) / "build"


def entry_path(kind: str, key: str, root: Path | None = None) -> Path:
    """Where the entry ``key`` of ``kind`` lives.

    Parameters
    ----------
    kind : str
        Sub-folder (``"models"``, ``"gains"``).
    key : str
        Hex SHA-256 of the inputs.
    root : Path, optional
        Default :func:`cache_root`.
    """
    return (root if root is not None else cache_root()) / kind / f"{key}.json"


def _digest(body: Any) -> str:
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def read_entry(kind: str, key: str, root: Path | None = None) -> dict[str, Any] | None:
    """The body stored for ``key``, or None when it is missing, malformed or not this key's.

    Parameters
    ----------
    kind, key, root :
        As in :func:`entry_path`.
    """
    try:
        d = json.loads(entry_path(kind, key, root).read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
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
    return atomic_write_text(entry_path(kind, key, root), json.dumps(d, sort_keys=True))


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
