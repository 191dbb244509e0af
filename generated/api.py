"""The simulation pipeline as functions: the command line and a notebook share them.

::

    from generated import api
    sc = api.load("scenarios/paper.toml")                      # or overrides={...}
    gains, ginfo = api.ensure_gains(sc)                        # synthesis if needed
    built = api.build(sc, gains)                               # closed loop -> C -> .so
    traj = api.simulate(built, sc)                             # the scenario's method
    df = api.trajectory_frame(built, sc, traj)                 # pandas DataFrame
    result = api.run("scenarios/paper.toml", overrides={"options.ablation": True})
    # all at once -> out/paper-ablation/trajectory.csv, meta.json (eq. (42): u_i = Ψ_i, no ĝ_i)

A scenario with overrides is a distinct scenario: its name gets a suffix (``variant=``
chooses it) and its SHA-256 covers the overrides, so its gains, library and outputs
never mix with the base run's.
"""

from __future__ import annotations

import dataclasses
import hashlib
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pandas as pd

from core.artifacts import OUT_ROOT, atomic_write_text
from core.errors import ScenarioError
from core.memo import MEMO
from core.overrides import load, parse_override
from core.scenario import Scenario
from generated import solvers
from generated.built import Built
from generated.codegen import Library, build_library, cache_root
from generated.csource import check_dyn_signature, renamed
from generated.largescale import choose_plan
from generated.loaded import BUILDS, DAE_NAME, ODE_NAME, OUT_NAME, Image, current, open_image
from generated.meta import LibraryRecord, RunMeta, WallSeconds
from generated.progress import progress_bar
from generated.reuse import library_hashes, reuse_problem, run_inputs
from generated.schedule import output_grid
from generated.sundials_log import sundials_messages, sundials_summary
from generated.trajectory_file import (
    column_names,
    csv_text,
    evaluate_outputs,
    read_trajectory,
    trajectory_frame,
    trajectory_text,
)
from generated.values import CodegenSettings, IntegratorSettings, Trajectory, stop_note
from symbolic.closed_loop import bind, build_closed_loop, fix_parameters
from symbolic.parameters import DENSE_MAX_N, structure_key
from synthesis.gains import Gains
from synthesis.gains_cache import GainsInfo, ensure_gains, scenario_gains

#: the names other packages use, from this module or re-exported from the modules above
__all__ = [
    "RunResult",
    "breakpoints",
    "build",
    "build_from_closed_loop",
    "column_names",
    "csv_text",
    "ensure_gains",
    "scenario_gains",
    "evaluate_outputs",
    "integrate_built",
    "integrator_settings",
    "load",
    "parse_override",
    "read_trajectory",
    "resolve_codegen",
    "reuse_problem",
    "run",
    "simulate",
    "trajectory_frame",
    "with_method",
]


# --------------------------------------------------------------------------- scenario
def with_method(sc: Scenario, method: str | None) -> Scenario:
    """``sc`` with ``integration.method`` replaced (unchanged for ``None``; same name).

    Parameters
    ----------
    sc : Scenario
    method : str or None
        A registered method (:func:`generated.solvers.names`).

    Raises
    ------
    ScenarioError
        An unknown method, or one the scenario's rules refuse (``Scenario.validate``).
    """
    if method is None:
        return sc
    if method not in solvers.names():
        raise ScenarioError(
            str(sc.path), "integration.method", f"{method!r} is unknown", ", ".join(solvers.names())
        )
    return dataclasses.replace(sc, integration=dataclasses.replace(sc.integration, method=method))


# --------------------------------------------------------------------------- build
def resolve_codegen(N: int, settings: CodegenSettings | None = None) -> CodegenSettings:
    """``settings`` with ``jacobian="auto"`` resolved for N followers (the large-N plan).

    Parameters
    ----------
    N : int
    settings : CodegenSettings, optional
        Default ``CodegenSettings(jacobian="auto")``.
    """
    settings = settings or CodegenSettings(jacobian="auto")
    plan = choose_plan(N, settings.jacobian, linear_solver=settings.linear_solver)
    return plan.codegen_settings(settings)


