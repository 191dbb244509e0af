"""The simulation pipeline as functions: the command line and a notebook share them.

::

    from generated import api
    sc = api.load("scenarios/paper.toml")                      # or overrides={...}
    gains, ginfo = api.ensure_gains(sc)                        # synthesis if needed
    built = api.build(sc, gains)                               # closed loop -> C -> .so
    traj = api.simulate(built, sc)                             # CVODES / IDAS / fixed
    df = api.trajectory_frame(built, sc, traj)                 # pandas DataFrame

or all at once, writing ``out/<name>/trajectory.csv`` and ``meta.json``::

    result = api.run("scenarios/paper.toml")
    result = api.run("scenarios/paper.toml", overrides={"options.ablation": True})
    # -> out/paper-ablation/ (eq. (42): u_i = Ψ_i, no ĝ_i)

A scenario with overrides is a distinct scenario: its name gets a suffix
(``paper-ablation``; ``variant=`` chooses it) and its SHA-256 is that of the file
plus the overrides, so its gains, library and outputs never mix with the base run.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import io
import json
import math
import re
import sys
import time
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pandas as pd

from core.artifacts import OUT_ROOT, atomic_write_text, sha256_file
from core.errors import BuildError, IntegrationError, ScenarioError, SynthesisError
from core.scenario import METHODS, Scenario, load_scenario, scenario_from_dict
from generated.codegen import CodegenSettings, Library, build_library, check_dyn_signature, renamed
from generated.integrate import IntegratorSettings, Trajectory, integrate, output_grid
from synthesis.gains import Gains

ODE_NAME, DAE_NAME, OUT_NAME = "cl_ode", "cl_dae", "cl_out"


# --------------------------------------------------------------------------- scenario
def parse_override(text: str) -> tuple[str, Any]:
    """``"options.ablation=true"`` -> ``("options.ablation", True)`` (value read as TOML).

    A value that is not valid TOML is taken as a string (``integration.method=fixed``).

    Parameters
    ----------
    text : str
        ``KEY=VALUE`` as given to ``--set``.
    """
    if "=" not in text:
        raise ScenarioError(
            "--set", _brief_text(text), "is not KEY=VALUE", "e.g. options.ablation=true"
        )
    key, _, val = text.partition("=")
    key, val = key.strip(), val.strip()
    depth = _bracket_depth(val)
    if depth > MAX_SET_DEPTH:
        raise ScenarioError("--set", _brief_text(key), *_too_deep(depth))
    try:
        value = tomllib.loads(f"v = {val}")["v"]
    except tomllib.TOMLDecodeError:
        value = val
    except ValueError:  # an integer beyond Python's int-from-text digit limit
        raise ScenarioError("--set", _brief_text(key), *_too_long_int()) from None
    except RecursionError:  # unreachable below MAX_SET_DEPTH; kept as the last guard
        raise ScenarioError("--set", _brief_text(key), *_too_deep(depth)) from None
    _check_value("--set", key, value)
    return key, value


#: deepest nesting of arrays and inline tables a --set value may have (a scenario needs 3)
MAX_SET_DEPTH = 16
#: largest integer magnitude a value may have: TOML's own range (64-bit signed)
MAX_SET_INT = 2**63 - 1
#: longest variant label (the part after ``<name>-``); longer automatic labels are
#: shortened to a readable prefix and a hash, so out/<name>/ stays a short path component
MAX_VARIANT_CHARS = 60


def _brief_text(text: str, limit: int = 60) -> str:
    """``text`` cut to ``limit`` characters for an error message."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _too_deep(depth: int) -> tuple[str, str]:
    return (
        f"value is nested {depth} levels deep",
        f"at most {MAX_SET_DEPTH} levels of [ ] and {{ }}",
    )


def _too_long_int() -> tuple[str, str]:
    return (
        "value has an integer beyond 64 bits",
        f"integers of magnitude <= {MAX_SET_INT} (19 digits); write large numbers as floats, "
        "e.g. 1e30",
    )


