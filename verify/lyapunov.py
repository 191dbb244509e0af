"""Exact Lyapunov derivatives by automatic differentiation, and the pointwise checks.

V̇ = ∂V/∂x · f(t, x) + ∂V/∂t is built symbolically from the closed loop's
``outputs`` (V1, V2) and ``ode`` functions with CasADi (``jtimes`` and
``jacobian``); it is then evaluated at the stored states. No sampled data is
ever differenced here (the test suite differences V only to cross-check).

Theorem 1 (eq. (27)): V̇1 ≤ −δ̃ V1; with the φ floor φ_min > 0, V̇1 ≤ −δ̃ V1 + c_φ.
Theorem 2 (eqs. (36)–(38)): per follower,
V̇2i ≤ −χᵀKχ − ½k2‖θ̂ − d‖² + ½k2‖d‖² (+ Σ_r θ̂_r(|χ_r| − χ_r sgn_ε(χ_r)) with a boundary
layer; + the σ-modification's exact term −(gσ/γ)(ĝ − 1/g)(ĝ − ĝ0) when that law is on).

Speed (docs/verification.md, 'Evaluation cost'): for a closed loop with runtime parameters
(``cl.parametric``) the Functions evaluated along a trajectory, ``(t, x, p) -> (V1, V̇1,
V2, V̇2, χ)`` (one Function: one right-hand side for both V̇) and the outputs, are built
once per structure key from the parametric loop, expanded to SX, kept in this process
(:func:`fast_functions`) and mapped over the output times with the run's own p as a
non-mapped input; from the
:data:`COMPILE_FROM_USE`-th verification of one structure in a process (a study) they are
compiled to C through the content-addressed build cache. A closed loop without
``parametric``, or a check with another vector field (``ode=``), takes the MX path
(:func:`lyapunov_derivative`).
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from core.errors import BuildError
from core.memo import MEMO
from core.scenario import Scenario
from generated.csource import expanded
from verify.bounds import VerifyConfig, VerifyError

#: a structure's verify Functions are compiled to C from its this-many-th verification in one
#: process: a study's samples share one structure, a single run (one use) stays in CasADi's SX
#: virtual machine (docs/verification.md, 'Evaluation cost'); a loop with the graph as data
#: (a study's random graphs, one structure per N) is compiled from its first verification
COMPILE_FROM_USE = 2
#: structures whose Functions are kept per process (a random-graph study with the graph as
#: data has one per N)
CACHE_SIZE = 24


@dataclass(frozen=True)
class InequalityCheck:
    """A pointwise inequality lhs ≤ rhs evaluated at every output time.

    Attributes
    ----------
    claim : str
        What was checked.
    agent : int | None
        0-based follower, or None for a network-wide function.
    t, lhs, rhs : ndarray
        Times and both sides.
    holds : ndarray of bool
        lhs ≤ rhs + rtol·scale at each time.
    fraction : float
        Share of output times where it holds.
    worst : float
        max(lhs − rhs) (≤ 0 when it holds everywhere).
    t_worst : float
        Time of ``worst``.
    """

    claim: str
    agent: int | None
    t: np.ndarray
    lhs: np.ndarray
    rhs: np.ndarray
    holds: np.ndarray
    fraction: float
    worst: float
    t_worst: float

    @property
    def ok(self) -> bool:
        return bool(self.holds.all())

    def where(self) -> str:
        """One line saying where the inequality fails worst (or that it does not)."""
        who = "network" if self.agent is None else f"follower {self.agent + 1}"
        if self.ok:
            return f"{self.claim} holds for {who} at all {len(self.t)} output times"
        k = int(np.argmax(self.lhs - self.rhs))
        return (
            f"{self.claim} fails for {who}: worst at t = {self.t_worst:.4g} s, "
            f"lhs = {self.lhs[k]:.6g} > rhs = {self.rhs[k]:.6g}; holds at {100 * self.fraction:.1f}% "
            "of output times"
        )


def _make(claim, agent, t, lhs, rhs, scale, rtol) -> InequalityCheck:  # noqa: ANN001
    gap = lhs - rhs
    holds = gap <= rtol * scale
    k = int(np.argmax(gap))
    return InequalityCheck(
        claim=claim,
        agent=agent,
        t=t,
        lhs=lhs,
        rhs=rhs,
        holds=holds,
        fraction=float(holds.mean()) if len(holds) else 1.0,
        worst=float(gap[k]),
        t_worst=float(t[k]),
    )


def output_names(cl: Any) -> list[str]:
    """Names of the closed loop's outputs.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    """
    return list(cl.outputs.name_out())


