"""Per-agent kernels with the graph as runtime data: one library per follower model.

The whole-loop native build (:mod:`generated.native`) writes the graph into the code, and
the graph-ordered build (:mod:`generated.dag`) needs an acyclic graph of one model. This
module compiles, once per follower model and option set, the kernels of ONE agent
(:func:`symbolic.cascade.agent_block`, as C):

* ``ag_jet0``, ``ag_jet1``, ``ag_jet2``: the jets C0 η_i, C0 η̇_i, C0 η̈_i its listeners
  sum (level l reads only the levels < l of the agent's own neighbour sum);
* ``ag_rhs``: the agent's rates (and the leader's, eq. (3));
* ``ag_jac``: their Jacobian block K = ∂(ẋ_b, jets)/∂(x_b, nb);
* ``ag_faults``: every distinct fault expression of the scenario;

and appends the driver ``generated/native/agents.c``. Everything about the graph — N,
the pattern, the weights (L + B)_ij, the pinning and gauge a_i0 h_i, every switching
time — is runtime data (:class:`AgentProblem`, CSR arrays per topology) passed to the
driver, which evaluates the kernels over the agents in passes (one per jet level), so a
cycle is no special case. The Newton systems are reduced to the agents' jets and solved
by forward substitution (acyclic), a dense LU (small N) or GMRES (any graph); see the
driver's header comment.

What is compiled in, and so is the library's identity (the cache key is the hash of the
C source): the follower model and its physical parameters, the options, the leader
(A0, B0, C0 and u0), the observer gains and UIO (``gains``), and the set of distinct
fault expressions. Followers of several models run in one CVODE run, each from its own
library (the driver gets one table of kernel pointers per model).
"""

from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from core.errors import IntegrationError, ScenarioError
from core.graph import pinned_laplacian
from core.scenario import Scenario
from generated import native
from generated.codegen import CodegenSettings, Library, build_library
from generated.integrate import IntegratorSettings, Trajectory
from symbolic.cascade import agent_block
from symbolic.closed_loop import fault_function, make_layout, model_groups, observer_gains
from symbolic.parameters import param_matrix
from synthesis.gains import Gains

DRIVER = native.NATIVE_DIR / "agents.c"
JET_NAMES = ("ag_jet0", "ag_jet1", "ag_jet2")
RHS_NAME, JAC_NAME, FAULTS_NAME = "ag_rhs", "ag_jac", "ag_faults"
#: Newton-system solvers of the driver (``HITL_AG_*`` in agents.c)
SOLVERS = {"auto": 0, "forward": 1, "dense": 2, "gmres": 3}
#: compile flags of the kernel libraries: OpenMP threads over the agents of a pass
OPENMP_FLAGS = ("-fopenmp",)


def kernel_functions(
    sc: Scenario, gains: Gains, model_index: int, *, cse: bool = True
) -> list[ca.Function]:
    """The kernels of one follower model (module docstring), as CasADi Functions.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
        The observer gains and the UIO (compiled in).
    model_index : int
        0-based follower whose model and parameters the kernels use.
    cse : bool
        Common-subexpression elimination in the generated code.

    Returns
    -------
    list of casadi.Function
        ``ag_jet0..2``, ``ag_rhs``, ``ag_jac`` with inputs ``(t, xb, nb, cpl, prm, gf)``
        and ``ag_faults(t)``.
    """
    lay = make_layout(sc.m, sc.n, 1, sc.options.derivatives == "filtered")
    block = agent_block(sc, observer_gains(sc, gains), lay, model_index)
    args = block.sx_in()
    xbdot, jets = block.call(args)
    n = sc.n
    xb, nb = args[1], args[2]
    K = ca.densify(ca.jacobian(ca.vertcat(xbdot, jets), ca.vertcat(xb, nb)))
    opts = {"cse": True} if cse else {}
    names = block.name_in()
    fns = [
        ca.Function(JET_NAMES[lev], args, [jets[lev * n : (lev + 1) * n]], names, ["jet"], opts)
        for lev in range(3)
    ]
    fns.append(ca.Function(RHS_NAME, args, [xbdot, jets], names, ["xbdot", "jets"], opts))
    fns.append(ca.Function(JAC_NAME, args, [jets, K], names, ["jets", "K"], opts))
    faults, _ = fault_function(sc)
    t = ca.SX.sym("t")
    fns.append(ca.Function(FAULTS_NAME, [t], [faults(t)], ["t"], ["values"], opts))
    return fns


