"""Method ``native``'s engine: the per-agent driver, with the graph as runtime data.

One kernel library per follower model (:mod:`generated.agent_kernels`, whose
:func:`build_models` and :func:`kernel_key` are re-exported here: the one import path of
the method), evaluated over the agents by ``generated/native/agents.c``; N, the graph and
each follower's numbers are an :class:`AgentProblem`.
"""

from __future__ import annotations

import ctypes
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from core.errors import IntegrationError, ScenarioError
from core.scenario import Scenario
from generated import native
from generated.agent_graph import Segment, Topology, segments, topology
from generated.agent_kernels import KERNELS
from generated.agent_kernels import build_models as build_models
from generated.agent_kernels import kernel_key as kernel_key
from generated.loaded import open_kernels
from generated.schedule import schedule
from generated.values import IntegratorSettings, Status, Trajectory, flag_reason, flag_status
from symbolic.closed_loop import given_states, observer_gains
from symbolic.closed_loop import make_layout as make_layout
from symbolic.parameters import agent_rows
from synthesis.gains import Gains

#: Newton-system solvers of the driver (``HITL_AG_*`` in agents.c)
SOLVERS = {"auto": 0, "forward": 1, "dense": 2, "gmres": 3}


@dataclass(frozen=True)
class AgentProblem:
    """Everything of a scenario the compiled kernels do not hold.

    Attributes
    ----------
    N, m, na, n : int
        Followers, leader states, states per follower, output coordinates.
    model : ndarray
        N ints: each follower's kernel library.
    params : ndarray
        N × npar: each follower's row of :func:`symbolic.parameters.agent_rows`.
    topologies : tuple of Topology
        The base graph, then one per switching time.
    fade : float
        ``graph.link_fade``: seconds a switch's weights fade over (0: raw).
    """

    N: int
    m: int
    na: int
    n: int
    model: np.ndarray
    params: np.ndarray
    topologies: tuple[Topology, ...]
    fade: float

    @cached_property
    def segments(self) -> tuple[Segment, ...]:
        """What the driver reads (:func:`generated.agent_graph.segments`)."""
        return segments(self.topologies, self.fade)

    @property
    def nx(self) -> int:
        """States of the whole closed loop."""
        return self.m + self.N * self.na

    @property
    def acyclic(self) -> bool:
        """Whether every segment is acyclic (while links fade: the union of the topologies)."""
        return all(s.graph.acyclic for s in self.segments)


def problem(sc: Scenario, gains: Gains, model: np.ndarray) -> AgentProblem:
    """The runtime data of ``sc`` (graph, per-agent numbers).

    Parameters
    ----------
    sc : Scenario
    gains : Gains
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
    tops = tuple(topology(t.t_start, t.adjacency, t.pinning, h) for t in sc.graph.topologies())
    return AgentProblem(
        N=sc.N,
        m=sc.m,
        na=lay.agent_size,
        n=sc.n,
        model=np.asarray(model, np.int32),
        params=np.ascontiguousarray(agent_rows(sc, observer_gains(sc, gains)), dtype=float),
        topologies=tops,
        fade=float(sc.graph.link_fade) if len(tops) > 1 else 0.0,
    )


# ----------------------------------------------------------------------------- ctypes
_FN = ctypes.c_void_p


class Kernels(ctypes.Structure):
    """``hitl_agent_kernels`` of agents.c: the :data:`KERNELS` and their work sizes."""

    _fields_ = [("fn", _FN * len(KERNELS)), ("work", _FN * len(KERNELS))]


_IP, _DP = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_double)


class Problem(ctypes.Structure):
    """``hitl_agents_problem`` of agents.c."""

    _fields_ = [
        *((name, ctypes.c_int) for name in ("N", "m", "na", "n", "npar", "nmodels")),
        ("kern", ctypes.POINTER(Kernels)),
        ("model", _IP),
        ("prm", _DP),
        ("ntop", ctypes.c_int),
        ("t_switch", _DP),
        ("ptr", _IP),
        ("idx", _IP),
        ("w", _DP),
        ("cpl", _DP),
        ("order", _IP),
        ("acyclic", _IP),
        ("solver", ctypes.c_int),
        ("nthreads", ctypes.c_int),
        ("koff", _IP),
        ("poff", _IP),
        ("lead_nz", _IP),
        ("depth", _IP),
        ("act_ptr", _IP),
        ("act_top", _IP),
        ("w_off", _IP),
        ("ngraph", ctypes.c_int),
        ("t_graph", _DP),
        ("fade", ctypes.c_double),
    ]


@dataclass(frozen=True)
class LinearSettings:
    """How the driver solves its Newton systems (docs/performance.md) and its threads.

    Attributes
    ----------
    solver : str
        One of :data:`SOLVERS`; ``auto``: forward substitution on an acyclic topology,
        GMRES otherwise.
    threads : int
        OpenMP threads over the agents; 0 = OpenMP's default.
    """

    solver: str = "auto"
    threads: int = 1

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise IntegrationError(
                f"agents solver: {self.solver!r} is not one of {', '.join(SOLVERS)}"
            )


def _kernels(lib: ctypes.CDLL) -> Kernels:
    """The library's :data:`KERNELS` and their work-size functions."""
    k = Kernels()
    for q, name in enumerate(KERNELS):
        k.fn[q] = ctypes.cast(getattr(lib, name), _FN).value
        k.work[q] = ctypes.cast(getattr(lib, name + "_work"), _FN).value
    return k


