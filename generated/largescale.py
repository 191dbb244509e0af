"""Large-N plan: which derivatives to generate and how CVODES/IDAS solve their Newton systems.

CasADi's Jacobian of the mapped closed loop is generated unrolled per agent, so its C
grows with N until gcc no longer finishes; the MX-mapped right-hand side and its
``fwd1_<name>`` stay small. :func:`choose_plan` picks a :class:`JacobianPlan`: ``sparse``
(direct Newton, the default), ``jvp`` (matrix-free GMRES, no preconditioner: the large-N
plan of ``auto``) or ``gmres`` (GMRES preconditioned with ``jac_<name>``, never chosen by
``auto``); docs/simulation.md and docs/performance.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import casadi as ca

from core.errors import BuildError
from generated.values import JACOBIAN_CHOICES, CodegenSettings, IntegratorSettings

#: above this many agents ``auto`` switches to the matrix-free plan: a judgement call
#: between N = 5, where the direct plan is faster, and N = 50, where it does not compile
#: in reasonable time (docs/performance.md)
DIRECT_MAX_AGENTS = 20
#: Krylov subspace size: the closed loop's stiff modes (φ floor, tanh layer, gains
#: λ_ir k1_ir) need more than CVODES's default of 5
DEFAULT_MAX_KRYLOV = 20


@dataclass(frozen=True)
class JacobianPlan:
    """How the Newton systems of the implicit integrators are solved."""

    jacobian: str  # CodegenSettings.jacobian: "sparse", "jvp" or "gmres"
    expand: bool | None  # CodegenSettings.expand (False for jvp); None keeps the caller's
    linear_solver: str = "csparse"  # direct sparse solver of sparse
    extra_options: tuple[tuple[str, Any], ...] = ()  # SUNDIALS options beyond the scheme
    reason: str = ""  # why this plan (for reports)

    @property
    def strategy(self) -> str:
        """The Newton scheme: ``"direct"`` (``sparse``) or ``"gmres"`` (``jvp``, ``gmres``)."""
        return "direct" if self.jacobian == "sparse" else "gmres"

    @property
    def derivatives(self) -> tuple[str, ...]:
        """The derivative companions generated: ``jac`` and/or ``fwd1``."""
        return {"sparse": ("jac",), "jvp": ("fwd1",), "gmres": ("jac", "fwd1")}[self.jacobian]

    @property
    def integrator_options(self) -> dict[str, Any]:
        """The SUNDIALS options of the plan (Newton scheme, linear solver, extras)."""
        opts: dict[str, Any] = {"newton_scheme": self.strategy}
        if self.strategy == "direct":
            opts["linear_solver"] = self.linear_solver
        opts.update(dict(self.extra_options))
        return opts

    def codegen_settings(self, base: CodegenSettings | None = None) -> CodegenSettings:
        """``base`` (default ``CodegenSettings()``) with the plan's Jacobian strategy.

        Parameters
        ----------
        base : CodegenSettings, optional
        """
        base = base or CodegenSettings()
        expand = base.expand if self.expand is None else self.expand
        return dataclasses.replace(
            base, jacobian=self.jacobian, linear_solver=self.linear_solver, expand=expand
        )

    def integrator_settings(self, base: IntegratorSettings | None = None) -> IntegratorSettings:
        """``base`` (default ``IntegratorSettings()``) with the plan's linear algebra.

        Parameters
        ----------
        base : IntegratorSettings, optional
            The plan's extra options are merged after the base's own (the plan wins).
        """
        base = base or IntegratorSettings()
        extra = {**dict(base.extra_options), **dict(self.extra_options)}
        return dataclasses.replace(
            base,
            newton_scheme=self.strategy,
            linear_solver=self.linear_solver,
            extra_options=tuple(extra.items()),
        )


def choose_plan(
    N: int,
    jacobian: str = "auto",
    *,
    linear_solver: str = "csparse",
    max_krylov: int = DEFAULT_MAX_KRYLOV,
    direct_max_agents: int = DIRECT_MAX_AGENTS,
) -> JacobianPlan:
    """The Jacobian / linear-solver plan for N followers.

    Parameters
    ----------
    N : int
    jacobian : {"auto", "sparse", "jvp", "gmres"}
        ``auto``: ``sparse`` for ``N <= direct_max_agents``, else ``jvp``.
    linear_solver : str
        Direct sparse solver (CasADi Linsol plugin) of the ``sparse`` plan.
    max_krylov : int
        GMRES subspace size of the ``jvp`` plan.
    direct_max_agents : int
    """
    if jacobian not in JACOBIAN_CHOICES:
        raise BuildError(
            f"jacobian: {jacobian!r} is not allowed (expected {', '.join(JACOBIAN_CHOICES)})"
        )
    if int(N) < 1:
        raise BuildError(f"N: {N} must be >= 1 (number of followers)")
    if int(max_krylov) < 1:
        raise BuildError(f"max_krylov: {max_krylov} must be >= 1")
    if not ca.has_linsol(linear_solver):
        raise BuildError(f"linear_solver: {linear_solver!r} is not a CasADi linear solver plugin")
    if jacobian == "auto":
        jacobian = "sparse" if N <= direct_max_agents else "jvp"
        why = f"auto: N = {N} {'<=' if jacobian == 'sparse' else '>'} {direct_max_agents}"
    else:
        why = "requested"
    expand: bool | None = None
    extra: tuple[tuple[str, Any], ...] = ()
    if jacobian == "jvp":
        expand = False  # keep the MX map: code size flat in N
        # a preconditioner would need the full Jacobian, which this plan never forms
        extra = (("use_preconditioner", False), ("max_krylov", int(max_krylov)))
    return JacobianPlan(jacobian, expand, linear_solver, extra, why)