def kernel_settings(
    settings: CodegenSettings | None = None, openmp: bool = False
) -> CodegenSettings:
    """``settings`` for the kernels: with OpenMP's flags for a threaded build.

    Parameters
    ----------
    settings : CodegenSettings, optional
    openmp : bool
        Threads over the agents (``LinearSettings.threads`` > 1). A serial build has no
        OpenMP region: at small N entering one costs more than the pass it runs.
    """
    s = settings or CodegenSettings()
    extra = tuple(s.extra_cflags)
    if openmp:
        extra += tuple(f for f in OPENMP_FLAGS if f not in extra)
    return dataclasses.replace(s, extra_cflags=extra, jacobian="sparse", expand=True)


#: kernel libraries built in this process, by :func:`kernel_key`
_BUILT: dict[str, Library] = {}
#: the gains the kernels compile in (graph-independent: the leader's LMIs and the UIO)
KERNEL_GAINS = ("A0", "B0", "C0", "Q", "Gamma", "Phi", "lambda1", "lambda2")


def kernel_key(
    sc: Scenario,
    gains: Gains,
    model_index: int,
    settings: CodegenSettings | None = None,
    openmp: bool = False,
) -> str:
    """SHA-256 of everything the kernels of one model compile in (never the graph, never N).

    The follower model and its parameters, the leader, the observer's, controller's and
    options' structural settings (:func:`symbolic.parameters.structure` without its
    graph, followers and gains), the gains of :data:`KERNEL_GAINS`, the distinct fault
    expressions in order, the driver sources and the compiler settings. Two scenarios
    with equal keys compile to the same library: this process builds it once
    (the build cache keys it again by its source).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    model_index : int
    settings : CodegenSettings, optional
    openmp : bool
    """
    from symbolic.parameters import structure

    st = structure(sc, gains)
    fo = sc.followers[model_index]
    texts: list[str] = []
    for f in sc.followers:
        for e in (f.g.expr, *f.f):
            if e.text not in texts:
                texts.append(e.text)
    desc = {
        "structure": {k: v for k, v in st.items() if k not in ("graph", "followers", "gains")},
        "gains": {k: np.asarray(getattr(gains, k), float).tolist() for k in KERNEL_GAINS},
        "model": [fo.model, sorted(fo.params.items())],
        "faults": texts,
        "driver": hashlib.sha256(
            (native.COMMON.read_text() + DRIVER.read_text()).encode()
        ).hexdigest(),
        "settings": repr(kernel_settings(settings, openmp)),
    }
    return hashlib.sha256(json.dumps(desc, sort_keys=True, default=str).encode()).hexdigest()


def build_models(
    sc: Scenario, gains: Gains, settings: CodegenSettings | None = None, openmp: bool = False
) -> tuple[list[Library], np.ndarray]:
    """Compile (or reuse from the cache) one kernel library per follower model.

    A model whose :func:`kernel_key` was built before in this process reuses that
    library without building anything symbolic.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
    settings : CodegenSettings, optional
        Compiler, flags, cache root and ``cse``.
    openmp : bool
        A threaded build (:func:`kernel_settings`), needed for ``LinearSettings.threads``
        above 1.

    Returns
    -------
    libraries : list of Library
        One per model group (:func:`symbolic.closed_loop.model_groups`), in group order.
    model : ndarray
        N ints: the library of each follower.
    """
    s = kernel_settings(settings, openmp)
    groups = model_groups(sc)
    model = np.zeros(sc.N, dtype=np.int32)
    libs = []
    for g, members in enumerate(groups):
        model[members] = g
        key = kernel_key(sc, gains, members[0], settings, openmp)
        lib = _BUILT.get(key)
        if lib is None or not lib.path.is_file():
            fns = kernel_functions(sc, gains, members[0], cse=s.cse)
            lib = build_library(fns, s, toolchain=native.toolchain(DRIVER))
            _BUILT[key] = lib
        else:
            lib = dataclasses.replace(lib, cache_hit=True, codegen_seconds=0.0, compile_seconds=0.0)
        libs.append(lib)
    return libs, model


