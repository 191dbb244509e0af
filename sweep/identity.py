"""A study's identity, recorded in its folder (``study.json``) and compared on every run.

What the samples depend on: the seed, ``[set]``, ``[params]``, the ``[graph]``,
``[operator]`` and ``[faults]`` families, ``compare_gains``, the base scenario (path and SHA-256), the
operator traces' SHA-256 and the package's version. ``count``, ``name`` and
``description`` are not part of it: sample k is the same whatever the count.
"""

from __future__ import annotations

import dataclasses
import json
from importlib import metadata
from pathlib import Path
from typing import Any

from core.artifacts import atomic_write_text, sha256_bytes
from core.errors import ToolkitError
from core.files import FileRefused, read_regular_file
from core.provenance import current_commit
from core.scenario import MAX_SCENARIO_BYTES
from sweep.study import Study

IDENTITY = "study.json"
#: largest study.json read (bytes)
MAX_IDENTITY_BYTES = 1 << 22
#: the compared entries, in the order a refusal names them, with their names in it
COMPARED = {
    "seed": "seed",
    "set": "[set]",
    "params": "[params]",
    "graph": "[graph]",
    "operator": "[operator]",
    "faults": "[faults]",
    "compare_gains": "compare_gains",
    "base": "base (path)",
    "base_sha256": "base scenario (SHA-256)",
    "traces_sha256": "operator traces (SHA-256)",
    "version": "package version",
}


class StudyChanged(ToolkitError):
    """The folder holds results of a study other than this one under its name."""


def package_version() -> str:
    """The installed version of this package (``unknown`` when not installed)."""
    try:
        return metadata.version("hitl-formation")
    except metadata.PackageNotFoundError:
        return "unknown"


def _file_sha(path: str, limit: int) -> str:
    try:
        return sha256_bytes(read_regular_file(path, limit))
    except (OSError, FileRefused) as exc:
        return f"unreadable: {exc}"


def _plain(value: Any) -> Any:
    """JSON form (dataclasses as tables, tuples as lists), as read back from the file."""
    if dataclasses.is_dataclass(value):
        value = dataclasses.asdict(value)
    return json.loads(json.dumps(value, default=str))


def _graph(study: Study) -> Any:
    """The ``[graph]`` family's JSON form; ``losses.theorem1`` only when not the default
    (the identities recorded before the key existed stay this study's)."""
    g = _plain(study.graph)
    losses = g.get("losses") if isinstance(g, dict) else None
    if isinstance(losses, dict) and losses.get("theorem1") == "required":
        del losses["theorem1"]
    return g


def study_identity(study: Study) -> dict[str, Any]:
    """The identity of ``study`` (the compared entries :data:`COMPARED`, and ``commit``).

    Parameters
    ----------
    study : Study
        From :func:`sweep.study.load_study`.
    """
    traces = study.operator.traces if study.operator is not None else ()
    return {
        "seed": study.seed,
        "set": _plain(study.fixed),
        "params": _plain(study.params),
        "graph": _graph(study),
        "operator": _plain(study.operator),
        "faults": _plain(study.faults),
        # recorded only when true, so the identity of every other study is unchanged
        **({"compare_gains": True} if study.compare_gains else {}),
        "base": study.base,
        "base_sha256": _file_sha(study.base, MAX_SCENARIO_BYTES),
        "traces_sha256": [_file_sha(t, MAX_SCENARIO_BYTES << 6) for t in traces],
        "version": package_version(),
        "commit": current_commit(),  # recorded, not compared: a fix retries failed rows
    }


def changes(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """What differs between two identities, as the refusal names it.

    Parameters
    ----------
    old, new : dict
        Recorded and current identity.
    """
    out = []
    for key, label in COMPARED.items():
        if old.get(key) != new.get(key):
            if key in ("seed", "version"):
                label += f" {old.get(key)} -> {new.get(key)}"
            out.append(label)
    return out


def check_identity(folder: Path, study: Study, has_results: bool) -> None:
    """Refuse to add rows to ``folder`` when its results came from another study; record
    this study's identity there otherwise.

    Parameters
    ----------
    folder : Path
        The study's folder (its lock held).
    study : Study
        The study about to run.
    has_results : bool
        Whether ``folder`` holds a results table.

    Raises
    ------
    StudyChanged
        One line naming what changed and the fix.
    """
    path = Path(folder) / IDENTITY
    new = study_identity(study)
    fix = (
        f"give another --out DIR or a new `name` to keep both, or rerun with --restart to "
        f"discard the results in {folder}"
    )
    if has_results:
        old = _read(path)
        if old is None:
            raise StudyChanged(
                f"{folder} holds results without {IDENTITY} (the record of the study that made "
                f"them): {fix}"
            )
        diff = changes(old, new)
        if diff:
            raise StudyChanged(
                f"study {study.name}: {', '.join(diff)} changed since the results in {folder} "
                f"were computed: {fix}"
            )
    atomic_write_text(path, json.dumps(new, indent=1) + "\n")


def _read(path: Path) -> dict[str, Any] | None:
    """The recorded identity; None when missing or not an identity."""
    try:
        data = json.loads(read_regular_file(path, MAX_IDENTITY_BYTES))
    except (OSError, FileRefused, ValueError, RecursionError):
        return None
    return data if isinstance(data, dict) else None
