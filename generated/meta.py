"""``meta.json``: what a run was, what shaped it and how long each stage took.

:class:`RunMeta` is the file's content as typed fields in the file's key order
(``dataclasses.asdict`` keeps it); ``verify`` reads the file as a plain dict
(:func:`generated.reuse.reuse_problem`).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.errors import ToolkitError
from generated.sundials_log import sundials_messages as count_sundials_messages


class MetaFileError(ToolkitError):
    """A meta.json that is not the record of a run (missing or unknown keys)."""


@dataclass(frozen=True)
class LibraryRecord:
    """The compiled library a run executed (``meta["library"]``)."""

    key: str  # SHA-256 cache key (the folder name in the build cache)
    path: str
    source: str  # the generated C file
    source_bytes: int
    cache_hit: bool  # reused, not compiled
    cflags: list[str]
    compiler: str
    jacobian: str  # the Jacobian strategy used (``auto`` resolved from N)
    jacobian_requested: str
    expand: bool  # MX Functions expanded to SX before generating code
    casadi: str  # the CasADi version
    # the structure key (symbolic.parameters.structure_key): runs with equal keys execute
    # the same library with their own numbers, the runtime parameters p of this length
    structure: str = ""
    parameters: int = 0


@dataclass(frozen=True)
class WallSeconds:
    """Wall time of each stage of a run in seconds (``meta["wall_seconds"]``); ``compile`` is
    0 on a cache hit, ``integration`` the integrator's own ``stats["wall_seconds"]``."""

    load: float
    synthesis: float
    symbolic_build: float
    codegen: float
    compile: float
    integration: float | None
    outputs: float
    write: float
    total: float


@dataclass(frozen=True)
class RunMeta:
    """The content of ``meta.json``, key by key in the file's order."""

    scenario: str  # the name, with a variant suffix
    scenario_path: str
    scenario_sha256: str  # of the file and the overrides
    overrides: dict[str, Any]  # the ``--set`` overrides: dotted key -> value
    gains_path: str
    gains_sha256: str  # of the gains.json bytes used
    gains_reused: bool  # False: synthesized for this run
    method: str
    form: str  # the compiled form, ``ode`` or ``dae``
    rtol: float
    atol: float
    max_steps: int
    fixed_step: float | None  # the fixed-step method's step and safeguard tolerances
    fixed_rtol: float | None
    fixed_atol: float | None
    newton_scheme: str
    linear_solver: str
    integrator_extra_options: dict[str, Any]  # further SUNDIALS options of the large-N plan
    horizon: float
    output_step: float
    breakpoints: list[float]  # known discontinuity times the integration was split at
    rows: int  # data rows of trajectory.csv
    trajectory_sha256: str  # of trajectory.csv's bytes (the pair is checked on reuse)
    inputs: dict[str, Any]  # what shaped the run besides the library (reuse.run_inputs)
    libraries: dict[str, str]  # path -> SHA-256 of every shared library the run executed
    complete: bool  # False when the integrator stopped before the horizon
    t_reached: float
    message: str | None  # the integrator's reason for stopping early
    steps: int | None
    rhs_evals: int | None
    stats: dict[str, Any]  # all integrator statistics
    library: LibraryRecord
    cache_hit: bool  # same as library.cache_hit
    wall_seconds: WallSeconds
    # SUNDIALS' warnings and errors of the run, written to sundials.log
    # (sundials_log.sundials_messages); absent from older records: read back as none
    sundials_messages: dict[str, Any] = dataclasses.field(
        default_factory=lambda: count_sundials_messages("")
    )

    def to_dict(self) -> dict[str, Any]:
        """The record as meta.json's dict (nested records as dicts, keys in field order)."""
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        """The meta.json text: indented JSON; numpy values as plain numbers and lists."""
        return json.dumps(self.to_dict(), indent=2, default=_json)

    @classmethod
    def from_json(cls, text: str) -> RunMeta:
        """Read a meta.json text back.

        Parameters
        ----------
        text : str

        Raises
        ------
        MetaFileError
            If it is not JSON or its keys are not exactly those of a run's record.
        """
        try:
            d = json.loads(text)
            lib = LibraryRecord(**d["library"])
            wall = WallSeconds(**d["wall_seconds"])
            return cls(**{**d, "library": lib, "wall_seconds": wall})
        except (json.JSONDecodeError, TypeError, KeyError) as exc:
            raise MetaFileError(
                f"meta.json is not a run's record ({' '.join(str(exc).split())[:120]}); "
                "simulate again to rewrite it"
            ) from None


def _json(o: Any) -> Any:
    """JSON form of numpy scalars and arrays; ``str`` of anything else ``json`` cannot write."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