def symbolic_outputs(cl: Any, t: Any, x: Any) -> dict[str, Any]:
    """Call ``cl.outputs`` on symbols and return {name: expression}.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    t : casadi.SX or MX
        Time symbol.
    x : casadi.SX or MX
        State symbol (nx entries).
    """
    res = cl.outputs.call([t, x])
    return dict(zip(cl.outputs.name_out(), res, strict=True))


def lyapunov_derivative(cl: Any, name: str, ode: ca.Function | None = None) -> ca.Function:
    """``(t, x) -> (V, V̇)`` with V̇ = ∂V/∂x f(t, x) + ∂V/∂t exact (AD).

    Parameters
    ----------
    cl : ClosedLoop
        Provides ``outputs`` (with output ``name``) and ``ode``.
    name : str
        Output holding V (scalar V1 or the N-vector V2).
    ode : casadi.Function, optional
        A different vector field (e.g. a deliberately wrong adaptive law).

    Returns
    -------
    casadi.Function
    """
    f = ode if ode is not None else cl.ode
    t = ca.MX.sym("t")
    x = ca.MX.sym("x", cl.layout.nx)
    outs = symbolic_outputs(cl, t, x)
    if name not in outs:
        raise VerifyError(
            f"closed loop has no output {name!r} (outputs: {', '.join(outs)}); update verify"
        )
    V = ca.vec(outs[name])  # V1 (1×1) or V2 (N×1)
    xdot = f.call([t, x])[0]
    # eq. (18)–(26) (V̇1) and eq. (33)–(35) (V̇2) are derived in the paper by hand; here the
    # derivative along the flow is exact: ∂V/∂x · f + ∂V/∂t
    Vdot = ca.jtimes(V, x, xdot) + ca.jacobian(V, t)
    return ca.Function(f"{name}_dot", [t, x], [V, Vdot], ["t", "x"], [name, f"{name}_dot"])


def evaluate(fun: ca.Function, t: np.ndarray, X: np.ndarray) -> list[np.ndarray]:
    """Evaluate a ``(t, x) -> ...`` function at K samples; X is (K, nx).

    Parameters
    ----------
    fun : casadi.Function
        A Function of ``(t, x)``.
    t : ndarray
        K sample times.
    X : ndarray
        (K, nx) states at those times.

    Returns
    -------
    list of ndarray
        One (K, rows, cols) array per output.
    """
    K = len(t)
    res = fun.map(K)(np.asarray(t, dtype=float).reshape(1, K), np.asarray(X, dtype=float).T)
    return _blocks(fun, res, K)


def _blocks(fun: ca.Function, res: Any, K: int) -> list[np.ndarray]:
    """A K-fold map's outputs as one (K, rows, cols) array per output of ``fun``."""
    res = res if isinstance(res, tuple | list) else [res]
    out = []
    for j, r in enumerate(res):
        rows, cols = fun.size_out(j)
        # rows × (cols·K), sample k in block k
        a = r if isinstance(r, np.ndarray) else np.asarray(ca.DM(r).full(), dtype=float)
        out.append(a.reshape(rows, K, cols).transpose(1, 0, 2))
    return out


# ----------------------------------------------------------- per-structure Functions (fast path)
@dataclass
class FastFunctions:
    """The verify Functions of one structure, with p an input (:func:`fast_functions`).

    Attributes
    ----------
    functions : dict
        ``"V"``: ``(t, x, p) -> (V1, V1_dot, V2, V2_dot, chi)`` (read as ``"V1"`` and
        ``"V2"``, :data:`VIEWS`); ``"outputs"``: ``(t, x, p) -> outputs``. SX (or MX when
        the loop cannot be expanded) until compiled, then the compiled library's Functions.
    runs : set of str
        Digests of the distinct runs (p, x(0), output times) verified with these Functions
        in this process, counted until they are compiled.
    compiled : bool
        Whether :attr:`functions` come from a compiled library.
    maps : dict
        ``(name, K)`` -> the K-fold serial map with p not mapped.
    key : str
        The structure key the Functions were built for.
    """

    functions: dict[str, ca.Function]
    runs: set[str] = field(default_factory=set)
    compiled: bool = False
    maps: dict[tuple[str, int], ca.Function] = field(default_factory=dict)
    key: str = ""


_FAST = MEMO.namespace("verify-functions", CACHE_SIZE)  # core/memo.py