# ----------------------------------------------------------------------------- runtime data
def topological_order(ptr: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, bool]:
    """An order of the followers in which each comes after the ones it hears, if any.

    Kahn's algorithm; when a cycle blocks it, the waiting follower with the fewest
    unheard followers goes next (ties by index), so the order is still a good one for
    the forward-substitution preconditioner.

    Parameters
    ----------
    ptr, idx : ndarray
        CSR: follower i hears ``idx[ptr[i]:ptr[i+1]]``.

    Returns
    -------
    order : ndarray
        N ints.
    acyclic : bool
        Whether no follower was placed before one it hears.
    """
    N = len(ptr) - 1
    indeg = np.diff(ptr).astype(int)
    listeners: list[list[int]] = [[] for _ in range(N)]
    for i in range(N):
        for j in idx[ptr[i] : ptr[i + 1]]:
            listeners[int(j)].append(i)
    done = np.zeros(N, bool)
    order: list[int] = []
    acyclic = True
    ready = sorted(int(i) for i in np.flatnonzero(indeg == 0))
    while len(order) < N:
        if not ready:  # a cycle: break it at the follower with the fewest missing inputs
            acyclic = False
            wait = np.flatnonzero(~done)
            ready = [int(wait[np.argmin(indeg[wait])])]
        j = ready.pop(0)
        if done[j]:
            continue
        done[j] = True
        order.append(j)
        for i in listeners[j]:
            indeg[i] -= 1
            if indeg[i] == 0 and not done[i]:
                ready.append(i)
        ready.sort()
    return np.asarray(order, dtype=np.int32), acyclic


@dataclass(frozen=True)
class Topology:
    """One topology as the driver reads it.

    Attributes
    ----------
    t_start : float
    ptr, idx, w : ndarray
        CSR of the off-diagonal (L + B)_ij of each row (follower i hears idx).
    cpl : ndarray
        N × 2: (l̄_ii, a_i0 h_i).
    order : ndarray
        Sorted by depth on an acyclic topology (each follower after all it hears).
    acyclic : bool
    waves : ndarray
        Pointers into ``order``: wave w (followers of depth w) is
        ``order[waves[w]:waves[w+1]]``; one wave per follower on a cycle.
    """

    t_start: float
    ptr: np.ndarray
    idx: np.ndarray
    w: np.ndarray
    cpl: np.ndarray
    order: np.ndarray
    acyclic: bool
    waves: np.ndarray