def k_pattern(lib: ctypes.CDLL) -> tuple[int, np.ndarray, np.ndarray]:
    """K's structural pattern as the library's ``ag_jac`` writes it (:func:`parse_sparsity`).

    Parameters
    ----------
    lib : ctypes.CDLL
        A kernel library (:func:`load`).
    """
    return _sparsity_out(lib, "ag_jac", 1)


def _sparsity_out(lib: ctypes.CDLL, name: str, j: int) -> tuple[int, np.ndarray, np.ndarray]:
    """:func:`parse_sparsity` of output ``j`` of the library's Function ``name``."""
    f = getattr(lib, name + "_sparsity_out")
    f.restype = ctypes.POINTER(ctypes.c_longlong)
    f.argtypes = [ctypes.c_longlong]
    return parse_sparsity(f(j))


def parse_sparsity(sp: Sequence[int]) -> tuple[int, np.ndarray, np.ndarray]:
    """nrow, the column pointers and the rows of a pattern in CasADi's generated-code format.

    Parameters
    ----------
    sp : indexable of int
        ``nrow, ncol``, column pointers, rows; or ``nrow, ncol, 1`` for a dense pattern.
    """
    nrow, ncol = int(sp[0]), int(sp[1])
    if sp[2] == 1:  # a general pattern's first column pointer is 0
        return nrow, np.arange(ncol + 1) * nrow, np.tile(np.arange(nrow), ncol)
    colind = np.array([int(sp[2 + q]) for q in range(ncol + 1)])
    rows = np.array([int(sp[3 + ncol + q]) for q in range(colind[-1])])
    return nrow, colind, rows


def _k_layout(libs: list[ctypes.CDLL], model: np.ndarray, m: int) -> dict[str, np.ndarray]:
    """koff, poff (each agent's K nonzeros and packed factorisation) and lead_nz."""
    pats = [k_pattern(lib) for lib in libs]
    nnz = np.array([int(pats[j][1][-1]) for j in model])
    # doubles of each agent's packed factorisation P (ag_nfac's first output)
    npk = np.array([_sparsity_out(lib, "ag_nfac", 0)[1][-1] for lib in libs])[model]
    _, colind, rows = pats[model[0]]
    lead = -np.ones((m, m), np.int32)  # column-major, as the driver reads it
    q = np.arange(colind[m])  # the nonzeros of the leader's columns, then its rows
    q = q[rows[q] < m]
    lead[np.searchsorted(colind, q, side="right") - 1, rows[q]] = q
    return {
        "koff": np.concatenate([[0], np.cumsum(nnz)]).astype(np.int32),
        "poff": np.concatenate([[0], np.cumsum(npk)]).astype(np.int32),
        "lead_nz": np.ascontiguousarray(lead.ravel()),
    }