def clear_cache() -> None:
    """Forget every structure's verify Functions and closed loop kept in this process."""
    from symbolic.closed_loop import forget_parametric

    _FAST.clear()
    forget_parametric()
    _LAST_EVALUATION.clear()


def _remember(cache: Any, key: str, value: Any) -> Any:
    """Put ``value`` in ``cache`` (a :mod:`core.memo` namespace) under ``key``."""
    cache[key] = value
    return value


#: what each name of :func:`evaluate_p` reads of the one Function ``"V"``: its outputs
#: (V1, V̇1, V2, V̇2, χ) in that order
VIEWS = {"V1": ("V", slice(0, 2)), "V2": ("V", slice(2, 5))}


def _derivative_p(outs_f: ca.Function, ode_f: ca.Function) -> ca.Function:
    """``(t, x, p) -> (V1, V̇1, V2, V̇2, χ)`` from the (t, x, p) outputs and ode, SX when both
    are: one Function, so that the right-hand side both derivatives need is evaluated once
    and one map is built (the same numbers, bit for bit, as a Function per V:
    ``tests/test_verify_lyapunov.py``). Its common subexpressions are not eliminated: that
    costs more per structure (0.3 s at N = 15) than it saves on a run's evaluation (0.15 s)."""
    Sym = ca.SX if outs_f.is_a("SXFunction") and ode_f.is_a("SXFunction") else ca.MX
    t = Sym.sym("t")
    x, p = Sym.sym("x", outs_f.size_in(1)), Sym.sym("p", outs_f.size_in(2))
    outs = dict(zip(outs_f.name_out(), outs_f.call([t, x, p]), strict=True))
    missing = [nm for nm in ("V1", "V2", "chi") if nm not in outs]
    if missing:
        raise VerifyError(
            f"closed loop has no output {missing[0]!r} (outputs: {', '.join(outs)}); update verify"
        )
    xdot = ode_f.call([t, x, p])[0]
    res, names = [], []
    for name in ("V1", "V2"):
        V = ca.vec(outs[name])
        # the same exact derivative along the flow as lyapunov_derivative: ∂V/∂x · f + ∂V/∂t
        res += [V, ca.jtimes(V, x, xdot) + ca.jacobian(V, t)]
        names += [name, f"{name}_dot"]
    return ca.Function(
        "verify_V_dot", [t, x, p], [*res, outs["chi"]], ["t", "x", "p"], [*names, "chi"]
    )


def fast_functions(cl: Any, run: str = "") -> FastFunctions:
    """The per-structure verify Functions of ``cl`` (built on first use, then reused).

    Parameters
    ----------
    cl : ClosedLoop
        A closed loop with ``parametric`` (its structure key names the cache entry).
    run : str
        Identifies the run being verified (:func:`run_digest`); the several checks of one
        run count once.

    Returns
    -------
    FastFunctions
        From the :data:`COMPILE_FROM_USE`-th distinct run of the structure (the first with
        the graph as data) its Functions are compiled to C
        (:func:`generated.codegen.build_library`, content-hash cache).
    """
    par = cl.parametric
    entry = _FAST.get(par.structure_key)
    if entry is None:
        outs_f, ode_f = expanded(par.outputs), expanded(par.ode)
        funs = {"V": _derivative_p(outs_f, ode_f), "outputs": outs_f}
        entry = FastFunctions(funs, key=par.structure_key)
    _remember(_FAST, par.structure_key, entry)
    if not entry.compiled:
        entry.runs.add(run)
        if len(entry.runs) >= (1 if par.layout.dense else COMPILE_FROM_USE):
            _compile(entry)
    return entry


def _compile(entry: FastFunctions) -> None:
    """Replace ``entry``'s SX Functions by their compiled C (kept SX if gcc fails)."""
    from generated.codegen import build_library
    from generated.csource import renamed

    entry.compiled = True  # tried once per structure and process, whatever the outcome
    if not all(f.is_a("SXFunction") for f in entry.functions.values()):
        return  # MX that does not expand: C would not be faster than its virtual machine
    named = {k: renamed(f, f"verify_{k}") for k, f in entry.functions.items()}
    try:
        lib = build_library(list(named.values()))
    except BuildError as exc:
        print(f"verify: evaluating in CasADi, not compiled ({exc})", file=sys.stderr)
        return
    entry.functions = {k: lib.function(f.name()) for k, f in named.items()}
    entry.maps.clear()


