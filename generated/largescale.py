"""Large-N strategy: what to generate and how CVODES/IDAS solve their Newton systems.

Why this module exists (measured, see ``docs/performance.md``): CasADi's Jacobian of
the mapped closed loop is generated *unrolled* per agent — the C file grows linearly
in N (13.8 MB flat / 5.6 MB mapped at N = 50, 48 MB at N = 500, gcc did not finish),
and so does the Jacobian built by CasADi's AD from a mapped MX Function. The
right-hand side alone, kept as an MX ``map`` (no SX expansion), stays small and its
forward derivative (one direction, ``fwd1_<name>``) is mapped too.

Two plans:

``direct``
    The simulation stage's default: SX-expanded right-hand side plus its sparse
    Jacobian ``jac_<name>``, factorised by a direct sparse solver (``csparse``).
    Best for small N (few agents, tiny Jacobian, fewest steps).
``gmres``
    Matrix-free Newton–Krylov: the MX-mapped right-hand side and its Jacobian-vector
    product ``fwd1_<name>`` only (no Jacobian is ever formed, generated or factorised),
    solved by CVODES/IDAS's GMRES without a preconditioner. Generated code size and
    compile time stay flat in N; the cost per step is linear in N·(degree).

:func:`choose_plan` picks one from N; :func:`plan_functions` lists what to generate;
:func:`build_plan` compiles through :func:`generated.codegen.build_library` (same
cache); :func:`integrate_plan` runs CasADi's CVODES/IDAS with the plan's options.

Hook wanted in ``generated/integrate.py`` (so the simulation CLI can use ``gmres``):
``IntegratorSettings.extra_options: tuple[tuple[str, Any], ...] = ()`` merged into
the SUNDIALS options of ``_Sundials`` (this module needs
``("use_preconditioner", False), ("max_krylov", k)``), and in
``generated/codegen.py`` a ``CodegenSettings.jacobian = "jvp"`` that generates
``fwd1_<name>`` *without* ``jac_<name>`` but with the Jacobian's sparsity pattern
(``CodeGenerator.add(f, True)``; without it CasADi's set-up allocates a dense nx×nx
matrix). Until then :func:`build_plan` compiles through the codegen module's
``cache_key``/``compile_source`` and :func:`integrate_plan` calls
:func:`casadi.integrator` itself.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from symbolic.errors import BuildError, IntegrationError

PLANS = ("direct", "gmres")
#: above this many agents ``auto`` switches to the matrix-free plan. Measured
#: (docs/performance.md): N = 5 direct 0.67 s vs gmres 1.16 s; N = 50 direct does not
#: even compile in 60 s (≈ 0.13 MB of expanded C per agent). 20 is a judgement call
#: between the two; the crossover itself was not measured.
DIRECT_MAX_AGENTS = 20
#: Krylov subspace size: the closed loop's stiff modes (φ floor, tanh layer, gains
#: λ_ir k1_ir) need more than CVODES's default of 5
DEFAULT_MAX_KRYLOV = 20
#: seconds per IDAS call (a restart with a fresh consistent-initial-condition search)
IDAS_CHUNK = 1.0


@dataclass(frozen=True)
class JacobianPlan:
    """How the Newton systems of the implicit integrators are solved.

    Attributes
    ----------
    strategy : str
        ``"direct"`` or ``"gmres"`` (see the module docstring).
    expand : bool
        Expand the MX closed loop to SX before generating C (``direct``) or keep the
        mapped MX graph (``gmres``: code size independent of N).
    derivatives : tuple of str
        Derivative companions to generate: ``("jac",)`` or ``("fwd1",)``.
    integrator_options : dict
        SUNDIALS options for :func:`casadi.integrator` (``newton_scheme`` and the
        linear-solver options).
    reason : str
        Why this plan was chosen (for reports).
    """

    strategy: str
    expand: bool
    derivatives: tuple[str, ...]
    integrator_options: dict[str, Any] = field(default_factory=dict)
    reason: str = ""


def choose_plan(
    N: int,
    strategy: str = "auto",
    *,
    linear_solver: str = "csparse",
    max_krylov: int = DEFAULT_MAX_KRYLOV,
    direct_max_agents: int = DIRECT_MAX_AGENTS,
) -> JacobianPlan:
    """The Jacobian / linear-solver plan for N agents.

    Parameters
    ----------
    N : int
        Number of followers.
    strategy : {"auto", "direct", "gmres"}
        ``auto``: ``direct`` for ``N <= direct_max_agents``, else ``gmres``.
    linear_solver : str
        Direct sparse solver (CasADi Linsol plugin) of the ``direct`` plan.
    max_krylov : int
        GMRES subspace size of the ``gmres`` plan.
    direct_max_agents : int
        Crossover of ``auto``.

    Returns
    -------
    JacobianPlan

    Raises
    ------
    BuildError
        Unknown strategy, N < 1 or max_krylov < 1.
    """
    if strategy not in ("auto", *PLANS):
        raise BuildError(f"strategy: {strategy!r} is not allowed (expected auto, direct or gmres)")
    if int(N) < 1:
        raise BuildError(f"N: {N} must be >= 1 (number of followers)")
    if int(max_krylov) < 1:
        raise BuildError(f"max_krylov: {max_krylov} must be >= 1")
    if strategy == "auto":
        strategy = "direct" if N <= direct_max_agents else "gmres"
        why = f"auto: N = {N} {'<=' if strategy == 'direct' else '>'} {direct_max_agents}"
    else:
        why = "requested"
    if strategy == "direct":
        return JacobianPlan(
            "direct",
            expand=True,
            derivatives=("jac",),
            integrator_options={"newton_scheme": "direct", "linear_solver": linear_solver},
            reason=why,
        )
    return JacobianPlan(
        "gmres",
        expand=False,
        derivatives=("fwd1",),
        integrator_options={
            "newton_scheme": "gmres",
            "use_preconditioner": False,  # a preconditioner would need the full Jacobian
            "max_krylov": int(max_krylov),
        },
        reason=why,
    )


def plan_functions(dyn: ca.Function, plan: JacobianPlan) -> list[ca.Function]:
    """The Functions to put in the library: ``dyn`` and its derivative companions.

    ``jac_<name>`` (``dyn.jacobian()``) and ``fwd1_<name>`` (``dyn.forward(1)``) are the
    names CasADi's :func:`casadi.external` looks up, so the loaded ``dyn`` carries them.
    """
    funs = [dyn]
    for d in plan.derivatives:
        if d == "jac":
            funs.append(dyn.jacobian())
        elif d == "fwd1":
            funs.append(dyn.forward(1))
        else:  # pragma: no cover - plans are built by choose_plan
            raise BuildError(f"plan.derivatives: {d!r} is unknown (expected jac or fwd1)")
    return funs


@dataclass(frozen=True)
class PlanBuild:
    """A compiled right-hand side for a plan.

    Attributes
    ----------
    dyn : casadi.Function
        The compiled integrator-form function (external, with its companions).
    library : generated.codegen.Library
    plan : JacobianPlan
    timings : dict
        ``codegen`` and ``compile`` seconds (0 compile on a cache hit).
    """

    dyn: ca.Function
    library: Any
    plan: JacobianPlan
    timings: dict[str, float]


def build_plan(
    dyn_symbolic: ca.Function, plan: JacobianPlan, name: str = "cl_ode", settings: Any = None
) -> PlanBuild:
    """Generate and compile ``dyn_symbolic`` for ``plan`` (cached by content).

    Parameters
    ----------
    dyn_symbolic : casadi.Function
        ``ClosedLoop.ode_dyn`` (or ``dae_dyn`` for IDAS).
    plan : JacobianPlan
    name : str
        Name of the function in the library.
    settings : generated.codegen.CodegenSettings, optional
        Compiler settings; ``expand`` is taken from the plan.
    """
    import dataclasses

    from generated.codegen import CodegenSettings, build_library, check_dyn_signature, renamed

    check_dyn_signature(dyn_symbolic, "build_plan: dyn_symbolic")
    settings = dataclasses.replace(settings or CodegenSettings(), expand=plan.expand)
    t0 = time.perf_counter()
    dyn = renamed(dyn_symbolic, name, expand=plan.expand)
    funs = plan_functions(dyn, plan)
    t_prep = time.perf_counter() - t0
    if plan.strategy == "gmres":
        lib = _build_with_jac_sparsity(funs, settings, name)
    else:
        lib = build_library(funs, settings, with_derivatives=())
    timings = {"codegen": t_prep + lib.codegen_seconds, "compile": lib.compile_seconds}
    return PlanBuild(lib.function(name), lib, plan, timings)


def _build_with_jac_sparsity(funs: Sequence[ca.Function], settings: Any, name: str) -> Any:
    """Like :func:`generated.codegen.build_library`, but ``name`` carries its Jacobian sparsity.

    Without the pattern an external Function reports a dense Jacobian, and CasADi's
    CVODES/IDAS set-up allocates a dense nx×nx matrix even when GMRES never forms it
    (measured at N = 500: 2.8 GB peak and ≈ 400 s of set-up; with the pattern 1.3 s).
    The pattern adds O(nnz) integers to the C file (1.6 MB at N = 500, 7.1 MB at
    N = 2,000) but no code: gcc time stays 1.5–3 s. Same cache layout and key as
    ``build_library`` (the key hashes the source text).
    """
    import json
    import os
    import shutil
    import tempfile
    from pathlib import Path

    from generated.codegen import (
        LIBRARY_NAME,
        MANIFEST_NAME,
        SOURCE_NAME,
        Library,
        cache_key,
        compile_source,
    )

    t0 = time.perf_counter()
    cg = ca.CodeGenerator(SOURCE_NAME, dict(settings.codegen_options))
    for f in funs:
        cg.add(f, f.name() == name)  # with_jac_sparsity for the integrator's function
    source = cg.dump()
    t_codegen = time.perf_counter() - t0
    names = tuple(f.name() for f in funs)
    key = cache_key(source, settings)
    root = settings.root()
    folder = root / key
    if (folder / MANIFEST_NAME).is_file() and (folder / LIBRARY_NAME).is_file():
        return Library(key, folder, folder / SOURCE_NAME, folder / LIBRARY_NAME, names, True,
                       t_codegen, 0.0, len(source))  # fmt: skip
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".tmp-{key[:12]}-"))
    try:
        t_compile = compile_source(source, settings, tmp)
        info = {"key": key, "names": list(names), "source_bytes": len(source),
                "compile_seconds": t_compile, "with_jac_sparsity": name}  # fmt: skip
        (tmp / MANIFEST_NAME).write_text(json.dumps(info, indent=2))  # last: marks complete
        try:
            os.rename(tmp, folder)
        except OSError:
            if not (folder / MANIFEST_NAME).is_file():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return Library(key, folder, folder / SOURCE_NAME, folder / LIBRARY_NAME, names, False,
                   t_codegen, t_compile, len(source))  # fmt: skip


@dataclass(frozen=True)
class PlanResult:
    """Outcome of :func:`integrate_plan`.

    Attributes
    ----------
    t, x : ndarray
        Output times reached and the states there (K×nx).
    complete : bool
    message : str
        Empty when complete, else the solver's reason.
    stats : dict
        ``steps``, ``rhs_evals``, ``jtimes_evals``, ``jac_evals``, ``lin_setups``,
        ``error_test_fails``, ``newton_fails``, ``newton_iters``, ``wall_seconds``.
    """

    t: np.ndarray
    x: np.ndarray
    complete: bool
    message: str
    stats: dict[str, Any]


_STATS = {
    "steps": "nsteps",
    "rhs_evals": "nfevals",
    "jtimes_evals": "n_call_jtimesF",
    "jac_evals": "n_call_jacF",
    "lin_setups": "nlinsetups",
    "error_test_fails": "netfails",
    "newton_fails": "nncfails",
    "newton_iters": "nniters",
}


def integrate_plan(
    dyn: ca.Function,
    x0: np.ndarray,
    t_out: np.ndarray,
    plan: JacobianPlan,
    *,
    method: str = "cvodes",
    rtol: float = 1e-6,
    atol: float = 1e-8,
    max_steps: int = 200000,
    breakpoints: Sequence[float] = (),
    z0: np.ndarray | None = None,
) -> PlanResult:
    """Integrate a compiled ``dyn`` with the plan's linear algebra (one call per segment).

    The run is restarted at every breakpoint (known discontinuities); the integrator
    is called once per segment with all output times of that segment, so Python is
    out of the integration loop.

    Parameters
    ----------
    dyn : casadi.Function
        Integrator form ``(t, x, z, p, u) -> (ode, alg, quad, zero)``.
    x0 : ndarray
    t_out : ndarray
        Increasing output times, ``t_out[0]`` the initial time.
    plan : JacobianPlan
    method : {"cvodes", "idas"}
    rtol, atol : float
    max_steps : int
        SUNDIALS ``max_num_steps`` between two output times.
    breakpoints : sequence of float
    z0 : ndarray, optional
        Algebraic initial guess (IDAS).

    Returns
    -------
    PlanResult
        Never raises on a solver failure: ``complete`` is False and ``message`` says why.
    """
    if method not in ("cvodes", "idas"):
        raise IntegrationError(f"method: {method!r} is not allowed (expected cvodes or idas)")
    opts: dict[str, Any] = {
        "abstol": atol,
        "reltol": rtol,
        "max_num_steps": int(max_steps),
        "disable_internal_warnings": True,
        "show_eval_warnings": False,
    }
    if method == "idas":
        opts["suppress_algebraic"] = True
        opts["calc_ic"] = True
    opts.update(plan.integrator_options)  # the plan's choices win
    t_out = np.asarray(t_out, dtype=float)
    x = np.asarray(x0, dtype=float).ravel()
    nz = int(dyn.size1_in(2))
    z = np.zeros(nz) if z0 is None else np.asarray(z0, dtype=float).ravel()
    bps = sorted(b for b in set(map(float, breakpoints)) if t_out[0] < b < t_out[-1])
    edges = [float(t_out[0]), *bps, float(t_out[-1])]
    if method == "idas":
        # CasADi's IDACalcIC fails on this loop when the call spans the whole horizon
        # (measured: fine up to 1 s, IDA_CONV_FAIL over 20 s): restart every IDAS_CHUNK s
        cuts = np.arange(edges[0] + IDAS_CHUNK, edges[-1] - 1e-9, IDAS_CHUNK)
        edges = sorted(set(edges) | {float(c) for c in cuts})
    X = [x]
    T = [float(t_out[0])]
    acc = dict.fromkeys(_STATS, 0)
    message = ""
    wall0 = time.perf_counter()
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        targets = [float(t) for t in t_out if a < t <= b * (1 + 1e-14)]
        if not targets or abs(targets[-1] - b) > 1e-12:
            targets.append(b)
        integ = ca.integrator("plan", method, dyn, a, targets, opts)
        try:
            res = integ(x0=x, z0=z)
        except RuntimeError as exc:
            lines = [ln for ln in str(exc).splitlines() if ln.strip()]
            message = f"{method} failed in [{a:g}, {b:g}] s: {lines[-1] if lines else exc}"
            _accumulate(acc, integ.stats())
            break
        _accumulate(acc, integ.stats())
        Xs = np.array(res["xf"], dtype=float).reshape(len(x), len(targets), order="F").T
        if nz:
            z = np.array(res["zf"], dtype=float).reshape(nz, len(targets), order="F").T[-1]
        if not np.all(np.isfinite(Xs)):
            message = f"{method}: state not finite in [{a:g}, {b:g}] s"
            break
        on_grid = np.isin(np.array(targets), t_out)
        X.extend(Xs[on_grid])
        T.extend(np.array(targets)[on_grid])
        x = Xs[-1]
    acc["wall_seconds"] = time.perf_counter() - wall0
    return PlanResult(np.array(T), np.array(X), not message, message, acc)


def _accumulate(acc: dict[str, Any], st: dict[str, Any]) -> None:
    for k, name in _STATS.items():
        v = st.get(name)
        if isinstance(v, int | float) and np.isfinite(v):
            acc[k] += int(v)
