"""Derive M, C, G from a Lagrangian with sympy, check Properties 1–2, wrap in CasADi.

The derivation is a pure function of the model's definition (its module's source, this
module's source, the parameters, the sympy and CasADi versions); its results (the
CasADi Functions, ``M_bounds``, how Properties 1–2 were established) are kept in the
build cache as JSON (:func:`model_key`, docs/simulation.md), so a fresh process that
finds them needs neither sympy nor the property checks.
"""

from __future__ import annotations

import hashlib
import inspect
import json
from collections.abc import Mapping
from functools import partial
from importlib.metadata import version
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from core.errors import ScenarioError
from core.memo import MEMO
from core.models import cache
from core.models.base import REGISTRY, ELModel, ModelSpec

if TYPE_CHECKING:
    import sympy as sp

#: cache sub-folder and the format of its entries' bodies
CACHE_KIND = "models"
CACHE_FORMAT = 1


def euler_lagrange_matrices(T: sp.Expr, V: sp.Expr, p: list[sp.Symbol], q: list[sp.Symbol]):
    """M, C, G of eq. (2) from kinetic energy ``T`` and potential energy ``V``.

    M_kj = ∂²T/∂q_k∂q_j; C_kj = Σ_i c_ijk q_i with the Christoffel symbols of
    the first kind c_ijk = ½(∂M_kj/∂p_i + ∂M_ki/∂p_j − ∂M_ij/∂p_k), which is the
    choice that makes Ṁ − 2C skew-symmetric (Property 2); G_k = ∂V/∂p_k.

    Parameters
    ----------
    T : sympy.Expr
        Kinetic energy, quadratic in ``q``.
    V : sympy.Expr
        Potential energy, a function of ``p``.
    p, q : list of sympy.Symbol
        Generalised coordinates and velocities.
    """
    import sympy as sp

    n = len(p)
    M = sp.Matrix(n, n, lambda k, j: sp.simplify(sp.diff(T, q[k], q[j])))  # eq. (2): M
    C = sp.zeros(n, n)
    for k in range(n):
        for j in range(n):
            C[k, j] = sp.simplify(  # eq. (2): C from the Christoffel symbols
                sum(
                    sp.Rational(1, 2)
                    * (sp.diff(M[k, j], p[i]) + sp.diff(M[k, i], p[j]) - sp.diff(M[i, j], p[k]))
                    * q[i]
                    for i in range(n)
                )
            )
    G = sp.Matrix([sp.simplify(sp.diff(V, pk)) for pk in p])  # eq. (2): G
    return M, C, G


def check_properties(
    M: sp.Matrix, C: sp.Matrix, p: list[sp.Symbol], q: list[sp.Symbol], name: str
) -> dict[str, str]:
    """Property 1 (M symmetric, positive definite) and Property 2 (Ṁ − 2C skew), symbolically.

    Positive definiteness uses Sylvester's criterion on the simplified leading
    minors: a constant minor is decided exactly; a minor of one angle is
    minimised exactly over one period with :func:`sympy.minimum`; anything
    else falls back to a dense grid (reported as ``"sampled"``). Property 2
    must simplify to the zero matrix exactly.

    Parameters
    ----------
    M, C : sympy.Matrix
        Inertia and Coriolis matrices.
    p, q : list of sympy.Symbol
        Generalised coordinates and velocities.
    name : str
        Model name, for the error message.

    Returns
    -------
    dict
        ``{"property1": "exact" | "sampled (...)", "property2": "exact"}``.

    Raises
    ------
    ScenarioError
        Naming the model and the failed property.
    """
    import sympy as sp

    if sp.simplify(M - M.T) != sp.zeros(*M.shape):
        raise ScenarioError(
            "model", name, "Property 1 fails: M is not symmetric", "a symmetric inertia matrix"
        )
    n = M.shape[0]
    how1 = "exact"
    for k in range(1, n + 1):
        minor = sp.simplify(M[:k, :k].det())
        low, exact = _minimum(minor, p)
        if not exact:
            how1 = f"sampled (leading minor {k} depends on several coordinates)"
        if not low > 0:
            raise ScenarioError(
                "model",
                name,
                f"Property 1 fails: leading minor {k} of M reaches {float(low):.6g}",
                "M positive definite (check the mass and inertia parameters)",
            )
    # Property 2: Ṁ − 2C skew-symmetric, i.e. S + Sᵀ = 0 exactly
    Mdot = sp.zeros(n, n)
    for i in range(n):
        for j in range(n):
            Mdot[i, j] = sum(sp.diff(M[i, j], p[k]) * q[k] for k in range(n))
    S = sp.simplify(Mdot - 2 * C)
    if not sp.simplify(S + S.T).is_zero_matrix:
        raise ScenarioError(
            "model",
            name,
            "Property 2 fails: Mdot - 2C is not skew-symmetric",
            "C from Christoffel symbols",
        )
    return {"property1": how1, "property2": "exact"}