def depth_waves(
    ptr: np.ndarray, idx: np.ndarray, order: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``order`` regrouped by depth (1 + the largest depth of the followers heard).

    Parameters
    ----------
    ptr, idx : ndarray
        CSR of an acyclic topology.
    order : ndarray
        A topological order of it.

    Returns
    -------
    (order, waves) : (ndarray, ndarray)
        The followers sorted by (depth, position in ``order``) and the wave pointers.
    """
    depth = np.zeros(len(order), dtype=int)
    for i in order:
        js = idx[ptr[i] : ptr[i + 1]]
        depth[i] = 1 + depth[js].max() if len(js) else 0
    pos = np.empty(len(order), dtype=int)
    pos[order] = np.arange(len(order))
    new = np.asarray(sorted(order, key=lambda i: (depth[i], pos[i])), dtype=np.int32)
    counts = np.bincount(depth, minlength=depth.max() + 1)
    return new, np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)


def topology(t_start: float, adjacency: np.ndarray, pinning: np.ndarray, h: np.ndarray) -> Topology:
    """The driver's data of one graph (eq. (6)'s L + B and a0 ∘ h).

    Parameters
    ----------
    t_start : float
    adjacency : ndarray
        N×N, a_ij (follower i hears j).
    pinning : ndarray
        N, a_i0.
    h : ndarray
        N gauge signs.
    """
    L_B = pinned_laplacian(np.asarray(adjacency, float), np.asarray(pinning, float)).toarray()
    N = L_B.shape[0]
    ptr, idx, w = [0], [], []
    for i in range(N):
        js = [int(j) for j in np.flatnonzero(L_B[i]) if j != i]
        idx += js
        w += [float(L_B[i, j]) for j in js]
        ptr.append(len(idx))
    p, q = np.asarray(ptr, np.int32), np.asarray(idx, np.int32)
    order, acyclic = topological_order(p, q)
    if acyclic:
        order, waves = depth_waves(p, q, order)
    else:
        waves = np.arange(N + 1, dtype=np.int32)
    cpl = np.column_stack([np.diag(L_B), np.asarray(pinning, float) * h]).astype(float)
    return Topology(float(t_start), p, q, np.asarray(w, float), cpl, order, acyclic, waves)


@dataclass(frozen=True)
class AgentProblem:
    """Everything of a scenario the compiled kernels do not hold.

    Attributes
    ----------
    N, m, na, n : int
        Followers, leader states, states per follower, output coordinates.
    model : ndarray
        N ints: each follower's kernel library.
    fault_index : ndarray
        N × (1+n): ``gf`` of follower i is ``values[fault_index[i]]``.
    nfaults : int
        Length of the fault kernel's output.
    params : ndarray
        N × npar, agent-major.
    topologies : tuple of Topology
        The base graph, then one per switching time.
    """

    N: int
    m: int
    na: int
    n: int
    model: np.ndarray
    fault_index: np.ndarray
    nfaults: int
    params: np.ndarray
    topologies: tuple[Topology, ...]

    @property
    def nx(self) -> int:
        """States of the whole closed loop."""
        return self.m + self.N * self.na

    @property
    def acyclic(self) -> bool:
        """Whether every topology is acyclic."""
        return all(t.acyclic for t in self.topologies)


def problem(sc: Scenario, gains: Gains, model: np.ndarray) -> AgentProblem:
    """The runtime data of ``sc`` (graph, per-agent numbers, fault indices).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
        Supplies the gauge h (checked against the graph).
    model : ndarray
        From :func:`build_models`.

    Raises
    ------
    ScenarioError
        If ``gains.H`` is not N signs.
    """
    h = np.diag(np.atleast_2d(gains.H)).astype(float)
    if h.shape != (sc.N,) or not np.all(np.abs(h) == 1.0):
        raise ScenarioError("gains", "H", f"gauge has entries {h}", f"{sc.N} signs +1/-1")
    lay = make_layout(sc.m, sc.n, sc.N, sc.options.derivatives == "filtered")
    faults, fidx = fault_function(sc)
    tops = tuple(topology(t.t_start, t.adjacency, t.pinning, h) for t in sc.graph.topologies())
    return AgentProblem(
        N=sc.N,
        m=sc.m,
        na=lay.agent_size,
        n=sc.n,
        model=np.asarray(model, np.int32),
        fault_index=np.asarray(fidx, np.int32).reshape(sc.N, 1 + sc.n),
        nfaults=int(faults.sparsity_out(0).numel()),
        params=np.ascontiguousarray(param_matrix(sc).T, dtype=float),
        topologies=tops,
    )


# ----------------------------------------------------------------------------- ctypes
_FN = ctypes.c_void_p


class Kernels(ctypes.Structure):
    """``hitl_agent_kernels`` of agents.c."""

    _fields_ = [
        ("jet", _FN * 3),
        ("rhs", _FN),
        ("jac", _FN),
        ("jet_work", _FN * 3),
        ("rhs_work", _FN),
        ("jac_work", _FN),
    ]


_IP = ctypes.POINTER(ctypes.c_int)
_DP = ctypes.POINTER(ctypes.c_double)


class Problem(ctypes.Structure):
    """``hitl_agents_problem`` of agents.c."""

    _fields_ = [
        ("N", ctypes.c_int),
        ("m", ctypes.c_int),
        ("na", ctypes.c_int),
        ("n", ctypes.c_int),
        ("npar", ctypes.c_int),
        ("nmodels", ctypes.c_int),
        ("kern", ctypes.POINTER(Kernels)),
        ("model", _IP),
        ("faults", _FN),
        ("faults_work", _FN),
        ("nfaults", ctypes.c_int),
        ("fidx", _IP),
        ("prm", _DP),
        ("ntop", ctypes.c_int),
        ("t_switch", _DP),
        ("ptr", _IP),
        ("idx", _IP),
        ("w", _DP),
        ("cpl", _DP),
        ("order", _IP),
        ("acyclic", _IP),
        ("nwaves", _IP),
        ("wave_ptr", _IP),
        ("solver", ctypes.c_int),
        ("nthreads", ctypes.c_int),
        ("krylov", ctypes.c_int),
        ("ls_tol", ctypes.c_double),
        ("max_iter", ctypes.c_int),
    ]


@dataclass(frozen=True)
class LinearSettings:
    """How the driver solves its Newton systems and how many threads it uses.

    Attributes
    ----------
    solver : str
        ``auto`` (forward substitution on an acyclic topology, GMRES otherwise),
        ``forward``, ``dense`` or ``gmres`` (:data:`SOLVERS`).
    threads : int
        OpenMP threads over the agents; 0 = OpenMP's default.
    krylov : int
        GMRES restart length.
    tol : float
        GMRES: relative residual of the jets system reached at every solve.
    max_iter : int
        GMRES iterations per solve before the solve fails (CVODE then retries).
    """

    solver: str = "auto"
    threads: int = 1
    krylov: int = 30
    tol: float = 1e-12
    max_iter: int = 300

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise IntegrationError(
                f"agents solver: {self.solver!r} is not one of {', '.join(SOLVERS)}"
            )


def _fn(lib: ctypes.CDLL, name: str) -> int:
    return ctypes.cast(getattr(lib, name), ctypes.c_void_p).value


def _kernels(lib: ctypes.CDLL) -> Kernels:
    k = Kernels()
    for lev, name in enumerate(JET_NAMES):
        k.jet[lev] = _fn(lib, name)
        k.jet_work[lev] = _fn(lib, name + "_work")
    k.rhs, k.rhs_work = _fn(lib, RHS_NAME), _fn(lib, RHS_NAME + "_work")
    k.jac, k.jac_work = _fn(lib, JAC_NAME), _fn(lib, JAC_NAME + "_work")
    return k


def load(libraries: Sequence[Path]) -> list[ctypes.CDLL]:
    """The kernel libraries, loaded and checked (struct sizes against the mirror).

    Parameters
    ----------
    libraries : sequence of Path

    Raises
    ------
    BuildError
        As :func:`generated.native.open_library`.
    IntegrationError
        If a library's problem struct differs from :class:`Problem`.
    """
    libs = [native.load(Path(p)) for p in libraries]
    ci, cd, prob = ctypes.c_int, ctypes.c_double, ctypes.POINTER(Problem)
    opts, res = ctypes.POINTER(native.Options), ctypes.POINTER(native.Result)
    for lib, p in zip(libs, libraries, strict=True):
        lib.hitl_agents_problem_size.restype = ctypes.c_long
        lib.hitl_agents_openmp.restype = ci
        lib.hitl_agents_run.restype = ci
        lib.hitl_agents_run.argtypes = [prob, _DP, opts, res, ctypes.POINTER(ctypes.c_long)]
        lib.hitl_agents_probe.restype = ci
        lib.hitl_agents_probe.argtypes = [prob, cd, _DP, cd, _DP, _DP, _DP, ctypes.c_char_p, ci]
        if lib.hitl_agents_problem_size() != ctypes.sizeof(Problem):
            raise IntegrationError(f"{Path(p).name}: hitl_agents_problem differs from the mirror")
    return libs


def _c_problem(
    libs: list[ctypes.CDLL], prob: AgentProblem, ls: LinearSettings
) -> tuple[Problem, list]:
    """The driver's problem struct and the arrays it points into (kept alive by the caller)."""
    tops = prob.topologies
    N = prob.N
    offs = np.cumsum([0] + [len(t.idx) for t in tops])
    ptr = np.concatenate([t.ptr + offs[k] for k, t in enumerate(tops)]).astype(np.int32)
    arrays = {
        "model": np.ascontiguousarray(prob.model, np.int32),
        "fidx": np.ascontiguousarray(prob.fault_index.ravel(), np.int32),
        "prm": np.ascontiguousarray(prob.params, float),
        "t_switch": np.ascontiguousarray([t.t_start for t in tops[1:]] + [0.0], float),
        "ptr": np.ascontiguousarray(ptr),
        "idx": np.ascontiguousarray(np.concatenate([t.idx for t in tops] + [[0]]), np.int32),
        "w": np.ascontiguousarray(np.concatenate([t.w for t in tops] + [[0.0]]), float),
        "cpl": np.ascontiguousarray(np.concatenate([t.cpl.ravel() for t in tops]), float),
        "order": np.ascontiguousarray(np.concatenate([t.order for t in tops]), np.int32),
        "acyclic": np.asarray([int(t.acyclic) for t in tops], np.int32),
        "nwaves": np.asarray([len(t.waves) - 1 if t.acyclic else 0 for t in tops], np.int32),
        "wave_ptr": np.concatenate(
            [np.pad(t.waves, (0, N + 1 - len(t.waves))) for t in tops]
        ).astype(np.int32),
    }
    kern = (Kernels * len(libs))(*[_kernels(lib) for lib in libs])
    c = Problem(
        N=N,
        m=prob.m,
        na=prob.na,
        n=prob.n,
        npar=prob.params.shape[1],
        nmodels=len(libs),
        kern=kern,
        faults=_fn(libs[0], FAULTS_NAME),
        faults_work=_fn(libs[0], FAULTS_NAME + "_work"),
        nfaults=prob.nfaults,
        ntop=len(tops),
        solver=SOLVERS[ls.solver],
        nthreads=int(ls.threads),
        krylov=int(ls.krylov),
        ls_tol=float(ls.tol),
        max_iter=int(ls.max_iter),
    )
    for name, a in arrays.items():
        ptype = _IP if a.dtype == np.int32 else _DP
        setattr(c, name, a.ctypes.data_as(ptype))
    return c, [kern, *arrays.values()]


