"""Euler–Lagrange follower models, eq. (2): M(p) p̈ + C(p, ṗ) ṗ + G(p) = g u + f.

A model is declared by its Lagrangian (kinetic and potential energy, in sympy)
in one small file under ``core/models/`` that registers a
:class:`ModelSpec`. :func:`build_model` derives M, C (Christoffel symbols of the
first kind) and G with sympy, checks Property 1 and Property 2, and returns an
:class:`ELModel` carrying CasADi functions.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import casadi as ca

#: name -> spec; filled by the model modules on import of ``core.models``
REGISTRY: dict[str, ModelSpec] = {}


@dataclass(frozen=True)
class ModelSpec:
    """Declaration of one follower model.

    Attributes
    ----------
    name : str
        Registry key used by scenario files (``followers[i].model``).
    n : int
        Number of generalised coordinates.
    defaults : Mapping[str, float]
        Every parameter with its default; scenario files may override any of
        them and no other key.
    lagrangian : callable
        ``lagrangian(params: dict[str, sympy.Symbol | float]) -> (T, V, p, q)``:
        kinetic energy, potential energy, coordinate symbols and velocity
        symbols (sympy); ``(T, V, p, q, R)`` adds Rayleigh's dissipation function
        R(p, q) (e.g. ½ Σ c_k q_k² for viscous friction), whose ∂R/∂q enters eq. (2).
    description : str
        One line for the README and summaries.
    nonnegative : frozenset[str]
        Parameters that may be zero (e.g. gravity ``g0``); every other
        parameter must be strictly positive (checked when a scenario loads).
    """

    name: str
    n: int
    defaults: Mapping[str, float]
    lagrangian: Callable[[Mapping[str, Any]], tuple[Any, ...]]
    description: str = ""
    nonnegative: frozenset[str] = frozenset()


@dataclass(frozen=True)
class ELModel:
    """A derived Euler–Lagrange model with CasADi functions.

    Attributes
    ----------
    name, n, params :
        As in the spec, ``params`` with every value filled in.
    M : casadi.Function
        ``p -> M(p)`` (n×n), Property 1: symmetric positive definite.
    C : casadi.Function
        ``(p, q) -> C(p, q)`` (n×n), Christoffel form, Property 2 holds.
    G : casadi.Function
        ``p -> G(p)`` (n).
    D : casadi.Function or None
        ``(p, q) -> D(p, q)`` (n), the dissipative force ∂R/∂q of the model's Rayleigh
        function R (None: no dissipation); it enters eq. (2) beside G:
        M p̈ + C ṗ + G + D = g u + f.
    M_bounds : tuple[float, float]
        (inf λ_min(M), sup λ_max(M)) over the configuration space, as needed
        by Theorem 2's bounds (exact when M is constant; otherwise a dense grid
        over one period refined by a bounded local search).
    checks : Mapping[str, str]
        How Property 1 and Property 2 were established (``"exact"`` or
        ``"sampled"`` with the reason), for summaries and reports.
    symbolic : callable, optional
        ``() -> (M, C, G, p, q, D)``: the sympy expressions and symbols the Functions
        came from, derived on first use (a model read from the derivation cache
        never needs sympy unless asked); also as ``sympy_M`` ... ``sympy_q``.
    """

    name: str
    n: int
    params: Mapping[str, float]
    M: ca.Function
    C: ca.Function
    G: ca.Function
    M_bounds: tuple[float, float]
    D: ca.Function | None = None
    checks: Mapping[str, str] = field(default_factory=dict)
    symbolic: Callable[[], tuple[Any, ...]] | None = field(repr=False, default=None, compare=False)

    def _sym(self, i: int) -> Any:
        return self.symbolic()[i] if self.symbolic is not None else None

    @property
    def sympy_M(self) -> Any:
        """sympy M(p)."""
        return self._sym(0)

    @property
    def sympy_C(self) -> Any:
        """sympy C(p, q)."""
        return self._sym(1)

    @property
    def sympy_G(self) -> Any:
        """sympy G(p)."""
        return self._sym(2)

    @property
    def sympy_p(self) -> Any:
        """The coordinate symbols."""
        return self._sym(3)

    @property
    def sympy_q(self) -> Any:
        """The velocity symbols."""
        return self._sym(4)

    @property
    def sympy_D(self) -> Any:
        """sympy D(p, q) = ∂R/∂q (None without dissipation)."""
        return self._sym(5)

    def forces(self, p: Any, q: Any) -> Any:
        """G(p) + D(p, q): the forces besides inertia and Coriolis in eq. (2) (CasADi).

        Parameters
        ----------
        p, q : casadi.SX or MX
            Coordinates and velocities.
        """
        return self.G(p) if self.D is None else self.G(p) + self.D(p, q)


def register(spec: ModelSpec) -> ModelSpec:
    """Add ``spec`` to :data:`REGISTRY` (one call per model file).

    Parameters
    ----------
    spec : ModelSpec
        The model's name, Lagrangian and default parameters.
    """
    REGISTRY[spec.name] = spec
    return spec