def _minimum(expr: sp.Expr, p: list[sp.Symbol]) -> tuple[float, bool]:
    """Infimum of ``expr`` over the coordinates and whether it is exact."""
    import sympy as sp

    deps = [s for s in p if s in expr.free_symbols]
    if not deps:
        return float(expr), True
    if len(deps) == 1 and _periodic_in(expr, deps):
        try:
            low = sp.minimum(expr, deps[0], sp.Interval(-sp.pi, sp.pi))
            if low.is_number and low.is_finite:
                return float(low), True
        except (NotImplementedError, ValueError, TypeError):  # sympy gave up: sample instead
            pass
    f = sp.lambdify(deps, expr, "numpy")
    grid = np.linspace(-np.pi, np.pi, 721 if len(deps) == 1 else 61)
    pts = np.array(np.meshgrid(*[grid] * len(deps))).reshape(len(deps), -1)
    return float(np.min(np.broadcast_to(f(*pts), pts.shape[1:]))), False


def _periodic_in(expr: sp.Expr, syms: list[sp.Symbol]) -> bool:
    """True when every symbol in ``syms`` enters ``expr`` only through sin/cos (2π-periodic)."""
    import sympy as sp

    probe = expr.replace(
        lambda e: isinstance(e, sp.sin | sp.cos) and e.free_symbols & set(syms),
        lambda e: sp.Dummy(),
    )
    return not (probe.free_symbols & set(syms))


def _to_casadi(
    exprs: sp.Matrix, syms: list[list[sp.Symbol]], names: list[str], fname: str
) -> ca.Function:
    import sympy as sp

    cs_syms = [ca.SX.sym(nm, len(s)) for nm, s in zip(names, syms, strict=True)]
    flat = [s for group in syms for s in group]
    flat_cs = [cs_syms[g][k] for g, group in enumerate(syms) for k in range(len(group))]
    f = sp.lambdify(
        flat,
        exprs,
        modules=[
            {
                "sin": ca.sin,
                "cos": ca.cos,
                "tan": ca.tan,
                "exp": ca.exp,
                "sqrt": ca.sqrt,
                "log": ca.log,
                "tanh": ca.tanh,
                "atan2": ca.atan2,
                "Abs": ca.fabs,
                "ImmutableDenseMatrix": _mat,
                "MutableDenseMatrix": _mat,
            },
            "math",
        ],
    )
    out = f(*flat_cs)
    return ca.Function(fname, cs_syms, [ca.SX(out)], names, [fname])


def _mat(rows):  # sympy Matrix -> CasADi SX via nested lists
    return ca.vertcat(
        *[ca.horzcat(*[ca.SX(x) if not isinstance(x, ca.SX) else x for x in r]) for r in rows]
    )


def _mass_bounds(M: sp.Matrix, p: list[sp.Symbol], name: str) -> tuple[float, float]:
    """inf λ_min(M) and sup λ_max(M) over the configuration space (Theorem 2 needs both).

    Exact when M is constant. When M depends on angles only (through sin/cos),
    a grid over one period is refined by a bounded local search from the best
    grid point. Any other dependence has no finite configuration box to search,
    so it is refused.
    """
    import sympy as sp
    from scipy.optimize import minimize

    deps = [s for s in p if s in M.free_symbols]
    if not deps:
        ev = np.linalg.eigvalsh(np.array(M.evalf(), dtype=float))
        return float(ev[0]), float(ev[-1])
    if not all(_periodic_in(e, deps) for e in M):
        raise ScenarioError(
            "model",
            name,
            "M depends on a coordinate other than through sin/cos; M_bounds cannot be searched",
            "an inertia matrix periodic in the coordinates it depends on",
        )
    f = sp.lambdify(deps, M, "numpy")

    def eig(x: np.ndarray) -> np.ndarray:
        return np.linalg.eigvalsh(np.array(f(*x), dtype=float))

    grid = np.linspace(-np.pi, np.pi, 721 if len(deps) == 1 else 121 if len(deps) == 2 else 25)
    pts = np.array(np.meshgrid(*[grid] * len(deps))).reshape(len(deps), -1).T
    evs = np.array([eig(x) for x in pts])
    box = [(-np.pi, np.pi)] * len(deps)
    x_lo = minimize(lambda x: eig(x)[0], pts[np.argmin(evs[:, 0])], bounds=box)
    x_hi = minimize(lambda x: -eig(x)[-1], pts[np.argmax(evs[:, -1])], bounds=box)
    lo = min(float(evs[:, 0].min()), float(x_lo.fun))
    hi = max(float(evs[:, -1].max()), float(-x_hi.fun))
    return lo, hi