def _check_threads(libs: list[ctypes.CDLL], linear: LinearSettings) -> None:
    if linear.threads != 1 and not libs[0].hitl_agents_openmp():
        raise IntegrationError(
            f"agents threads: {linear.threads} needs the threaded build "
            "(build_models(..., openmp=True)); or threads = 1"
        )


def _state(prob: AgentProblem, x: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=float).ravel()
    if x.size != prob.nx:
        raise IntegrationError(f"x: {x.size} entries, the closed loop has {prob.nx} states")
    return x


def run(
    libraries: Sequence[Path],
    prob: AgentProblem,
    x0: np.ndarray,
    t_out: np.ndarray,
    settings: IntegratorSettings,
    *,
    linear: LinearSettings | None = None,
    breakpoints: Sequence[float] = (),
    progress: Callable[[float], None] | None = None,
) -> Trajectory:
    """Integrate the closed loop with the per-agent driver.

    Parameters
    ----------
    libraries : sequence of Path
        ``Library.path`` of :func:`build_models`, in model order.
    prob : AgentProblem
    x0 : ndarray
        The whole closed loop's initial state at ``t_out[0]``.
    t_out : ndarray
        Increasing output times.
    settings : IntegratorSettings
        ``rtol``, ``atol`` and ``max_steps``.
    linear : LinearSettings, optional
    breakpoints : sequence of float
        Restart times (faults, graph switches), reconciled with ``t_out``.
    progress : callable, optional

    Returns
    -------
    Trajectory
        Method ``"native"``; ``stats["krylov_iters"]`` counts GMRES iterations.
    """
    wall0 = time.perf_counter()
    libs = load(libraries)
    x = _state(prob, x0)
    linear = linear or LinearSettings()
    _check_threads(libs, linear)
    call = native.DriverCall.of(x.size, t_out, settings, breakpoints)
    cp, _keep = _c_problem(libs, prob, linear)
    kry = ctypes.c_long(0)
    libs[0].hitl_agents_run(
        ctypes.byref(cp),
        native.dptr(x),
        ctypes.byref(call.options),
        ctypes.byref(call.result),
        ctypes.byref(kry),
    )
    traj = call.trajectory("native", wall0, progress)
    traj.stats["krylov_iters"] = int(kry.value)
    return traj