def evaluate_p(
    entry: FastFunctions, name: str, t: np.ndarray, X: np.ndarray, p: np.ndarray
) -> list[np.ndarray]:
    """Evaluate ``entry.functions[name]`` at K samples with one parameter vector p.

    Parameters
    ----------
    entry : FastFunctions
        From :func:`fast_functions`.
    name : str
        ``"V1"`` (V1, V̇1), ``"V2"`` (V2, V̇2, χ), ``"outputs"``, or any other key of
        ``entry.functions`` (all its outputs).
    t : ndarray
        K sample times.
    X : ndarray
        (K, nx) states at those times.
    p : ndarray
        The run's parameter vector (``cl.p0``), the same at every sample.

    Returns
    -------
    list of ndarray
        One (K, rows, cols) array per output.
    """
    fname, part = VIEWS.get(name, (name, slice(None)))
    fun = entry.functions[fname]
    K = len(t)
    t = np.ascontiguousarray(t, dtype=float)
    X = np.ascontiguousarray(X, dtype=float)
    p = np.ascontiguousarray(p, dtype=float).ravel()
    head = (entry.key, entry.compiled, fun.class_name(), fname)  # SX machine or compiled C
    last = _LAST_EVALUATION.get("last")
    if last is None or last[0] != head or not all(map(_same_bits, last[1], (t, X, p))):
        fmap = entry.maps.get((fname, K))
        if fmap is None:  # p is not mapped: one copy serves the K samples
            shared = [False, False, True]  # map(n, reduce_in, reduce_out): built in ms
            fmap = entry.maps[(fname, K)] = fun.map(K, shared, [False] * fun.n_out())
        vals = _blocks(fun, _call_buffers(fmap, t, X, p), K)
        last = _LAST_EVALUATION["last"] = (head, (t.copy(), X.copy(), p.copy()), vals)
    return [a.copy(order="K") for a in last[2][part]]


#: the last evaluation with its Functions and inputs: one run's three Theorem 1 checks
#: evaluate the same V1 and V̇1 (inputs compared bit for bit, never by identity)
_LAST_EVALUATION = MEMO.namespace("verify-last-evaluation", 1)  # core/memo.py


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two float arrays have the same shape and the same bytes."""
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _call_buffers(fmap: ca.Function, t: np.ndarray, X: np.ndarray, p: np.ndarray) -> list:
    """Outputs of the K-fold map called on numpy memory (no DM conversion of the states).

    X (K, nx) in row-major order is the map's nx×K input in CasADi's column-major
    order, so every input is passed as it is; each output is returned as a DM-like dense
    array (rows × cols·K) built from the nonzeros the call writes.
    """
    if not all(fmap.sparsity_in(j).is_dense() for j in range(fmap.n_in())):
        return fmap.call([ca.DM(t.reshape(1, -1)), ca.DM(X.T), ca.DM(p)])
    buf, run = fmap.buffer()
    outs = [np.empty(fmap.nnz_out(j)) for j in range(fmap.n_out())]
    for j, a in enumerate((t, X, p)):
        buf.set_arg(j, memoryview(a))
    for j, a in enumerate(outs):
        buf.set_res(j, memoryview(a))
    run()
    res = []
    for j, nz in enumerate(outs):
        sp = fmap.sparsity_out(j)
        if sp.is_dense():
            dense = nz
        else:
            dense = np.zeros(sp.numel())  # structural zeros are 0.0, as DM.full() gives
            dense[np.asarray(sp.find(), dtype=np.intp)] = nz
        # column-major rows × cols·K, stored row-major as DM.full() returns it (the same
        # memory order downstream, so every later reduction adds in the same order)
        res.append(np.ascontiguousarray(dense.reshape(sp.size2(), sp.size1()).T))
    return res


def _fast(cl: Any, ode: ca.Function | None, t: np.ndarray, X: np.ndarray) -> FastFunctions | None:
    """The fast path's Functions for ``cl``, or None when the MX path must be taken."""
    if ode is not None or getattr(cl, "parametric", None) is None or cl.p0 is None:
        return None
    return fast_functions(cl, run_digest(cl.p0, t, X))


def run_digest(p: np.ndarray, t: np.ndarray, X: np.ndarray) -> str:
    """A digest of a run: its parameters, first state and output times (not the whole X).

    Parameters
    ----------
    p : ndarray
        Parameter vector.
    t : ndarray
        Output times.
    X : ndarray
        (K, nx) states.
    """
    h = hashlib.sha256(np.asarray(p, dtype=float).tobytes())
    h.update(np.asarray(t, dtype=float).tobytes())
    if len(X):
        h.update(np.asarray(X[0], dtype=float).tobytes())
    return h.hexdigest()


