"""Derive M, C, G from a Lagrangian with sympy, check Properties 1–2, wrap in CasADi."""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import casadi as ca
import numpy as np
import sympy as sp

from symbolic.errors import ScenarioError
from symbolic.models.base import REGISTRY, ELModel, ModelSpec


def euler_lagrange_matrices(T: sp.Expr, V: sp.Expr, p: list[sp.Symbol], q: list[sp.Symbol]):
    """M, C, G of eq. (2) from kinetic energy ``T`` and potential energy ``V``.

    M_kj = ∂²T/∂q_k∂q_j; C_kj = Σ_i c_ijk q_i with the Christoffel symbols of
    the first kind c_ijk = ½(∂M_kj/∂p_i + ∂M_ki/∂p_j − ∂M_ij/∂p_k), which is the
    choice that makes Ṁ − 2C skew-symmetric (Property 2); G_k = ∂V/∂p_k.
    """
    n = len(p)
    M = sp.Matrix(n, n, lambda k, j: sp.simplify(sp.diff(T, q[k], q[j])))
    C = sp.zeros(n, n)
    for k in range(n):
        for j in range(n):
            C[k, j] = sp.simplify(
                sum(
                    sp.Rational(1, 2)
                    * (sp.diff(M[k, j], p[i]) + sp.diff(M[k, i], p[j]) - sp.diff(M[i, j], p[k]))
                    * q[i]
                    for i in range(n)
                )
            )
    G = sp.Matrix([sp.simplify(sp.diff(V, pk)) for pk in p])
    return M, C, G


def check_properties(
    M: sp.Matrix, C: sp.Matrix, p: list[sp.Symbol], q: list[sp.Symbol], name: str
) -> None:
    """Property 1 (M symmetric, positive definite) and Property 2 (Ṁ − 2C skew), symbolically.

    Positive definiteness is checked by Sylvester's criterion on the leading
    minors, simplified; a minor that sympy cannot decide is checked on a grid.
    """
    if sp.simplify(M - M.T) != sp.zeros(*M.shape):
        raise ScenarioError(
            "model", name, "Property 1 fails: M is not symmetric", "a symmetric inertia matrix"
        )
    n = M.shape[0]
    for k in range(1, n + 1):
        minor = sp.simplify(M[:k, :k].det())
        pos = sp.ask(sp.Q.positive(minor)) if minor.free_symbols else bool(minor > 0)
        if pos is False:
            raise ScenarioError(
                "model",
                name,
                f"Property 1 fails: leading minor {k} of M is not positive",
                "M positive definite",
            )
        if pos is None:
            f = sp.lambdify(p, minor, "numpy")
            rng = np.random.default_rng(0)
            samples = [float(f(*rng.uniform(-np.pi, np.pi, len(p)))) for _ in range(200)]
            if min(samples) <= 0:
                raise ScenarioError(
                    "model",
                    name,
                    f"Property 1 fails: leading minor {k} of M reaches {min(samples):.3g}",
                    "M positive definite",
                )
    Mdot = sp.zeros(n, n)
    for i in range(n):
        for j in range(n):
            Mdot[i, j] = sum(sp.diff(M[i, j], p[k]) * q[k] for k in range(n))
    S = sp.simplify(Mdot - 2 * C)
    if sp.simplify(S + S.T) != sp.zeros(n, n):
        raise ScenarioError(
            "model",
            name,
            "Property 2 fails: Mdot - 2C is not skew-symmetric",
            "C from Christoffel symbols",
        )


def _to_casadi(
    exprs: sp.Matrix, syms: list[list[sp.Symbol]], names: list[str], fname: str
) -> ca.Function:
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


def _mass_bounds(M: sp.Matrix, p: list[sp.Symbol]) -> tuple[float, float]:
    """inf λ_min(M) and sup λ_max(M) over joint angles, on a dense grid of each coordinate M depends on."""
    deps = [s for s in p if s in M.free_symbols]
    f = sp.lambdify(p, M, "numpy")
    if not deps:
        ev = np.linalg.eigvalsh(np.array(f(*([0.0] * len(p))), dtype=float))
        return float(ev[0]), float(ev[-1])
    grid = np.linspace(-np.pi, np.pi, 721 if len(deps) == 1 else 121)
    lo, hi = np.inf, -np.inf
    for pt in np.array(np.meshgrid(*[grid] * len(deps))).reshape(len(deps), -1).T:
        vals = dict(zip(deps, pt, strict=True))
        ev = np.linalg.eigvalsh(np.array(f(*[vals.get(s, 0.0) for s in p]), dtype=float))
        lo, hi = min(lo, ev[0]), max(hi, ev[-1])
    return float(lo), float(hi)


@lru_cache(maxsize=64)
def _build_cached(name: str, items: tuple[tuple[str, float], ...]) -> ELModel:
    spec: ModelSpec = REGISTRY[name]
    params = dict(items)
    T, V, p, q = spec.lagrangian(params)
    M, C, G = euler_lagrange_matrices(T, V, p, q)
    check_properties(M, C, p, q, name)
    Mf = _to_casadi(M, [p], ["p"], "M")
    Cf = _to_casadi(C, [p, q], ["p", "q"], "C")
    Gf = _to_casadi(G, [p], ["p"], "G")
    return ELModel(
        name=name, n=spec.n, params=params, M=Mf, C=Cf, G=Gf, M_bounds=_mass_bounds(M, p),
        sympy_M=M, sympy_C=C, sympy_G=G, sympy_p=p, sympy_q=q,
    )  # fmt: skip


def build_model(name: str, params: Mapping[str, float] | None = None) -> ELModel:
    """Derive the model ``name`` with ``params`` (defaults filled in), cached.

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
