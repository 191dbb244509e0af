"""Method ``idas``: the semi-explicit DAE form (accelerations as algebraic states) with IDAS.

z is out of IDAS's error and Newton tests and solved from alg(t, x, z) = 0 by Newton in z
at t = 0 and at breakpoints (docs/simulation.md, "IDAS and the algebraic states").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from generated.solvers import register
from generated.solvers.engine import CasadiSolver, SundialsStepper

if TYPE_CHECKING:
    from generated.values import IntegratorSettings


def _z_newton_step(f: ca.Function, nz: int, linear_solver: str) -> ca.Function | None:
    """``(t, x, z) -> Δz``: one Newton step on alg(t, x, z) = 0 in z (None without ∂alg/∂z)."""
    t, x, z = ca.MX.sym("t"), ca.MX.sym("x", f.size1_in(1)), ca.MX.sym("z", nz)
    e = ca.MX(0, 1)
    try:
        alg = f(t, x, z, e, e)[1]
        return ca.Function(
            "z_newton", [t, x, z], [ca.solve(ca.jacobian(alg, z), alg, linear_solver)]
        )
    except RuntimeError:  # e.g. a library generated without jac_<name> (jvp builds)
        return None


class IdasStepper(SundialsStepper):
    """IDAS on the DAE form; z solved from alg = 0 at the start of every segment."""

    plugin = "idas"

    def plugin_options(self) -> dict[str, Any]:
        """``suppress_algebraic`` and, with algebraic states, z out of the Newton test."""
        opts: dict[str, Any] = {"suppress_algebraic": True}  # without it IDAS stalls early
        self._znewton: ca.Function | None = None
        if self.nz:
            # z out of the Newton test too (see IntegratorSettings.algebraic_atol)
            nx = int(self.f.size1_in(1))
            opts["abstolv"] = [float(self.s.atol)] * nx + [float(self.s.algebraic_atol)] * self.nz
            self._znewton = _z_newton_step(self.f, self.nz, self.s.linear_solver)
        return opts

    def _consistent_z(self, t0: float, x: np.ndarray, z: np.ndarray) -> np.ndarray | None:
        """z with alg(t0, x, z) = 0 (Newton in z, x fixed), or None if that fails.

        Replaces IDACalcIC, whose convergence test uses the same weights: with z out of
        it, IDACalcIC stops short of a consistent z (friction DAE of the tests).
        """
        if self._znewton is None:
            return None
        z = np.array(z, dtype=float).ravel()
        for _ in range(20):
            try:
                dz = np.array(self._znewton(t0, x, z), dtype=float).ravel()
            except RuntimeError:  # singular ∂alg/∂z
                return None
            if not np.all(np.isfinite(dz)):
                return None
            z = z - dz
            if np.max(np.abs(dz)) <= 1e-12 * (1.0 + np.max(np.abs(z))):
                return z
        return None

    def call_options(
        self, t0: float, x: np.ndarray, z: np.ndarray, new_segment: bool
    ) -> tuple[dict[str, Any], np.ndarray]:
        """At t0 and at breakpoints z from :meth:`_consistent_z`; carried over otherwise.

        Parameters
        ----------
        t0, x, z, new_segment
        """
        if not self.nz:
            return self.opts, z
        # at other chunk boundaries z is consistent already; IDACalcIC only as a fallback
        zc = self._consistent_z(t0, x, z) if new_segment else np.asarray(z, dtype=float)
        if zc is None:
            return {**self.opts, "calc_ic": True}, z
        xdot = np.array(self.f(t0, x, zc, [], [])[0], dtype=float).ravel()
        return {**self.opts, "calc_ic": False, "init_xdot": xdot.tolist()}, zc


class Idas(CasadiSolver):
    """IDAS (BDF) on the DAE form through CasADi; z solved from alg = 0 at restarts."""

    name = "idas"
    form = "dae"
    summary = "BDF on the DAE form (SUNDIALS IDAS) through CasADi"

    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """An :class:`IdasStepper`.

        Parameters
        ----------
        f, settings, nx, nz
        """
        return IdasStepper(f, settings, nz)


SOLVER = register(Idas())