def model_key(name: str, items: tuple[tuple[str, float], ...]) -> str | None:
    """SHA-256 of what defines the derived model (the derivation cache's key), or None.

    The model module's source and the Lagrangian's qualified name, this module's source
    (the derivation and the checks), the parameters (exact: JSON keeps every float's
    digits) and the sympy and CasADi versions (their simplification and serialization).
    None (not cached) when the Lagrangian is not a plain function of a source file or
    captures variables: its source would not define it.

    Parameters
    ----------
    name : str
        Registered model name.
    items : tuple of (str, float)
        Every parameter, sorted by name.
    """
    spec: ModelSpec = REGISTRY[name]
    lag = spec.lagrangian
    if not inspect.isfunction(lag) or lag.__closure__ or lag.__defaults__ or lag.__kwdefaults__:
        return None
    try:
        source = inspect.getsourcefile(lag)
    except TypeError:
        return None
    if source is None or not Path(source).is_file():
        return None
    text = json.dumps(
        {
            "format": CACHE_FORMAT,
            "name": name,
            "n": spec.n,
            "params": [[k, float(v)] for k, v in items],
            "lagrangian": lag.__qualname__,
            "model_source": _file_sha256(source),
            "derive_source": _file_sha256(__file__),
            "sympy": version("sympy"),
            "casadi": ca.__version__,
        },
        sort_keys=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()


def _file_sha256(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@MEMO.memoize("model-derivations", 64)
def _symbolic(name: str, items: tuple[tuple[str, float], ...]) -> tuple[Any, ...]:
    """(M, C, G, p, q, D) in sympy, eq. (2), derived from the model's Lagrangian; D is the
    dissipative force ∂R/∂q of a Rayleigh function R the Lagrangian may return fifth (None
    without)."""
    import sympy as sp

    out = REGISTRY[name].lagrangian(dict(items))
    T, V, p, q = out[:4]
    M, C, G = euler_lagrange_matrices(T, V, p, q)
    D = sp.Matrix([sp.simplify(sp.diff(out[4], qk)) for qk in q]) if len(out) > 4 else None
    return M, C, G, p, q, D


def check_dissipation(D: sp.Matrix, p: list[sp.Symbol], q: list[sp.Symbol], name: str) -> str:
    """The force D(p, q) = ∂R/∂q dissipates: its Jacobian ∂D/∂q = ∂²R/∂q² is positive
    semidefinite, exactly when constant, else on a grid of p and q (``"sampled"``).

    Parameters
    ----------
    D : sympy.Matrix
        The dissipative force.
    p, q : list of sympy.Symbol
        Generalised coordinates and velocities.
    name : str
        Model name, for the error message.

    Raises
    ------
    ScenarioError
        Naming the model and the smallest eigenvalue found.
    """
    import sympy as sp

    H = sp.simplify(D.jacobian(q))
    if not (H - H.T).is_zero_matrix:
        raise ScenarioError(
            "model", name, "dissipation: dD/dq is not symmetric", "D = dR/dq of a Rayleigh R(q)"
        )
    syms = [s for s in (*p, *q) if s in H.free_symbols]
    how = "exact" if not syms else "sampled (dD/dq depends on the state)"
    f = sp.lambdify(syms, H, "numpy")
    rng = np.random.default_rng(0)
    pts = rng.uniform(-np.pi, np.pi, size=(200 if syms else 1, len(syms)))
    low = min(float(np.linalg.eigvalsh(np.array(f(*pt), dtype=float)).min()) for pt in pts)
    if low < -1e-12:
        raise ScenarioError(
            "model",
            name,
            f"dissipation: dD/dq has eigenvalue {low:.6g} < 0",
            "a Rayleigh function R with a positive semidefinite Hessian in q",
        )
    return how


def _derive(name: str, items: tuple[tuple[str, float], ...]) -> dict[str, Any]:
    """The derivation's results as a JSON body: Functions serialized by CasADi, numbers."""
    M, C, G, p, q, D = _symbolic(name, items)
    checks = check_properties(M, C, p, q, name)
    funcs = {
        "M": _to_casadi(M, [p], ["p"], "M"),
        "C": _to_casadi(C, [p, q], ["p", "q"], "C"),
        "G": _to_casadi(G, [p], ["p"], "G"),
    }
    if D is not None:
        checks["dissipation"] = check_dissipation(D, p, q, name)
        funcs["D"] = _to_casadi(D, [p, q], ["p", "q"], "D")
    return {
        "name": name,
        "params": [[k, v] for k, v in items],
        "checks": dict(checks),
        "M_bounds": list(_mass_bounds(M, p, name)),
        "functions": {k: f.serialize() for k, f in funcs.items()},
    }


#: each Function's inputs as (name, rows, columns) for n coordinates, and its output shape
_SIGNATURES = {
    "M": (lambda n: [("p", n, 1)], lambda n: (n, n)),
    "C": (lambda n: [("p", n, 1), ("q", n, 1)], lambda n: (n, n)),
    "G": (lambda n: [("p", n, 1)], lambda n: (n, 1)),
    "D": (lambda n: [("p", n, 1), ("q", n, 1)], lambda n: (n, 1)),  # only with dissipation
}


def _model_from(
    body: dict[str, Any], name: str, items: tuple[tuple[str, float], ...]
) -> ELModel | None:
    """The ELModel a cache body describes, or None when any part is not what it must be."""
    spec: ModelSpec = REGISTRY[name]
    checks, bounds, fs = body.get("checks"), cache.finite_pair(body.get("M_bounds")), {}
    if body.get("name") != name or body.get("params") != [[k, v] for k, v in items]:
        return None
    if not isinstance(checks, dict) or not {"property1", "property2"} <= set(checks):
        return None
    if not all(isinstance(v, str) for v in checks.values()) or bounds is None:
        return None
    stored = body.get("functions")
    want = {"M", "C", "G"} | ({"D"} if "dissipation" in checks else set())
    if (
        not isinstance(stored, dict)
        or set(stored) != want
        or set(checks) - {*want, "property1", "property2", "dissipation"}
    ):
        return None
    for k, (ins, out) in _SIGNATURES.items():
        if k not in want:
            continue
        if not isinstance(stored[k], str):
            return None
        try:  # CasADi's own format (no eval); the body's checksum already matched
            f = ca.Function.deserialize(stored[k])
        except Exception:  # noqa: BLE001 - any failure to read means: recompute
            return None
        got = [(f.name_in(i), f.size1_in(i), f.size2_in(i)) for i in range(f.n_in())]
        if f.name() != k or got != ins(spec.n) or f.n_out() != 1 or f.size_out(0) != out(spec.n):
            return None
        fs[k] = f
    return _model(name, items, fs, bounds, checks)


def _model(
    name: str,
    items: tuple[tuple[str, float], ...],
    fs: dict[str, ca.Function],
    bounds: tuple[float, float],
    checks: dict[str, str],
) -> ELModel:
    return ELModel(
        name=name,
        n=REGISTRY[name].n,
        params=dict(items),
        M=fs["M"],
        C=fs["C"],
        G=fs["G"],
        D=fs.get("D"),
        M_bounds=bounds,
        checks=checks,
        symbolic=partial(_symbolic, name, items),
    )


@MEMO.memoize("model-builds", 64)
def _build_cached(name: str, items: tuple[tuple[str, float], ...]) -> ELModel:
    key = model_key(name, items)
    body = cache.read_entry(CACHE_KIND, key) if key is not None else None
    model = _model_from(body, name, items) if body is not None else None
    if model is not None:
        return model
    body = _derive(name, items)
    try:
        if key is not None:
            cache.write_entry(CACHE_KIND, key, body)
    except OSError:  # an unwritable cache costs the next process the derivation, no more
        pass
    # the Functions as read back: a fresh derivation and a cache hit give the same graphs
    model = _model_from(body, name, items)
    if model is None:
        raise RuntimeError(f"model {name}: its CasADi Functions do not read back")
    return model


def build_model(name: str, params: Mapping[str, float] | None = None) -> ELModel:
    """Derive the model ``name`` with ``params`` (defaults filled in), cached.

    Parameters
    ----------
    name : str
        A registered model name (``REGISTRY``).
    params : mapping of str to float, optional
        Parameters overriding the model's defaults.

    Raises
    ------
    ScenarioError
        Unknown model or parameter, or a failed Property 1/2.
    """
    if name not in REGISTRY:
        raise ScenarioError("model", name, "unknown model", "one of " + ", ".join(sorted(REGISTRY)))
    spec = REGISTRY[name]
    full = dict(spec.defaults)
    for k, v in (params or {}).items():
        if k not in full:
            raise ScenarioError(
                "model", f"{name}.{k}", "unknown parameter", "one of " + ", ".join(sorted(full))
            )
        full[k] = float(v)
    return _build_cached(name, tuple(sorted(full.items())))