def probe(
    libraries: Sequence[Path],
    prob: AgentProblem,
    t: float,
    x: np.ndarray,
    gamma: float,
    b: np.ndarray,
    linear: LinearSettings | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The driver's right-hand side at (t, x) and its solution of (I − γJ) sol = b.

    Parameters
    ----------
    libraries : sequence of Path
    prob : AgentProblem
    t : float
    x, b : ndarray
    gamma : float
    linear : LinearSettings, optional

    Returns
    -------
    (xdot, sol) : (ndarray, ndarray)

    Raises
    ------
    IntegrationError
        Wrong sizes, or the driver failed (singular block, GMRES not converged).
    """
    libs = load(libraries)
    linear = linear or LinearSettings()
    _check_threads(libs, linear)
    x, b = _state(prob, x), _state(prob, b)
    xdot, sol = np.zeros_like(x), np.zeros_like(x)
    msg = ctypes.create_string_buffer(native.MSG_LEN)
    cp, _keep = _c_problem(libs, prob, linear)
    dp = native.dptr
    ret = libs[0].hitl_agents_probe(
        ctypes.byref(cp),
        float(t),
        dp(x),
        float(gamma),
        dp(b),
        dp(xdot),
        dp(sol),
        msg,
        native.MSG_LEN,
    )
    if ret != 0:
        raise IntegrationError(
            f"per-agent driver: {msg.value.decode(errors='replace') or 'solve failed'}"
        )
    return xdot, sol


def initial_state(sc: Scenario) -> np.ndarray:
    """x(0) of ``sc`` without the whole closed loop (``initial.start = "given"``, oracle).

    The same state as :func:`symbolic.closed_loop.initial_state` for these options (which
    then needs no output of the loop): Table 2's states as given.

    Parameters
    ----------
    sc : Scenario

    Raises
    ------
    ScenarioError
        For ``initial.start = "formation"`` or filtered derivatives (their x(0) needs
        η̇_i(0) and b_i(0): use the whole closed loop's x0).
    """
    if sc.initial.start != "given" or sc.options.derivatives != "oracle":
        raise ScenarioError(
            sc.path,
            "initial.start",
            "x(0) of 'formation' or filtered derivatives needs the closed loop's outputs",
            'initial.start = "given" with options.derivatives = "oracle", or the whole '
            "closed loop's x0",
        )
    N = sc.N
    lay = make_layout(sc.m, sc.n, N, False)
    return lay.pack(
        {
            "eta0": sc.leader.eta0,
            "mu": sc.initial.mu,
            "eta": sc.initial.eta,
            "phi": sc.observer.phi0.reshape(N, 1),
            "p": np.array([fo.p0 for fo in sc.followers]),
            "q": np.array([fo.q0 for fo in sc.followers]),
            "thetahat": sc.initial.theta_hat,
            "ghat": sc.initial.ghat.reshape(N, 1),
        }
    )