def _bracket_depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` in a TOML value, outside quoted strings."""
    depth = deepest = 0
    quote, escaped = "", False
    for c in text:
        if quote:
            if escaped:
                escaped = False
            elif c == "\\" and quote == '"':
                escaped = True
            elif c == quote:
                quote = ""
        elif c in "\"'":
            quote = c
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def _check_value(file: str, key: str, value: Any) -> None:
    """Refuse a value nested deeper than :data:`MAX_SET_DEPTH` or with a huge integer.

    Iterative, so that the check itself cannot exhaust the stack.
    """
    stack = [(value, 0)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, dict | list | tuple):
            if depth + 1 > MAX_SET_DEPTH:
                raise ScenarioError(file, _brief_text(key), *_too_deep(depth + 1))
            items = v.values() if isinstance(v, dict) else v
            stack.extend((x, depth + 1) for x in items)
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) > MAX_SET_INT:
            raise ScenarioError(file, _brief_text(key), *_too_long_int())


def _set_path(data: dict, file: str, key: str, value: Any) -> None:
    """Set a dotted key (``options.ablation``, ``followers[2].g``; 1-based) in the raw TOML."""
    parts = key.split(".")
    node: Any = data
    for k, part in enumerate(parts):
        m = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?", part)
        if not m:
            raise ScenarioError(file, key, "is not a dotted key", "e.g. options.ablation")
        name, index = m.group(1), m.group(2)
        last = k == len(parts) - 1 and index is None
        if last:
            node[name] = value
            return
        if name not in node:
            node[name] = {}
        node = node[name]
        if index is not None:
            i = int(index)
            if not isinstance(node, list) or not 1 <= i <= len(node):
                raise ScenarioError(file, key, f"index {i} is out of range", "a 1-based index")
            if k == len(parts) - 1:
                node[i - 1] = value
                return
            node = node[i - 1]
        if not isinstance(node, dict):
            raise ScenarioError(file, key, f"{part} is not a table", "a key into a table")


def _variant_label(overrides: Mapping[str, Any]) -> str:
    """Name suffix made from the overrides (``ablation``, ``method-fixed``).

    A label longer than :data:`MAX_VARIANT_CHARS` keeps a readable prefix and ends in 12
    hex digits of the SHA-256 of the overrides, so distinct overrides stay distinct.
    """
    parts = []
    for k, v in overrides.items():
        leaf = re.sub(r"\[\d+\]", "", k.split(".")[-1])
        parts.append(leaf if v is True else f"{leaf}-{v}")
    label = re.sub(r"[^A-Za-z0-9_.-]+", "-", "-".join(parts)).strip("-") or "variant"
    if len(label) <= MAX_VARIANT_CHARS:
        return label
    digest = hashlib.sha256(_canonical(overrides).encode()).hexdigest()[:12]
    return f"{label[: MAX_VARIANT_CHARS - 13].rstrip('-.')}-{digest}"


def _canonical(overrides: Mapping[str, Any]) -> str:
    """The overrides as canonical JSON (sorted keys): their identity in hashes."""
    return json.dumps({k: overrides[k] for k in sorted(overrides)}, sort_keys=True, default=str)


def load(
    path: str | Path,
    overrides: Mapping[str, Any] | None = None,
    variant: str | None = None,
) -> Scenario:
    """Load and validate a scenario, optionally with overrides of its fields.

    Parameters
    ----------
    path : str or Path
        The scenario TOML file.
    overrides : mapping, optional
        Dotted keys as in the file (``{"options.ablation": True}``,
        ``{"integration.method": "fixed"}``, ``{"followers[2].g": 0.5}``). The result
        is validated exactly like a file.
    variant : str, optional
        Name suffix of the overridden scenario (default: made from the keys, e.g.
        ``ablation``); the scenario is then called ``<name>-<variant>``.

    Returns
    -------
    Scenario
        With overrides, ``sha256`` is the SHA-256 of the file's hash and the overrides.
    """
    sc = load_scenario(path)
    if not overrides:
        return sc
    for k, v in overrides.items():  # programmatic overrides get the --set bounds too
        _check_value(str(path), k, v)
    if variant is not None and len(variant) > MAX_VARIANT_CHARS:
        raise ScenarioError(
            str(path),
            "variant",
            f"{_brief_text(variant)!r} has {len(variant)} characters",
            f"at most {MAX_VARIANT_CHARS} (it names the folder out/<name>-<variant>/)",
        )
    raw = Path(path).read_bytes()
    data = tomllib.loads(raw.decode("utf-8"))
    for k, v in overrides.items():
        _set_path(data, str(path), k, v)
    sha = hashlib.sha256((sc.sha256 + "\n" + _canonical(overrides)).encode()).hexdigest()
    # the loader's own validation, on the modified table
    out = scenario_from_dict(data, path=path, sha256=sha)
    label = variant or _variant_label(overrides)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", label):
        raise ScenarioError(
            str(path), "variant", f"{_brief_text(label)!r} is not a plain name", "[A-Za-z0-9_.-]"
        )
    return dataclasses.replace(out, name=f"{sc.name}-{label}", sha256=sha)


def with_method(sc: Scenario, method: str | None) -> Scenario:
    """``sc`` with ``integration.method`` replaced (unchanged for ``None``; same name).

    Parameters
    ----------
    sc : Scenario
    method : str or None
        One of :data:`core.scenario.METHODS`.

    Raises
    ------
    ScenarioError
        For an unknown method, or one the scenario does not allow: the replaced
        scenario is validated (:meth:`core.scenario.Scenario.validate`), so e.g.
        ``options.sign = "exact"`` with a variable-step method is refused.
    """
    if method is None:
        return sc
    if method not in METHODS:
        raise ScenarioError(
            str(sc.path), "integration.method", f"{method!r} is unknown", ", ".join(METHODS)
        )
    return dataclasses.replace(sc, integration=dataclasses.replace(sc.integration, method=method))


# --------------------------------------------------------------------------- synthesis
@dataclass(frozen=True)
class GainsInfo:
    """Where the gains came from: ``path``, ``sha256`` of gains.json, ``reused``, ``seconds``."""

    path: Path
    sha256: str
    reused: bool
    seconds: float


def ensure_gains(sc: Scenario, out_root: str | Path | None = None):
    """Read ``out/<name>/gains.json`` if it belongs to this scenario, else synthesize and write it.

    The file belongs to the scenario when its ``scenario_sha256`` equals ``sc.sha256``;
    it is then re-certified (:func:`synthesis.gains.recertified`: it must match the
    scenario and pass every certificate check not confined to scenario-given gains).
    A malformed or failing file is refused in one line, whatever ``STRICT`` says.

    Parameters
    ----------
    sc : Scenario
        The scenario (``name`` picks the folder, ``sha256`` decides reuse).
    out_root : str or Path, optional
        Output root; default ``out/`` (``$HITL_OUT``).

    Returns
    -------
    (Gains, GainsInfo)
    """
    from synthesis.gains import read_gains_file, recertified, save_gains

    path = Path(out_root or OUT_ROOT) / sc.name / "gains.json"
    t0 = time.perf_counter()
    if path.is_file():
        gf = read_gains_file(path)  # a malformed file is refused, never overwritten
        if gf.scenario_sha256 == sc.sha256:  # reused only after a fresh certificate
            gains = recertified(gf.gains, str(path), sc)
            return gains, GainsInfo(path, gf.sha256, True, time.perf_counter() - t0)
    try:
        from synthesis import synthesize
    except ImportError:
        raise SynthesisError(
            f"{path}: missing or stale and synthesis.synthesize is not available (run make synth)"
        ) from None
    gains = synthesize(sc)
    if gains.info.get("scenario_sha256") != sc.sha256:  # variants carry their own hash
        gains = dataclasses.replace(gains, info={**gains.info, "scenario_sha256": sc.sha256})
    save_gains(gains, path)
    return gains, GainsInfo(path, sha256_file(path), False, time.perf_counter() - t0)


# --------------------------------------------------------------------------- build
def resolve_codegen(N: int, settings: CodegenSettings | None = None) -> CodegenSettings:
    """``settings`` with its Jacobian strategy resolved for N agents (the large-N plan).

    ``jacobian="auto"`` becomes ``sparse`` (direct Newton) for N <= 20 and ``jvp``
    (matrix-free GMRES, mapped MX) above: :func:`generated.largescale.choose_plan`.

    Parameters
    ----------
    N : int
        Number of followers.
    settings : CodegenSettings, optional
        Default ``CodegenSettings(jacobian="auto")``.
    """
    from generated.largescale import choose_plan

    settings = settings or CodegenSettings(jacobian="auto")
    plan = choose_plan(N, settings.jacobian, linear_solver=settings.linear_solver)
    return plan.codegen_settings(settings)


@dataclass(frozen=True)
class Built:
    """A closed loop compiled for one method.

    Attributes
    ----------
    closed_loop : symbolic.closed_loop.ClosedLoop
    library : Library
    dyn : casadi.Function
        The compiled integrator-form right-hand side (ODE, or DAE for ``idas``).
    outputs : casadi.Function
        The compiled ``(t, x) -> named outputs``.
    form : str
        ``"ode"`` or ``"dae"``.
    timings : dict
        ``symbolic_build``, ``codegen``, ``compile`` seconds.
    dag : (Library, Cascade) or None
        Method ``native`` above :data:`generated.native.MAX_AGENTS` followers: the
        graph-ordered library (:mod:`generated.dag`) and the per-follower blocks it was
        built from; None otherwise.
    """

    closed_loop: Any
    library: Library
    dyn: ca.Function
    outputs: ca.Function
    form: str
    timings: dict[str, float] = field(default_factory=dict)
    dag: tuple[Library, Any] | None = None


def build(
    sc: Scenario,
    gains: Gains,
    method: str | None = None,
    settings: CodegenSettings | None = None,
    closed_loop: Any = None,
) -> Built:
    """Symbolic closed loop -> C -> shared library (cached) -> loaded Functions.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    method : str, optional
        ``cvodes``/``fixed`` build the ODE form, ``idas`` the DAE form, ``native`` the
        ODE form plus the native driver's functions — whole-loop for N <= 20, graph-ordered
        blocks above (:func:`native_cascade`) — (default: the scenario's method).
    settings : CodegenSettings, optional
        ``jacobian="auto"`` is resolved from ``sc.N`` (:func:`resolve_codegen`).
    closed_loop : ClosedLoop, optional
        A prebuilt closed loop (skips ``build_closed_loop``).
    """
    settings = resolve_codegen(sc.N, settings)
    method = method or sc.integration.method
    t0 = time.perf_counter()
    # first: a graph the native method cannot order fails before the closed loop is built
    cascade = native_cascade(sc, gains) if method == "native" else None
    if closed_loop is None:
        from symbolic.closed_loop import build_closed_loop

        closed_loop = build_closed_loop(sc, gains)
    return build_from_closed_loop(
        closed_loop, method, settings, t_symbolic_start=t0, cascade=cascade
    )


def native_cascade(sc: Scenario, gains: Gains) -> Any:
    """The per-follower blocks the native method needs at ``sc.N`` (None at N <= 20).

    Parameters
    ----------
    sc : Scenario
    gains : Gains

    Returns
    -------
    Cascade or None
        :func:`symbolic.cascade.build_cascade` above :data:`generated.native.MAX_AGENTS`
        followers (the whole-loop build's limit), None below.

    Raises
    ------
    ScenarioError
        Above the limit, if the graph has a cycle or the followers differ in model.
    """
    from generated import native

    if sc.N <= native.MAX_AGENTS:
        return None
    from symbolic.cascade import build_cascade

    return build_cascade(sc, gains)


def build_from_closed_loop(
    cl: Any,
    method: str,
    settings: CodegenSettings | None = None,
    *,
    t_symbolic_start: float | None = None,
    cascade: Any = None,
) -> Built:
    """Compile an existing :class:`~symbolic.closed_loop.ClosedLoop` for ``method``.

    Parameters
    ----------
    cl : ClosedLoop
        Supplies ``ode_dyn``/``dae_dyn`` and ``outputs``.
    method : str
        ``idas`` compiles the DAE form, any other method the ODE form; ``native`` adds
        :func:`generated.native.native_functions` and links the driver and SUNDIALS.
    settings : CodegenSettings, optional
        ``jacobian="auto"`` is resolved from the closed loop's N (:func:`resolve_codegen`).
    t_symbolic_start : float, optional
        ``time.perf_counter()`` when the symbolic build began, so that
        ``timings["symbolic_build"]`` includes it (default: now).
    cascade : Cascade, optional
        Method ``native`` above :data:`generated.native.MAX_AGENTS` followers: the
        per-follower blocks (:func:`native_cascade`) compiled by :mod:`generated.dag`.
    """
    settings = resolve_codegen(cl.layout.N, settings)
    t0 = time.perf_counter() if t_symbolic_start is None else t_symbolic_start
    form = "dae" if method == "idas" else "ode"
    src, name = (cl.dae_dyn, DAE_NAME) if form == "dae" else (cl.ode_dyn, ODE_NAME)
    check_dyn_signature(src, f"closed loop {form}_dyn")
    dyn = renamed(src, name, expand=settings.expand, cse=settings.cse)
    outs = renamed(cl.outputs, OUT_NAME, expand=settings.expand, cse=settings.cse)
    functions, derive, toolchain, dag_lib = [dyn, outs], [name], None, None
    if method == "native":  # the driver's functions and SUNDIALS; CVODES' jac_ not needed
        from generated import native

        derive = []
        if cl.layout.N <= native.MAX_AGENTS:  # whole loop, flat SX
            functions += native.native_functions(dyn, cse=settings.cse)[0]  # dyn: SX already
            toolchain = native.toolchain()
        else:  # graph-ordered blocks: one block's code whatever N (generated/dag.py)
            from generated import dag

            if cascade is None:
                raise BuildError(
                    f"integration.method 'native' above N = {native.MAX_AGENTS} needs the "
                    "per-follower blocks: call build(sc, gains, method='native') or pass "
                    "cascade=native_cascade(sc, gains)"
                )
            dag_lib = dag.build(cascade, settings)
    t_sym = time.perf_counter() - t0
    lib = build_library(functions, settings, with_derivatives=derive, toolchain=toolchain)
    timings = {
        "symbolic_build": t_sym,
        "codegen": lib.codegen_seconds + (dag_lib.codegen_seconds if dag_lib else 0.0),
        "compile": lib.compile_seconds + (dag_lib.compile_seconds if dag_lib else 0.0),
    }
    return Built(
        cl, lib, lib.function(name), lib.function(OUT_NAME), form, timings,
        dag=(dag_lib, cascade) if dag_lib else None,
    )  # fmt: skip


# --------------------------------------------------------------------------- simulate
def integrator_settings(
    sc: Scenario,
    method: str | None = None,
    codegen: CodegenSettings | None = None,
    fixed_tol: float | None = None,
) -> IntegratorSettings:
    """The scenario's integration settings (tolerances, steps) with the codegen linear algebra.

    Parameters
    ----------
    sc : Scenario
        Supplies ``integration`` (method, rtol, atol, max_steps, fixed_step).
    method : str, optional
        Overrides ``integration.method``.
    codegen : CodegenSettings, optional
        Its Jacobian strategy (``auto`` resolved from ``sc.N``) gives the Newton scheme,
        the linear solver and the plan's extra SUNDIALS options
        (:func:`generated.largescale.choose_plan`; default ``jacobian="auto"``).
    fixed_tol : float, optional
        Safeguard tolerance of the fixed-step method (sets ``fixed_rtol`` and
        ``fixed_atol``; default 1e-3, see :class:`IntegratorSettings`).
    """
    from generated.largescale import choose_plan

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
    """Known discontinuity times of a run: the scenario's and the closed loop's, sorted.

    Parameters
    ----------
    built : Built
        Supplies ``closed_loop.breakpoints``.
    sc : Scenario
        Supplies ``sc.breakpoints()`` (fault onsets, steps in inputs).
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
        Its form must match the method (``dae`` for ``idas``, else ``ode``).
    sc : Scenario
        Supplies the horizon, output step and breakpoints.
    settings : IntegratorSettings, optional
        Default :func:`integrator_settings` of ``sc``.
    progress : callable, optional
        Called with the simulated time reached after every integrator call.

    Returns
    -------
    Trajectory
        Incomplete (not raised) on an integrator failure (see
        :func:`generated.integrate.integrate`).

    Raises
    ------
    IntegrationError
        If the method does not match ``built.form``.
    """
    s = settings or integrator_settings(sc)
    t_out = output_grid(sc.integration.horizon, sc.integration.output_step)
    x0 = np.asarray(built.closed_loop.x0, dtype=float)
    return integrate_built(built, x0, t_out, s, breakpoints(built, sc), progress)


def integrate_built(
    built: Built,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    bps: Sequence[float] = (),
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate a compiled closed loop from ``x0`` with the method of ``settings``.

    The one place that sends ``native`` to :func:`generated.native.run` (whole loop) or
    :func:`generated.dag.run` (graph-ordered blocks) and the CasADi methods to
    :func:`generated.integrate.integrate`.

    Parameters
    ----------
    built : Built
        Built for the method (``idas``: DAE form; ``native``: the native build).
    x0 : ndarray
        Initial state at ``t_out[0]`` (the DAE's z starts from ``closed_loop.z0``).
    t_out : ndarray
        Output times.
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
    s = settings
    if (s.method == "idas") != (built.form == "dae"):
        raise IntegrationError(
            f"method {s.method!r} needs the {'DAE' if s.method == 'idas' else 'ODE'} build "
            f"(this one is {built.form}): call build(..., method={s.method!r})"
        )
    if s.method == "native" and built.dag is not None:
        from generated import dag

        lib, cascade = built.dag
        return dag.run(lib.path, cascade, x0, t_out, s, breakpoints=bps, progress=progress)
    if s.method == "native":
        from generated import native

        if native.RHS_NAME not in built.library.names:
            raise IntegrationError(
                "method 'native' needs the native build: call build(..., method='native')"
            )
        return native.run(built.library.path, x0, t_out, s, breakpoints=bps, progress=progress)
    z0 = np.asarray(built.closed_loop.z0, dtype=float) if built.form == "dae" else None
    return integrate(built.dyn, x0, t_out, s, breakpoints=bps, z0=z0, progress=progress)


# --------------------------------------------------------------------------- outputs
def column_names(sc: Scenario) -> list[str]:
    """The CSV columns, in order (agents and components 1-based).

    Parameters
    ----------
    sc : Scenario
        Supplies the sizes ``N``, ``n`` and ``m``.
    """
    m, n, N = sc.m, sc.n, sc.N
    cols = ["t"] + [f"eta0_{k}" for k in range(1, m + 1)]
    for i in range(1, N + 1):
        cols += [f"p{i}_{r}" for r in range(1, n + 1)]
        cols += [f"q{i}_{r}" for r in range(1, n + 1)]
        cols += [f"eta{i}_{k}" for k in range(1, m + 1)]
        cols += [f"mu{i}_{k}" for k in range(1, m + 1)]
        cols += [f"phi{i}"]
        cols += [f"thetahat{i}_{r}" for r in range(1, n + 1)]
        cols += [f"ghat{i}"]
        cols += [f"u{i}_{r}" for r in range(1, n + 1)]
        cols += [f"b{i}_{r}" for r in range(1, n + 1)]
        cols += [f"et{i}_{r}" for r in range(1, n + 1)]
        cols += [f"eeta{i}_{k}" for k in range(1, m + 1)]
        cols += [f"chi{i}_{r}" for r in range(1, n + 1)]
        cols += [f"V2_{i}"]
    return [*cols, "V1"]


#: CSV prefix -> candidate names of the closed loop's outputs (first match wins)
_OUTPUT_ALIASES = {
    "u": ("u",),
    "b": ("b",),
    "et": ("e_t", "et"),
    "eeta": ("ebar", "e_eta_bar", "eeta"),
    "chi": ("chi",),
    "V2": ("V2",),
    "V1": ("V1",),
}


def evaluate_outputs(built: Built, traj: Trajectory) -> dict[str, np.ndarray]:
    """All named outputs at every output time: ``name -> array (K, rows, cols)``.

    Parameters
    ----------
    built : Built
        Supplies the compiled ``outputs`` Function.
    traj : Trajectory
        The output times and states.
    """
    K = len(traj.t)
    f = built.outputs
    if K == 0:
        return {nm: np.zeros((0, *f.size_out(j))) for j, nm in enumerate(f.name_out())}
    res = f.map(K)(traj.t.reshape(1, -1), traj.x.T)
    res = res if isinstance(res, list | tuple) else [res]
    out = {}
    for j, nm in enumerate(f.name_out()):
        r, c = f.size_out(j)
        a = np.array(ca.DM(res[j]).full(), dtype=float)  # r x (c*K), time blocks side by side
        out[nm] = a.reshape(r, K, c).transpose(1, 0, 2)
    return out


def _agent_rows(arr: np.ndarray, N: int, width: int, name: str) -> np.ndarray:
    """A per-agent output (K, N, width): row i = agent i (the closed loop's convention)."""
    if arr.shape[1:] != (N, width):
        raise BuildError(
            f"closed loop output {name!r} is {arr.shape[1]}x{arr.shape[2]} per time, "
            f"expected {N}x{width} (one row per agent)"
        )
    return arr


def trajectory_frame(built: Built, sc: Scenario, traj: Trajectory) -> pd.DataFrame:
    """The trajectory as a DataFrame with exactly the columns of :func:`column_names`.

    Parameters
    ----------
    built : Built
        Supplies the state layout and the compiled outputs.
    sc : Scenario
        Supplies the sizes ``N``, ``n`` and ``m``.
    traj : Trajectory
        The output times and states.

    Raises
    ------
    BuildError
        If the closed loop's outputs or state layout do not give these columns.
    """
    cl = built.closed_loop
    sl = cl.layout.slices
    outs = evaluate_outputs(built, traj)

    def out(prefix: str) -> tuple[str, np.ndarray]:
        for nm in _OUTPUT_ALIASES[prefix]:
            if nm in outs:
                return nm, outs[nm]
        raise BuildError(
            f"closed loop outputs lack {prefix!r} (looked for {', '.join(_OUTPUT_ALIASES[prefix])}; "
            f"it has {', '.join(outs)})"
        )

    N, n, m = sc.N, sc.n, sc.m
    X = traj.x
    K = len(traj.t)
    blocks: list[np.ndarray] = [traj.t.reshape(-1, 1), X[:, sl["eta0"]]]
    named = {}
    for key, width in (("u", n), ("b", n), ("et", n), ("eeta", m), ("chi", n), ("V2", 1)):
        nm, arr = out(key)
        named[key] = _agent_rows(arr, N, width, nm)
    for i in range(N):
        for key in ("p", "q", "eta", "mu", "phi", "thetahat", "ghat"):
            blocks.append(X[:, sl[(key, i)]])
        for key in ("u", "b", "et", "eeta", "chi", "V2"):
            blocks.append(named[key][:, i, :])
    nm, v1 = out("V1")
    if v1.shape[1:] != (1, 1):
        raise BuildError(f"closed loop output {nm!r} is not a scalar")
    blocks.append(v1.reshape(K, 1))
    data = np.hstack(blocks)
    cols = column_names(sc)
    if data.shape[1] != len(cols):
        raise BuildError(
            f"trajectory has {data.shape[1]} columns, expected {len(cols)} (check the state layout)"
        )
    return pd.DataFrame(data, columns=cols)


def csv_text(df: pd.DataFrame) -> str:
    """Deterministic CSV: header, then ``repr`` of every float (shortest round-trip form).

    Parameters
    ----------
    df : pandas.DataFrame
        All columns numeric; the index is not written.
    """
    buf = io.StringIO()
    buf.write(",".join(df.columns) + "\n")
    for row in df.to_numpy(dtype=float).tolist():
        buf.write(",".join(map(repr, row)) + "\n")
    return buf.getvalue()


#: first line of a trajectory.csv whose run stopped early (readers skip ``#`` lines)
INCOMPLETE_MARK = "# incomplete: "
#: packages whose sources shape a trajectory (their hash is part of the reuse key)
CODE_PACKAGES = ("symbolic", "synthesis", "generated")


def trajectory_text(df: pd.DataFrame, traj: Trajectory) -> str:
    """The ``trajectory.csv`` text: :func:`csv_text`, led by ``# incomplete: <reason>`` if partial.

    Parameters
    ----------
    df : pandas.DataFrame
        The frame (:func:`trajectory_frame`).
    traj : Trajectory
        Its ``complete``, ``t_reached`` and ``message`` mark a partial run in the file itself.
    """
    if traj.complete:
        return csv_text(df)
    why = " ".join(str(traj.message or "integrator stopped").split())
    return f"{INCOMPLETE_MARK}t = {traj.t_reached!r}: {why}\n" + csv_text(df)


def read_trajectory(data: bytes | str | Path) -> tuple[pd.DataFrame, str | None]:
    """Parse ``trajectory.csv`` (bytes, text or a path): the frame and the incomplete reason.

    Parameters
    ----------
    data : bytes, str or Path
        The file's bytes or text, or its path.

    Returns
    -------
    (DataFrame, str or None)
        The reason is the text after ``# incomplete: `` (None for a complete run).
    """
    if isinstance(data, Path):
        data = data.read_bytes()
    text = data.decode("utf-8") if isinstance(data, bytes) else data
    first = text.split("\n", 1)[0]
    reason = first[len(INCOMPLETE_MARK) :] if first.startswith(INCOMPLETE_MARK) else None
    return pd.read_csv(io.StringIO(text), comment="#"), reason


def _data_rows(text: str) -> int:
    """Rows of a trajectory text: non-empty lines that are neither comments nor the header."""
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    return max(len(lines) - 1, 0)


@functools.lru_cache(maxsize=1)
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
        The build (its library, and the graph-ordered one above N = 20).
    """
    libs = [built.library] + ([built.dag[0]] if built.dag is not None else [])
    return {str(lib.path): sha256_file(lib.path) for lib in libs}


def reuse_problem(folder: Path, sc: Scenario, method: str | None = None) -> tuple[str | None, Any]:
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
        meta = json.loads(meta_p.read_text())
        data = csv_p.read_bytes()
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
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
        rows = _data_rows(data.decode("utf-8"))
    except UnicodeDecodeError:
        return "trajectory.csv is not text", None
    if rows != meta.get("rows") or data.startswith(INCOMPLETE_MARK.encode()):
        return f"trajectory.csv has {rows} rows, meta.json records {meta.get('rows')}", None
    return None, (meta, data)


# --------------------------------------------------------------------------- progress
class ProgressBar:
    """A one-line progress bar on stderr, shown only once a run has lasted more than a second.

    Call it with the simulated time reached; it redraws at most every 0.1 s.

    Parameters
    ----------
    label : str
        Text before the bar.
    horizon : float
        Simulated time that counts as 100 %.
    stream : file-like, optional
        Where to write (default ``sys.stderr``).
    delay : float
        Wall seconds before the bar first appears.
    """

    def __init__(self, label: str, horizon: float, stream: Any = None, delay: float = 1.0):
        self.label, self.horizon, self.delay = label, horizon, delay
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.perf_counter()
        self.shown = False
        self._last = -math.inf

    def __call__(self, t: float) -> None:
        now = time.perf_counter()
        el = now - self.t0
        if el < self.delay or now - self._last < 0.1:
            return
        self._last = now
        frac = min(max(t / self.horizon, 0.0), 1.0) if self.horizon > 0 else 1.0
        bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
        self.stream.write(
            f"\r{self.label} [{bar}] {100 * frac:5.1f}%  t = {t:.2f}/{self.horizon:g} s  {el:.1f} s"
        )
        self.stream.flush()
        self.shown = True

    def close(self) -> None:
        """End the bar's line, if it was shown."""
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


# --------------------------------------------------------------------------- whole run
@dataclass(frozen=True)
class RunResult:
    """What :func:`run` produced: the frame, the trajectory, the files and ``meta``."""

    frame: pd.DataFrame
    trajectory: Trajectory
    csv_path: Path
    meta_path: Path
    meta: dict[str, Any]


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
        Scenario file.
    overrides, variant
        See :func:`load` (e.g. ``{"options.ablation": True}`` -> ``out/<name>-ablation/``).
    method : str, optional
        Overrides ``integration.method`` for this run without renaming the output.
    codegen : CodegenSettings, optional
        Default ``CodegenSettings(jacobian="auto")``: the plan is chosen from N
        (:func:`resolve_codegen`).
    out_root : str or Path, optional
        Default ``out/`` (``$HITL_OUT``).
    progress : bool
        Progress bar on stderr for runs longer than a second.
    raise_on_failure : bool
        After writing an incomplete trajectory, raise :class:`IntegrationError`.
    fixed_tol : float, optional
        Safeguard tolerance of the fixed-step method (default 1e-3).

    Returns
    -------
    RunResult
    """
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    sc = load(path, overrides, variant)
    t_load = time.perf_counter() - t0
    requested = (codegen or CodegenSettings(jacobian="auto")).jacobian
    codegen = resolve_codegen(sc.N, codegen)
    method = method or sc.integration.method
    if sc.options.sign == "exact" and method != "fixed":
        raise ScenarioError(
            sc.path, "options.sign", "'exact' makes variable-step integrators chatter and fail",
            "method 'fixed'",
        )  # fmt: skip
    root = Path(out_root or OUT_ROOT)
    gains, ginfo = ensure_gains(sc, root)
    built = build(sc, gains, method, codegen)
    s = integrator_settings(sc, method, codegen, fixed_tol)
    bar = ProgressBar(f"sim {sc.name} ({method})", sc.integration.horizon) if progress else None
    try:
        traj = simulate(built, sc, s, bar)
    finally:
        if bar is not None:
            bar.close()
    t0 = time.perf_counter()
    df = trajectory_frame(built, sc, traj)
    t_outputs = time.perf_counter() - t0
    folder = root / sc.name
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    text = trajectory_text(df, traj)
    # trajectory.csv first, meta.json (which records its SHA-256) last: a reader checks the pair
    csv_path = atomic_write_text(folder / "trajectory.csv", text)
    t_write = time.perf_counter() - t0
    st = traj.stats
    meta = {
        "scenario": sc.name,
        "scenario_path": str(sc.path),
        "scenario_sha256": sc.sha256,
        "overrides": {k: v for k, v in (overrides or {}).items()},
        "gains_path": str(ginfo.path),
        "gains_sha256": ginfo.sha256,
        "gains_reused": ginfo.reused,
        "method": method,
        "form": built.form,
        "rtol": s.rtol,
        "atol": s.atol,
        "max_steps": s.max_steps,
        "fixed_step": s.fixed_step if method == "fixed" else None,
        "fixed_rtol": s.fixed_rtol if method == "fixed" else None,
        "fixed_atol": s.fixed_atol if method == "fixed" else None,
        "newton_scheme": s.newton_scheme,
        "linear_solver": s.linear_solver,
        "integrator_extra_options": dict(s.extra_options),
        "horizon": sc.integration.horizon,
        "output_step": sc.integration.output_step,
        "breakpoints": breakpoints(built, sc),
        "rows": len(df),
        "trajectory_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
        "inputs": run_inputs(sc, ginfo.sha256, method),
        "libraries": library_hashes(built),
        "complete": traj.complete,
        "t_reached": traj.t_reached,
        "message": traj.message,
        "steps": st.get("steps"),
        "rhs_evals": st.get("rhs_evals"),
        "stats": st,
        "library": {
            "key": built.library.key,
            "path": str(built.library.path),
            "source": str(built.library.source),
            "source_bytes": built.library.source_bytes,
            "cache_hit": built.library.cache_hit,
            "cflags": list(codegen.cflags),
            "compiler": codegen.compiler,
            "jacobian": codegen.jacobian,
            "jacobian_requested": requested,
            "expand": codegen.expand,
            "casadi": ca.__version__,
        },
        "cache_hit": built.library.cache_hit,
        "wall_seconds": {
            "load": t_load,
            "synthesis": ginfo.seconds,
            **built.timings,
            "integration": st.get("wall_seconds"),
            "outputs": t_outputs,
            "write": t_write,
            "total": time.perf_counter() - t_all,
        },
    }
    meta_path = atomic_write_text(folder / "meta.json", json.dumps(meta, indent=2, default=_json))
    result = RunResult(df, traj, csv_path, meta_path, meta)
    if raise_on_failure:
        traj.raise_if_incomplete()
    return result


def _json(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