def load(libraries: Sequence[Path]) -> list[ctypes.CDLL]:
    """The kernel libraries, loaded and checked (:func:`generated.native.open_library`).

    Parameters
    ----------
    libraries : sequence of Path

    Raises
    ------
    IntegrationError
        If a library's problem struct differs from :class:`Problem`.
    """
    # read once, when the first OpenMP library loads: sleeping threads cost more to wake
    # than a wave takes (docs/performance.md)
    os.environ.setdefault("OMP_WAIT_POLICY", "active")
    libs = [open_kernels(Path(p)) for p in libraries]  # from verified private copies
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
    libraries: Sequence[Path], prob: AgentProblem, linear: LinearSettings | None
) -> tuple[list[ctypes.CDLL], Problem, list]:
    """The loaded libraries, the driver's problem struct and the arrays it points into."""
    libs = load(libraries)
    ls = linear or LinearSettings()
    if ls.threads != 1 and not libs[0].hitl_agents_openmp():
        raise IntegrationError(
            f"agents threads: {ls.threads} needs the threaded build "
            "(build_models(..., openmp=True)); or threads = 1"
        )
    segs = prob.segments
    tops = [s.graph for s in segs]  # each segment's pattern (the union while links fade)
    offs = np.cumsum([0] + [len(t.idx) for t in tops])
    ptr = np.concatenate([t.ptr + offs[k] for k, t in enumerate(tops)]).astype(np.int32)
    nact = [len(s.active) for s in segs]
    w_off = np.cumsum([0] + [len(t.idx) for s, t in zip(segs, tops, strict=True) for _ in s.active])
    arrays = {
        "model": np.ascontiguousarray(prob.model, np.int32),
        "prm": np.ascontiguousarray(prob.params, float),
        "t_switch": np.ascontiguousarray([s.t_start for s in segs[1:]] + [0.0], float),
        "ptr": np.ascontiguousarray(ptr),
        "idx": np.ascontiguousarray(np.concatenate([t.idx for t in tops] + [[0]]), np.int32),
        "w": np.ascontiguousarray(np.concatenate([s.w.ravel() for s in segs] + [[0.0]]), float),
        "cpl": np.ascontiguousarray(np.concatenate([s.cpl.ravel() for s in segs]), float),
        "act_ptr": np.concatenate([[0], np.cumsum(nact)]).astype(np.int32),
        "act_top": np.ascontiguousarray(np.concatenate([s.active for s in segs]), np.int32),
        "w_off": np.ascontiguousarray(w_off[:-1], np.int32),
        "t_graph": np.ascontiguousarray([t.t_start for t in prob.topologies], float),
        "order": np.ascontiguousarray(np.concatenate([t.order for t in tops]), np.int32),
        "acyclic": np.asarray([int(t.acyclic) for t in tops], np.int32),
        "depth": np.ascontiguousarray(np.concatenate([t.depth for t in tops]), np.int32),
        **_k_layout(libs, np.asarray(prob.model), prob.m),
    }
    kern = (Kernels * len(libs))(*[_kernels(lib) for lib in libs])
    c = Problem(
        N=prob.N,
        m=prob.m,
        na=prob.na,
        n=prob.n,
        npar=prob.params.shape[1],
        nmodels=len(libs),
        kern=kern,
        ntop=len(segs),
        ngraph=len(prob.topologies),
        fade=float(prob.fade),
        solver=SOLVERS[ls.solver],
        nthreads=int(ls.threads),
    )
    for name, a in arrays.items():
        ptype = _IP if a.dtype == np.int32 else _DP
        setattr(c, name, a.ctypes.data_as(ptype))
    return libs, c, [kern, *arrays.values()]


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
    """Integrate the closed loop with the per-agent driver (``stats["krylov_iters"]``: GMRES).

    Parameters
    ----------
    libraries : sequence of Path
        ``Library.path`` of :func:`build_models`, in model order.
    prob : AgentProblem
    x0 : ndarray
    t_out : ndarray
    settings : IntegratorSettings
    linear : LinearSettings, optional
    breakpoints : sequence of float
        Restart times (faults, graph switches).
    progress : callable, optional
    """
    wall0 = time.perf_counter()
    libs, cp, _keep = _c_problem(libraries, prob, linear)
    x = _checked_state(x0, prob.nx)
    sched = schedule(t_out, breakpoints)
    fd, name = tempfile.mkstemp(prefix="hitl-sundials-", suffix=".log")  # SUNDIALS' messages
    os.close(fd)
    log = Path(name)
    tq = np.ascontiguousarray(sched.targets, dtype=float)
    bps = np.ascontiguousarray(sched.breaks, dtype=float)
    X, x_stop = np.full((len(sched.t_out), x.size), np.nan), np.full(x.size, np.nan)
    options = native.Options(
        rtol=float(settings.rtol),
        atol=float(settings.atol),
        max_steps=int(settings.max_steps),
        nt=len(tq),
        t_out=_dptr(tq),
        nb=len(bps),
        breaks=_dptr(bps),
        log_path=str(log).encode(),
    )
    result = native.Result(x_out=_dptr(X), x_stop=_dptr(x_stop))
    kry = ctypes.c_long(0)
    try:
        libs[0].hitl_agents_run(
            ctypes.byref(cp),
            _dptr(x),
            ctypes.byref(options),
            ctypes.byref(result),
            ctypes.byref(kry),
        )
        sundials_log = log.read_text(errors="replace")
    except OSError:
        sundials_log = ""
    finally:  # removed however the run ends (an interrupt included)
        log.unlink(missing_ok=True)
    traj = _trajectory(result, sched.t_out, X, x_stop, sundials_log, wall0)
    traj.stats["krylov_iters"] = int(kry.value)
    if progress is not None:
        progress(traj.t_reached)
    return traj


