"""``meta.json``: what a run was, what shaped it and how long each stage took.

:class:`RunMeta` is the file's content as typed fields in the file's key order
(``dataclasses.asdict`` keeps it); ``verify`` reads the file as a plain dict
(:func:`generated.reuse.reuse_problem`).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from core.errors import ToolkitError
from core.scenario import Scenario
from generated import solvers
from generated.codegen import Library
from generated.sundials_log import sundials_messages as count_sundials_messages
from generated.values import CodegenSettings, IntegratorSettings, Trajectory
from synthesis.gains_cache import GainsInfo


class MetaFileError(ToolkitError):
    """A meta.json that is not the record of a run (missing or unknown keys)."""


@dataclass(frozen=True)
class LibraryRecord:
    """The compiled library a run executed (``meta["library"]``).

    Attributes
    ----------
    key : str
        SHA-256 cache key (the folder name in the build cache).
    path, source : str
        The shared library and its generated C file.
    source_bytes : int
    cache_hit : bool
        True when the library was reused, not compiled.
    cflags : list of str
    compiler : str
    jacobian, jacobian_requested : str
        The Jacobian strategy used (``auto`` resolved from N) and the one asked for.
    expand : bool
        Whether MX Functions were expanded to SX before generating code.
    casadi : str
        The CasADi version.
    structure : str
        The structure key (:func:`symbolic.parameters.structure_key`): runs with equal
        keys execute the same library with their own numbers.
    parameters : int
        Length of the runtime parameter vector p the library was called with.
    """

    key: str
    path: str
    source: str
    source_bytes: int
    cache_hit: bool
    cflags: list[str]
    compiler: str
    jacobian: str
    jacobian_requested: str
    expand: bool
    casadi: str
    structure: str = ""
    parameters: int = 0

    @classmethod
    def of(
        cls,
        lib: Library,
        codegen: CodegenSettings,
        requested: str,
        structure: str = "",
        parameters: int = 0,
    ) -> LibraryRecord:
        """The record of ``lib`` built with ``codegen``.

        Parameters
        ----------
        lib : Library
        codegen : CodegenSettings
            With its Jacobian strategy resolved.
        requested : str
            The Jacobian strategy before resolution.
        structure : str
        parameters : int
        """
        return cls(
            key=lib.key,
            path=str(lib.path),
            source=str(lib.source),
            source_bytes=lib.source_bytes,
            cache_hit=lib.cache_hit,
            cflags=list(codegen.cflags),
            compiler=codegen.compiler,
            jacobian=codegen.jacobian,
            jacobian_requested=requested,
            expand=codegen.expand,
            casadi=ca.__version__,
            structure=structure,
            parameters=parameters,
        )


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
    """The content of ``meta.json``, key by key in the file's order.

    Attributes
    ----------
    scenario, scenario_path, scenario_sha256 : str
        The scenario's name (with a variant suffix), file and SHA-256 (file + overrides).
    overrides : dict
        The ``--set`` overrides (dotted key -> value).
    gains_path, gains_sha256 : str
        The ``gains.json`` used and the SHA-256 of its bytes.
    gains_reused : bool
        True when it was read, False when synthesized for this run.
    method, form : str
        The integration method and the compiled form (``ode`` or ``dae``).
    rtol, atol : float
    max_steps : int
    fixed_step, fixed_rtol, fixed_atol : float or None
        The fixed-step method's step and safeguard tolerances (None for other methods).
    newton_scheme, linear_solver : str
    integrator_extra_options : dict
        Further SUNDIALS options of the large-N plan.
    horizon, output_step : float
    breakpoints : list of float
        Known discontinuity times the integration was split at.
    rows : int
        Data rows of trajectory.csv.
    trajectory_sha256 : str
        SHA-256 of trajectory.csv's bytes (the pair is checked on reuse).
    inputs : dict
        What shaped the run besides the library (:func:`generated.reuse.run_inputs`).
    libraries : dict
        Path -> SHA-256 of every shared library the run executed.
    complete : bool
        False when the integrator stopped before the horizon.
    t_reached : float
    message : str or None
        The integrator's reason for stopping early.
    steps, rhs_evals : int or None
        Integrator steps and right-hand-side evaluations (``stats`` entries).
    stats : dict
        All integrator statistics.
    library : LibraryRecord
    cache_hit : bool
        Same as ``library.cache_hit``.
    wall_seconds : WallSeconds
    sundials_messages : dict
        SUNDIALS' warnings and errors of the run, written to ``sundials.log``
        (:func:`generated.sundials_log.sundials_messages`); absent from older records:
        read back as none.
    """

    scenario: str
    scenario_path: str
    scenario_sha256: str
    overrides: dict[str, Any]
    gains_path: str
    gains_sha256: str
    gains_reused: bool
    method: str
    form: str
    rtol: float
    atol: float
    max_steps: int
    fixed_step: float | None
    fixed_rtol: float | None
    fixed_atol: float | None
    newton_scheme: str
    linear_solver: str
    integrator_extra_options: dict[str, Any]
    horizon: float
    output_step: float
    breakpoints: list[float]
    rows: int
    trajectory_sha256: str
    inputs: dict[str, Any]
    libraries: dict[str, str]
    complete: bool
    t_reached: float
    message: str | None
    steps: int | None
    rhs_evals: int | None
    stats: dict[str, Any]
    library: LibraryRecord
    cache_hit: bool
    wall_seconds: WallSeconds
    sundials_messages: dict[str, Any] = dataclasses.field(
        default_factory=lambda: count_sundials_messages("")
    )

    @classmethod
    def of_run(
        cls,
        *,
        sc: Scenario,
        overrides: Mapping[str, Any] | None,
        gains: GainsInfo,
        form: str,
        settings: IntegratorSettings,
        breakpoints: list[float],
        trajectory: Trajectory,
        csv: tuple[int, str],
        inputs: dict[str, Any],
        libraries: dict[str, str],
        library: LibraryRecord,
        wall_seconds: WallSeconds,
    ) -> RunMeta:
        """The record of one run from its parts.

        Parameters
        ----------
        sc : Scenario
        overrides : mapping or None
        gains : GainsInfo
        form : str
        settings : IntegratorSettings
            Its ``method`` is the run's.
        breakpoints : list of float
        trajectory : Trajectory
        csv : (int, str)
            Data rows and SHA-256 of trajectory.csv.
        inputs, libraries, library, wall_seconds
            See the attributes.
        """
        s = settings
        used = solvers.get(s.method).settings_used(s)  # the method-specific settings
        st = trajectory.stats
        return cls(
            scenario=sc.name,
            scenario_path=str(sc.path),
            scenario_sha256=sc.sha256,
            overrides=dict(overrides or {}),
            gains_path=str(gains.path),
            gains_sha256=gains.sha256,
            gains_reused=gains.reused,
            method=s.method,
            form=form,
            rtol=s.rtol,
            atol=s.atol,
            max_steps=s.max_steps,
            fixed_step=used.get("fixed_step"),
            fixed_rtol=used.get("fixed_rtol"),
            fixed_atol=used.get("fixed_atol"),
            newton_scheme=s.newton_scheme,
            linear_solver=s.linear_solver,
            integrator_extra_options=dict(s.extra_options),
            horizon=sc.integration.horizon,
            output_step=sc.integration.output_step,
            breakpoints=breakpoints,
            rows=csv[0],
            trajectory_sha256=csv[1],
            inputs=inputs,
            libraries=libraries,
            complete=trajectory.complete,
            t_reached=trajectory.t_reached,
            message=trajectory.message,
            steps=st.get("steps"),
            rhs_evals=st.get("rhs_evals"),
            stats=st,
            library=library,
            cache_hit=library.cache_hit,
            wall_seconds=wall_seconds,
            sundials_messages=count_sundials_messages(trajectory.sundials_log),
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