def closed_loop(sc: Scenario, gains: Any) -> Any:
    """The closed loop of ``sc``, its parametric Functions reused per structure in this process.

    Parameters
    ----------
    sc : Scenario
    gains : Gains

    Returns
    -------
    ClosedLoop
        :func:`symbolic.closed_loop.closed_loop_for`: the parametric loop this process
        built for the structure (also by ``generated.api.build``) bound to ``sc``'s
        numbers, or a new build for a new structure.
    """
    from symbolic.closed_loop import closed_loop_for

    return closed_loop_for(sc, gains)


def outputs_at(cl: Any, t: np.ndarray, X: np.ndarray) -> dict[str, np.ndarray]:
    """All outputs at K samples: {name: (K, rows, cols)}; per-agent outputs have row i = agent i.

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    t : ndarray
        K sample times.
    X : ndarray
        (K, nx) states at those times.
    """
    fast = _fast(cl, None, t, X)
    if fast is None:
        vals = evaluate(cl.outputs, t, X)
    else:
        vals = evaluate_p(fast, "outputs", t, X, cl.p0)
    return dict(zip(cl.outputs.name_out(), vals, strict=True))


def agent_block(vals: dict[str, np.ndarray], name: str, agent: int) -> np.ndarray:
    """Agent ``agent``'s row of a per-agent output: (K, cols).

    Parameters
    ----------
    vals : dict
        Outputs as returned by :func:`outputs_at`.
    name : str
        Output name.
    agent : int
        0-based follower index.
    """
    if name not in vals:
        raise VerifyError(f"closed loop has no output {name!r}; update verify")
    return vals[name][:, agent, :]


def state_block(cl: Any, X: np.ndarray, key: Any) -> np.ndarray:
    """Columns of the state for layout key ``key``: (K, width).

    Parameters
    ----------
    cl : ClosedLoop
        The symbolic closed loop (its ``outputs`` Function and ``layout``).
    X : ndarray
        (K, nx) states.
    key : str or tuple
        Layout key: ``"eta0"`` or ``(name, agent)``.
    """
    if key not in cl.layout.slices:
        raise VerifyError(f"closed loop layout has no state {key!r}")
    return X[:, cl.layout.slices[key]]


# --------------------------------------------------------------------------- Theorem 1
def check_theorem1(
    cl: Any,
    t: np.ndarray,
    X: np.ndarray,
    rate: float,
    *,
    claim: str = "dV1/dt <= -delta V1",
    config: VerifyConfig | None = None,
    offset: float = 0.0,
    ode: ca.Function | None = None,
) -> InequalityCheck:
    """V̇1 ≤ −δ̃ V1 + c (eq. (27) when c = 0) at every sample, with V̇1 exact.

    With the φ floor the proof gives c = c_φ (:func:`verify.bounds.theorem1_floor`,
    derivation in docs/verification.md).

    Parameters
    ----------
    cl : ClosedLoop
    t : ndarray
        (K,) times.
    X : ndarray
        (K, nx) states.
    rate : float
        δ̃ to check.
    claim : str
        Label.
    config : VerifyConfig, optional
    offset : float
        c ≥ 0 added to the right side (the φ floor's constant c_φ).
    ode : casadi.Function, optional
        A different vector field (tests: a deliberately wrong observer).

    Returns
    -------
    InequalityCheck
    """
    cfg = config or VerifyConfig()
    fast = _fast(cl, ode, t, X)
    if fast is None:
        V, Vd = evaluate(lyapunov_derivative(cl, "V1", ode), t, X)
    else:
        V, Vd = evaluate_p(fast, "V1", t, X, cl.p0)
    V, Vd = V[:, 0, 0], Vd[:, 0, 0]
    rhs = -rate * V + offset  # eq. (27); + c_φ with the φ floor
    scale = np.abs(Vd) + rate * np.abs(V) + abs(offset) + 1e-300
    return _make(claim, None, np.asarray(t, float), Vd, rhs, scale, cfg.rtol)


# Theorem 2's check lives in verify/theorem2_check.py (it uses the functions above); its
# names are still reached here, resolved on first use (PEP 562)
_THEOREM2 = ("check_theorem2", "health_at", "sgn_eps", "theorem2_guaranteed", "theorem2_rhs")


def __getattr__(name: str) -> Any:
    if name in _THEOREM2:
        from verify import theorem2_check

        return getattr(theorem2_check, name)
    raise AttributeError(f"module 'verify.lyapunov' has no attribute {name!r}")