def _trajectory(
    result: native.Result,
    t_out: np.ndarray,
    X: np.ndarray,
    x_stop: np.ndarray,
    sundials_log: str,
    wall0: float,
) -> Trajectory:
    """The :class:`Trajectory` of what the driver filled in (rows of ``X`` up to ``filled``)."""
    text = result.msg.decode(errors="replace").strip()
    filled = int(result.filled)
    if filled < 1:
        raise IntegrationError(f"native integrator could not start: {text or 'unknown error'}")
    stats: dict[str, float | int] = {k: int(getattr(result, k)) for k in native.COUNTERS}
    stats.update(last_step=float(result.last_step), integrator_calls=1, jtimes_evals=0)
    stats["wall_seconds"] = time.perf_counter() - wall0
    t_reached = float(t_out[filled - 1])
    message, status = "", Status.OK
    if filled < len(t_out):  # "FLAG_NAME: SUNDIALS message"
        name, _, detail = text.partition(":")
        flag = name.strip() or str(int(result.flag))
        status = flag_status(flag)
        message = (
            f"native failed after t = {t_reached:.6g} s (working towards t = "
            f"{float(t_out[filled]):.6g} s): {flag_reason(flag)}"
            + (f" ({detail.strip()})" if detail.strip() else "")
        )
    return Trajectory(
        t=t_out[:filled].copy(),
        x=X[:filled],
        z=None,
        method="native",
        status=status,
        t_reached=t_reached,
        message=message,
        stats=stats,
        sundials_log=sundials_log,
        t_stop=float(result.t_stop),
        x_stop=x_stop.copy(),
    )


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

    Raises
    ------
    IntegrationError
        Wrong sizes, or the driver failed (singular block, GMRES not converged).
    """
    libs, cp, _keep = _c_problem(libraries, prob, linear)
    x, b = _checked_state(x, prob.nx), _checked_state(b, prob.nx)
    xdot, sol = np.zeros_like(x), np.zeros_like(x)
    msg = ctypes.create_string_buffer(native.MSG_LEN)
    args = (_dptr(x), float(gamma), _dptr(b), _dptr(xdot), _dptr(sol), msg, native.MSG_LEN)
    if libs[0].hitl_agents_probe(ctypes.byref(cp), float(t), *args) != 0:
        why = msg.value.decode(errors="replace") or "solve failed"
        raise IntegrationError(f"per-agent driver: {why}")
    return xdot, sol


def _dptr(a: np.ndarray) -> ctypes._Pointer:
    """A ``double *`` into a C-contiguous float64 array (the caller keeps it alive)."""
    return a.ctypes.data_as(_DP)


def _checked_state(x: np.ndarray, nx: int) -> np.ndarray:
    """``x`` as a contiguous float vector of the closed loop's ``nx`` states."""
    x = np.ascontiguousarray(x, dtype=float).ravel()
    if x.size != nx:
        raise IntegrationError(f"x: {x.size} entries, the closed loop has {nx} states")
    return x


def initial_state(sc: Scenario) -> np.ndarray:
    """x(0) of ``sc`` (Table 2's states) without the whole closed loop: ``initial.start =
    "given"`` with oracle derivatives only (otherwise it needs the loop's outputs).

    Parameters
    ----------
    sc : Scenario

    Raises
    ------
    ScenarioError
        For ``initial.start = "formation"`` or filtered derivatives.
    """
    if sc.initial.start != "given" or sc.options.derivatives != "oracle":
        raise ScenarioError(
            sc.path,
            "initial.start",
            "x(0) of 'formation' or filtered derivatives needs the closed loop's outputs",
            'initial.start = "given" with options.derivatives = "oracle", or the whole '
            "closed loop's x0",
        )
    return make_layout(sc.m, sc.n, sc.N, False).pack(given_states(sc))