def build(
    sc: Scenario,
    gains: Gains,
    method: str | None = None,
    settings: CodegenSettings | None = None,
    closed_loop: Any = None,
    dense_graph: bool = False,
) -> Built:
    """Symbolic closed loop -> C -> shared library (cached) -> loaded Functions.

    A scenario whose structure (:func:`symbolic.parameters.structure_key`) was built
    before in this process reuses that build with its own numbers: nothing symbolic, no
    code generation, no compiler.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    method : str, optional
        A registered method (default: the scenario's).
    settings : CodegenSettings, optional
        ``jacobian="auto"`` is resolved from ``sc.N`` (:func:`resolve_codegen`).
    closed_loop : ClosedLoop, optional
        A prebuilt closed loop (skips ``build_closed_loop``).
    dense_graph : bool
        For a method with its own libraries (``native``), the closed loop with the graph
        as data (``build_closed_loop(dense=True)``): one symbolic build per N for a study's
        many graphs, up to :data:`~symbolic.parameters.DENSE_MAX_N` followers.
    """
    settings = resolve_codegen(sc.N, settings)
    method = method or sc.integration.method
    t0 = time.perf_counter()
    # first: what the method needs of the scenario itself (the per-agent engine's kernels)
    prepared = solvers.get(method).prepare(sc, gains)
    dense = dense_graph and prepared is not None and sc.N <= DENSE_MAX_N
    # the cache folder is part of the key: a build of another cache (HITL_BUILD_DIR) is not reused
    key = (structure_key(sc, gains, dense=dense), method, settings, cache_root(settings))
    if prepared is not None:  # the method's own libraries: only the closed loop is reused
        if closed_loop is None:
            closed_loop = _loop_of(sc, gains, key, dense)
        return _compile(closed_loop, method, settings, t0, prepared)[0]
    if closed_loop is None and key in BUILDS:
        cl, image = BUILDS[key]
        image = current(image)
        if image is not None:
            BUILDS[key] = (cl, image)
            lib = dataclasses.replace(
                image.library, cache_hit=True, codegen_seconds=0.0, compile_seconds=0.0
            )
            cl = _bind(cl, sc, gains, key[0])
            return _bound(cl, lib, image.dyn_p, image.outputs_p, image.form, 0.0)
        del BUILDS[key]  # its entry no longer checks out: build again (the cache says why)
    if closed_loop is None:
        closed_loop = build_closed_loop(sc, gains)
    built, image = _compile(closed_loop, method, settings, t0, prepared)
    if image is not None and closed_loop.parametric is not None:
        BUILDS[key] = (built.closed_loop, image)
    return built


#: symbolic closed loops of the per-agent builds of this process, by structure (core/memo.py)
_LOOPS = MEMO.namespace("per-agent-loops", 16)


def _bind(cl: Any, sc: Scenario, gains: Gains, structure: str) -> Any:
    """The parametric closed loop of ``cl`` bound to ``sc``'s numbers."""
    return bind(cl.parametric, sc, gains, assembly=cl.assembly, blocks=cl.blocks, key=structure)


def _loop_of(sc: Scenario, gains: Gains, key: tuple, dense: bool) -> Any:
    """``sc``'s closed loop: the one kept for its structure ``key`` bound to its numbers, or a
    new symbolic build (kept); ``dense``: the graph as data."""
    cl = _LOOPS.get(key)
    if cl is None or cl.parametric is None:
        cl = build_closed_loop(sc, gains, dense=dense)
    else:
        cl = _bind(cl, sc, gains, key[0])
    _LOOPS[key] = cl
    return cl


def build_from_closed_loop(
    cl: Any, method: str, settings: CodegenSettings | None = None, *, prepared: Any = None
) -> Built:
    """Compile an existing :class:`~symbolic.closed_loop.ClosedLoop` for ``method``.

    Parameters
    ----------
    cl : ClosedLoop
    method : str
        A registered method: its ``form`` picks ``dae_dyn`` or ``ode_dyn``, its
        :meth:`~generated.solvers.Solver.build` what else is compiled.
    settings : CodegenSettings, optional
        ``jacobian="auto"`` is resolved from the closed loop's N (:func:`resolve_codegen`).
    prepared : object, optional
        What the method's :meth:`~generated.solvers.Solver.prepare` returned for the scenario.
    """
    return _compile(cl, method, settings, time.perf_counter(), prepared)[0]


