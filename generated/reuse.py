"""Whether a previous run may be reused: the inputs that shaped it and the files it left.

A run's ``meta.json`` records the SHA-256 of its scenario (with overrides), the operator
trace, ``gains.json``, the sources of :data:`CODE_PACKAGES`, the CasADi version and
every shared library it executed; :func:`reuse_problem` accepts the run only when all
of them are unchanged and ``trajectory.csv`` is the file meta.json describes.
"""

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
    """SHA-256 of the sources that shape a trajectory (git-independent).

    Every ``*.py``, ``*.c`` and ``*.h`` file under :data:`CODE_PACKAGES` (not the
    build cache), by relative path and content.
    """
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
        Its hash (the TOML and any overrides) and the data of the files it names.
    gains_sha256 : str or None
        SHA-256 of the ``gains.json`` bytes used.
    method : str
        The integration method.
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
        The build (its library, or the per-agent kernel libraries of method ``native``).
    """
    libs = [built.library] if built.agents is None else list(built.agents[0])
    return {str(lib.path): sha256_file(lib.path) for lib in libs}


def reuse_problem(
    folder: Path, sc: Scenario, method: str | None = None
) -> tuple[str | None, tuple[dict[str, Any], bytes] | None]:
    """Whether ``folder``'s trajectory.csv and meta.json may be reused for ``sc``.

    They may only if meta.json records exactly today's inputs (:func:`run_inputs`
    with the current ``gains.json``), every library it records still has its hash,
    the run is complete, and trajectory.csv has the SHA-256 and row count meta.json
    records (a kill between the two renames leaves a mismatched pair: not reused).

    Parameters
    ----------
    folder : Path
        ``out/<name>/``.
    sc : Scenario
        The scenario to be verified.
    method : str, optional
        Default: the scenario's.

    Returns
    -------
    (str or None, (dict, bytes) or None)
        The reason not to reuse (None to reuse), and meta.json with the CSV bytes.
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
    want = run_inputs(
        sc, sha256_file(gp) if gp.is_file() else None, method or sc.integration.method
    )
    for k, v in want.items():
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
