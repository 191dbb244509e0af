"""Whether a previous run may be reused: the inputs that shaped it and the files it left
(docs/simulation.md)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from core.artifacts import sha256_file
from core.files import FileRefused, read_json_file
from core.memo import MEMO
from core.scenario import Scenario
from generated.trajectory_file import INCOMPLETE_MARK, data_rows

if TYPE_CHECKING:
    from generated.built import Built

#: packages whose sources shape a trajectory (their hash is part of the reuse key)
CODE_PACKAGES = ("symbolic", "synthesis", "generated")
#: largest meta.json read back (a run's has a few kB) and its deepest nesting
MAX_META_BYTES = 16 << 20
MAX_META_DEPTH = 32


@MEMO.memoize("code-sha256", 1)
def code_sha256() -> str:
    """SHA-256 of every ``*.py``, ``*.c`` and ``*.h`` of :data:`CODE_PACKAGES` (not the build
    cache) by relative path and content: git-independent."""
    base = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for pkg in CODE_PACKAGES:
        for f in sorted((base / pkg).rglob("*")):
            if f.suffix in (".py", ".c", ".h") and "build" not in f.relative_to(base).parts:
                h.update(f.relative_to(base).as_posix().encode() + b"\0")
                h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def _trace_sha256(sc: Scenario) -> str | None:
    """SHA-256 of the operator trace the scenario loaded (``u0_csv``), None without one."""
    tr = sc.leader.u0_trace
    if tr is None:
        return None
    a = np.ascontiguousarray(np.asarray(tr, dtype=float))
    return hashlib.sha256(repr(a.shape).encode() + a.tobytes()).hexdigest()


def run_inputs(sc: Scenario, gains_sha256: str | None, method: str) -> dict[str, Any]:
    """What shaped a run, except the compiled library: the reuse key's scenario-side part.

    Parameters
    ----------
    sc : Scenario
    gains_sha256 : str or None
        SHA-256 of the ``gains.json`` bytes used.
    method : str
    """
    return {
        "scenario_sha256": sc.sha256,
        "u0_trace_sha256": _trace_sha256(sc),
        "gains_sha256": gains_sha256,
        "method": method,
        "code_sha256": code_sha256(),
        "casadi": ca.__version__,
    }


def library_hashes(built: Built) -> dict[str, str]:
    """SHA-256 of every shared library a run executes (path -> hash).

    Parameters
    ----------
    built : Built
        Its library, or the per-agent kernel libraries of method ``native``.
    """
    libs = [built.library] if built.agents is None else list(built.agents[0])
    return {str(lib.path): sha256_file(lib.path) for lib in libs}


def reuse_problem(
    folder: Path, sc: Scenario, method: str | None = None
) -> tuple[str | None, tuple[dict[str, Any], bytes] | None]:
    """Why ``folder``'s trajectory.csv and meta.json may not be reused for ``sc`` (None: they
    may), and meta.json with the CSV bytes when they may.

    Parameters
    ----------
    folder : Path
        ``out/<name>/``.
    sc : Scenario
    method : str, optional
        Default: the scenario's.
    """
    meta_p, csv_p = folder / "meta.json", folder / "trajectory.csv"
    if not (meta_p.is_file() and csv_p.is_file()):
        return "no previous run", None
    try:
        meta = read_json_file(meta_p, MAX_META_BYTES, MAX_META_DEPTH)
        data = csv_p.read_bytes()
    except (OSError, ValueError, FileRefused):  # not JSON, too large or too deep
        return "meta.json unreadable", None
    if not isinstance(meta, dict) or not isinstance(meta.get("inputs"), dict):
        return "meta.json records no inputs (older run)", None
    gp = folder / "gains.json"
    gains_sha256 = sha256_file(gp) if gp.is_file() else None
    for k, v in run_inputs(sc, gains_sha256, method or sc.integration.method).items():
        if meta["inputs"].get(k) != v:
            return f"{k} changed since the run", None
    libs = meta.get("libraries")
    if not isinstance(libs, dict) or not libs:
        return "meta.json records no library hash", None
    for path, digest in libs.items():
        if not Path(path).is_file() or sha256_file(path) != digest:
            return f"library {path} is gone or changed", None
    if not meta.get("complete", False):
        return "the run is incomplete", None
    if hashlib.sha256(data).hexdigest() != meta.get("trajectory_sha256"):
        return "trajectory.csv is not the file meta.json describes (SHA-256 differs)", None
    try:
        rows = data_rows(data.decode("utf-8"))
    except UnicodeDecodeError:
        return "trajectory.csv is not text", None
    if rows != meta.get("rows") or data.startswith(INCOMPLETE_MARK.encode()):
        return f"trajectory.csv has {rows} rows, meta.json records {meta.get('rows')}", None
    return None, (meta, data)