def _compile(
    cl: Any, method: str, settings: CodegenSettings | None, t0: float, prepared: Any
) -> tuple[Built, Image | None]:
    """The Built of ``cl`` (symbolic build timed from ``t0``) and its loaded library (None
    when the method runs its own libraries)."""
    solver = solvers.get(method)
    settings = resolve_codegen(cl.layout.N, settings)
    form = solver.form
    plan = solver.build(cl, settings, prepared)
    src = cl if cl.parametric is None else cl.parametric
    if plan.libraries:
        # nothing of the closed loop is compiled: its Functions run in CasADi's virtual
        # machine; the record is the first library's, a cache hit only when all were
        libs = plan.libraries
        lib = dataclasses.replace(
            libs[0],
            cache_hit=all(lib.cache_hit for lib in libs),
            codegen_seconds=sum(lib.codegen_seconds for lib in libs),
            compile_seconds=sum(lib.compile_seconds for lib in libs),
        )
        t_sym = time.perf_counter() - t0 - lib.codegen_seconds - lib.compile_seconds
        dyn_p = src.dae_dyn if form == "dae" else src.ode_dyn
        return _bound(cl, lib, dyn_p, src.outputs, form, t_sym, (libs, plan.data)), None
    dyn, name = (src.dae_dyn, DAE_NAME) if form == "dae" else (src.ode_dyn, ODE_NAME)
    check_dyn_signature(dyn, f"closed loop {form}_dyn")
    dyn = renamed(dyn, name, expand=settings.expand, cse=settings.cse)
    outs = renamed(src.outputs, OUT_NAME, expand=settings.expand, cse=settings.cse)
    t_sym = time.perf_counter() - t0
    lib = build_library([dyn, outs], settings, with_derivatives=[name])
    image = open_image(lib, form)
    return _bound(cl, lib, image.dyn_p, image.outputs_p, form, t_sym), image


def _bound(
    cl: Any, lib: Library, dyn_p: Any, outputs_p: Any, form: str, t_sym: float, agents: Any = None
) -> Built:
    """The Built of ``cl`` on ``dyn_p``, ``outputs_p`` (p an input when ``cl`` is parametric)
    with ``cl``'s p filled in; ``t_sym``: seconds of the symbolic build."""
    timings = dict(symbolic_build=t_sym, codegen=lib.codegen_seconds, compile=lib.compile_seconds)
    if cl.parametric is None:
        return Built(cl, lib, dyn_p, outputs_p, form, timings, agents=agents)
    p = np.asarray(cl.p0, dtype=float)
    fixed = (fix_parameters(dyn_p, p), fix_parameters(outputs_p, p))
    return Built(cl, lib, *fixed, form, timings, agents, p, dyn_p, outputs_p)


# --------------------------------------------------------------------------- simulate
def integrator_settings(
    sc: Scenario,
    method: str | None = None,
    codegen: CodegenSettings | None = None,
    fixed_tol: float | None = None,
) -> IntegratorSettings:
    """The scenario's integration settings with the codegen plan's linear algebra.

    Parameters
    ----------
    sc : Scenario
    method : str, optional
        Overrides ``integration.method``.
    codegen : CodegenSettings, optional
        Its Jacobian strategy (``auto`` resolved from ``sc.N``) gives the Newton scheme,
        linear solver and extra SUNDIALS options (:func:`generated.largescale.choose_plan`).
    fixed_tol : float, optional
        Safeguard tolerance of the fixed-step method (``fixed_rtol`` and ``fixed_atol``;
        default 1e-3).
    """
    ig = sc.integration
    cg = codegen or CodegenSettings(jacobian="auto")
    plan = choose_plan(sc.N, cg.jacobian, linear_solver=cg.linear_solver)
    extra = {} if fixed_tol is None else {"fixed_rtol": fixed_tol, "fixed_atol": fixed_tol}
    base = IntegratorSettings(
        **extra,
        method=method or ig.method,
        rtol=ig.rtol,
        atol=ig.atol,
        max_steps=ig.max_steps,
        fixed_step=ig.fixed_step,
    )
    return plan.integrator_settings(base)


def breakpoints(built: Built, sc: Scenario) -> list[float]:
    """Known discontinuity times of a run, the scenario's and the closed loop's, sorted.

    Parameters
    ----------
    built : Built
    sc : Scenario
    """
    cl_bps = getattr(built.closed_loop, "breakpoints", ())
    return sorted(set(sc.breakpoints()) | {float(b) for b in cl_bps})


def simulate(
    built: Built,
    sc: Scenario,
    settings: IntegratorSettings | None = None,
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate the compiled closed loop over the scenario's horizon (split at breakpoints).

    Parameters
    ----------
    built : Built
    sc : Scenario
    settings : IntegratorSettings, optional
        Default :func:`integrator_settings` of ``sc``.
    progress : callable, optional
        Called with the simulated time reached after every integrator call.

    Returns
    -------
    Trajectory
        Incomplete (not raised) on an integrator failure; its message then ends with the
        largest state where the integrator stopped (:func:`generated.values.stop_note`).
    """
    s = settings or integrator_settings(sc)
    t_out = output_grid(sc.integration.horizon, sc.integration.output_step)
    x0 = np.asarray(built.closed_loop.x0, dtype=float)
    traj = integrate_built(built, x0, t_out, s, breakpoints(built, sc), progress)
    k = traj.largest_at_stop()
    if traj.complete or k is None:
        return traj
    note = stop_note(traj.t_stop, built.closed_loop.layout.name_of(k), abs(traj.x_stop[k]))
    return dataclasses.replace(traj, message=traj.message + note)


def integrate_built(
    built: Built,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    bps: Sequence[float] = (),
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate ``built`` from ``x0`` with the method of ``settings``: the one place that
    runs a method (its :class:`~generated.solvers.Solver` checks the build, then runs it).

    Parameters
    ----------
    built : Built
    x0 : ndarray
        Initial state at ``t_out[0]`` (the DAE's z starts from ``closed_loop.z0``).
    t_out : ndarray
    settings : IntegratorSettings
    bps : sequence of float
        Breakpoints (:func:`breakpoints`).
    progress : callable, optional
        Called with the simulated time reached.

    Raises
    ------
    IntegrationError
        If the build does not fit the method.
    """
    solver = solvers.get(settings.method)
    solver.check_built(built)
    return solver.run(built, x0, t_out, settings, bps, progress)


# --------------------------------------------------------------------------- whole run
@dataclass(frozen=True)
class RunResult:
    """What :func:`run` produced: the frame, the trajectory, the two files and meta.json typed."""

    frame: pd.DataFrame
    trajectory: Trajectory
    csv_path: Path
    meta_path: Path
    record: RunMeta

    @property
    def meta(self) -> dict[str, Any]:
        """The content of meta.json as a dict (:meth:`RunMeta.to_dict`)."""
        return self.record.to_dict()


def _timed(f: Callable[..., Any], *args: Any) -> tuple[Any, float]:
    """``f(*args)`` and its wall time in seconds."""
    t0 = time.perf_counter()
    return f(*args), time.perf_counter() - t0


def _write_trajectory(folder: Path, df: pd.DataFrame, traj: Trajectory) -> tuple[Path, str]:
    """Write ``folder/trajectory.csv``; its path and the SHA-256 of its bytes."""
    folder.mkdir(parents=True, exist_ok=True)
    text = trajectory_text(df, traj)
    path = atomic_write_text(folder / "trajectory.csv", text)
    return path, hashlib.sha256(text.encode("utf-8")).hexdigest()


def _write_sundials_log(folder: Path, traj: Trajectory) -> None:
    """SUNDIALS' messages to ``folder/sundials.log`` and one line on stderr (without messages
    an older ``sundials.log`` is removed)."""
    log = folder / "sundials.log"
    line = sundials_summary(traj.sundials_log, log)
    if line is None:
        log.unlink(missing_ok=True)
        return
    atomic_write_text(log, traj.sundials_log)
    print(line, file=sys.stderr)


def _record(
    sc: Scenario,
    overrides: Mapping[str, Any] | None,
    ginfo: GainsInfo,
    built: Built,
    s: IntegratorSettings,
    traj: Trajectory,
    csv: tuple[int, str],
    codegen: CodegenSettings,
    requested: str,
    wall: dict[str, Any],
    t_all: float,
) -> RunMeta:
    """meta.json's record of a run (``csv``: rows and SHA-256 of trajectory.csv; ``requested``:
    the Jacobian strategy before resolution; ``wall``: seconds per stage, ``t_all``: start)."""
    used = solvers.get(s.method).settings_used(s)  # the method-specific settings
    lib, st = built.library, traj.stats
    par = getattr(built.closed_loop, "parametric", None)
    library = LibraryRecord(
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
        structure=par.structure_key if par is not None else "",
        parameters=len(built.p),
    )
    return RunMeta(
        scenario=sc.name,
        scenario_path=str(sc.path),
        scenario_sha256=sc.sha256,
        overrides=dict(overrides or {}),
        gains_path=str(ginfo.path),
        gains_sha256=ginfo.sha256,
        gains_reused=ginfo.reused,
        method=s.method,
        form=built.form,
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
        breakpoints=breakpoints(built, sc),
        rows=csv[0],
        trajectory_sha256=csv[1],
        inputs=run_inputs(sc, ginfo.sha256, s.method),
        libraries=library_hashes(built),
        complete=traj.complete,
        t_reached=traj.t_reached,
        message=traj.message,
        steps=st.get("steps"),
        rhs_evals=st.get("rhs_evals"),
        stats=st,
        library=library,
        cache_hit=library.cache_hit,
        wall_seconds=WallSeconds(**wall, total=time.perf_counter() - t_all),
        sundials_messages=sundials_messages(traj.sundials_log),
    )


def run(
    path: str | Path,
    *,
    overrides: Mapping[str, Any] | None = None,
    variant: str | None = None,
    method: str | None = None,
    codegen: CodegenSettings | None = None,
    out_root: str | Path | None = None,
    progress: bool = True,
    raise_on_failure: bool = True,
    fixed_tol: float | None = None,
) -> RunResult:
    """Load, synthesize if needed, build if needed, integrate, and write trajectory.csv + meta.json.

    Parameters
    ----------
    path : str or Path
    overrides, variant
        See :func:`load` (e.g. ``{"options.ablation": True}`` -> ``out/<name>-ablation/``).
    method : str, optional
        Overrides ``integration.method`` for this run without renaming the output.
    codegen : CodegenSettings, optional
        Default ``CodegenSettings(jacobian="auto")`` (:func:`resolve_codegen`).
    out_root : str or Path, optional
        Default ``out/`` (``$HITL_OUT``).
    progress : bool
        Progress bar on stderr (a terminal only) for runs longer than a second.
    raise_on_failure : bool
        After writing an incomplete trajectory, raise :class:`IntegrationError`.
    fixed_tol : float, optional
        Safeguard tolerance of the fixed-step method (default 1e-3).
    """
    t_all = time.perf_counter()
    sc, t_load = _timed(load, path, overrides, variant)
    requested = (codegen or CodegenSettings(jacobian="auto")).jacobian
    codegen = resolve_codegen(sc.N, codegen)
    method = method or sc.integration.method
    with_method(sc, method)  # the scenario's rules hold for the method run (Scenario.validate)
    root = Path(out_root or OUT_ROOT)
    gains, ginfo = ensure_gains(sc, root)
    built = build(sc, gains, method, codegen)
    s = integrator_settings(sc, method, codegen, fixed_tol)
    with progress_bar(f"sim {sc.name} ({method})", sc.integration.horizon, progress) as bar:
        traj = simulate(built, sc, s, bar)
    df, t_outputs = _timed(trajectory_frame, built, sc, traj)
    # trajectory.csv first, meta.json (which records its SHA-256) last: a reader checks the pair
    (csv_path, csv_sha), t_write = _timed(_write_trajectory, root / sc.name, df, traj)
    wall = {"load": t_load, "synthesis": ginfo.seconds, **built.timings}
    wall.update(integration=traj.stats.get("wall_seconds"), outputs=t_outputs, write=t_write)
    csv = (len(df), csv_sha)
    record = _record(sc, overrides, ginfo, built, s, traj, csv, codegen, requested, wall, t_all)
    _write_sundials_log(root / sc.name, traj)
    meta_path = atomic_write_text(root / sc.name / "meta.json", record.to_json())
    if raise_on_failure:
        traj.raise_if_incomplete()
    return RunResult(df, traj, csv_path, meta_path, record)
