"""Method ``fixed``: the linearly implicit ROS2 method with a fixed step (the exact sign's method).

ROS2 (Verwer, Spee, Blom, Hundsdorfer, SIAM J. Sci. Comput. 20, 1999), L-stable, on the
autonomised system with the generated sparse Jacobian J, γ = 1 + 1/√2:

    (I − γhJ) k1 = f(t_n, x_n) + γh ∂f/∂t
    (I − γhJ) k2 = f(t_n + h, x_n + h k1) − 2 k1 − γh ∂f/∂t
    x_{n+1} = x_n + (3/2) h k1 + (1/2) h k2.

Linearly implicit (no Newton iteration to fail on the exact sign) and order 2 for any
Jacobian (a W-method). Why it and its safeguard: docs/simulation.md.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from generated.solvers import register
from generated.solvers.engine import CasadiSolver, failure_reason
from generated.values import ChunkFailure, Status

if TYPE_CHECKING:
    from generated.values import IntegratorSettings

GAMMA_ROS2 = 1.0 + 1.0 / math.sqrt(2.0)


class Ros2Stepper:
    """ROS2 over an ODE's integrator form whose library has ``jac_<name>``.

    Parameters
    ----------
    f : casadi.Function
    s : IntegratorSettings
    nx : int
    """

    def __init__(self, f: ca.Function, s: IntegratorSettings, nx: int) -> None:
        self.s = s
        x = ca.MX.sym("x", nx)
        t = ca.MX.sym("t")
        h = ca.MX.sym("h")
        e = ca.MX(0, 1)

        def rhs(tt: ca.MX, xx: ca.MX) -> ca.MX:
            return f(tt, xx, e, e, e)[0]

        t2 = ca.MX.sym("t2")  # time of stage 2: t + h, or its left limit at a segment end
        k0 = rhs(t, x)
        J = ca.jacobian(k0, x)  # uses jac_<name> from the library: sparse
        ft = ca.jacobian(k0, t)  # ∂f/∂t: ROS2 applied to the autonomised system (t' = 1)
        W = ca.MX.eye(nx) - GAMMA_ROS2 * h * J
        k1 = ca.solve(W, k0 + GAMMA_ROS2 * h * ft, s.linear_solver)
        k2 = ca.solve(W, rhs(t2, x + h * k1) - 2 * k1 - GAMMA_ROS2 * h * ft, s.linear_solver)
        xn = x + 1.5 * h * k1 + 0.5 * h * k2
        # embedded first-order solution x + h k1: scaled local error estimate (max norm)
        est = ca.fabs(0.5 * h * (k1 + k2)) / (s.fixed_atol + s.fixed_rtol * ca.fabs(x))
        emax = ca.MX.sym("emax")
        self.step = ca.Function("ros2_step", [x, emax, t, h, t2], [xn, ca.fmax(emax, ca.mmax(est))])
        self._runs: dict[int, ca.Function] = {}

    def _run(self, K: int) -> ca.Function:
        f = self._runs.get(K)
        if f is None:  # K steps in one call; (x, emax) accumulated
            f = self._runs[K] = self.step.mapaccum(f"ros2_{K}", K, 2)
        return f

    def _advance(self, t0: float, t1: float, x: np.ndarray, K: int, depth: int, acc: dict):
        """x(t1) in K equal steps; each half again in K steps where the error test fails."""
        h = (t1 - t0) / K
        tv = t0 + h * np.arange(K)
        t2 = tv + h
        # the last stage-2 evaluation takes the left limit at t1: a jump at t1 (a
        # breakpoint) belongs to the next segment, as with the variable-step restarts
        t2[-1] = np.nextafter(t1, t0)
        acc["steps"] += K
        acc["rhs_evals"] += 2 * K
        acc["jac_evals"] += K
        acc["lin_setups"] += K
        acc["integrator_calls"] += 1
        try:
            X, E = self._run(K)(x, 0.0, tv.reshape(1, -1), np.full((1, K), h), t2.reshape(1, -1))
            xn = np.array(X[:, -1], dtype=float).ravel()
            err = float(E[-1])
        except RuntimeError:  # NaN met inside the interval (e.g. in the linear solve)
            xn, err = np.full_like(x, np.nan), math.inf  # refine, as for a failed error test
        if np.all(np.isfinite(xn)) and err <= 1.0:
            return xn
        if depth >= self.s.fixed_max_halvings:
            raise ChunkFailure(
                f"error test still fails with steps {2**depth} times smaller "
                f"(estimate {err:.3g}; raise fixed_rtol/fixed_atol or lower fixed_step)",
                Status.ERROR_TEST,
                t1,
            )
        # the same number of steps on each half: the step is halved where needed only
        acc["refined_intervals"] += 1
        tm = 0.5 * (t0 + t1)
        xm = self._advance(t0, tm, x, K, depth + 1, acc)
        return self._advance(tm, t1, xm, K, depth + 1, acc)

    def __call__(
        self,
        t0: float,
        x: np.ndarray,
        z: np.ndarray,
        times: list[float],
        acc: dict,
        new_segment: bool = True,
    ) -> tuple[np.ndarray, np.ndarray]:
        """States at ``times`` (no algebraic states); raises :class:`ChunkFailure`."""
        out = []
        tp, xp = t0, x
        for tt in times:
            try:
                K = max(1, math.ceil((tt - tp) / self.s.fixed_step - 1e-9))
                xp = self._advance(tp, tt, xp, K, 0, acc)
            except RuntimeError as exc:  # singular iteration matrix, NaN in the factorisation
                raise ChunkFailure(*failure_reason(exc), tt) from None
            if not np.all(np.isfinite(xp)):
                raise ChunkFailure(
                    "state is not finite (NaN or Inf): unstable step", Status.NOT_FINITE, tt
                )
            out.append(xp)
            tp = tt
        return np.array(out), np.zeros((len(times), 0))


class Fixed(CasadiSolver):
    """ROS2 (:class:`Ros2Stepper`) with the generated sparse Jacobian."""

    name = "fixed"
    form = "ode"
    summary = "ROS2, fixed step with a loose safeguard"
    fixed_step = True

    def stepper(self, f: ca.Function, settings: IntegratorSettings, nx: int, nz: int) -> Any:
        """A :class:`Ros2Stepper`.

        Parameters
        ----------
        f, settings, nx, nz
        """
        return Ros2Stepper(f, settings, nx)

    def settings_used(self, settings: IntegratorSettings) -> dict[str, Any]:
        """``fixed_step``, ``fixed_rtol``, ``fixed_atol``.

        Parameters
        ----------
        settings : IntegratorSettings
        """
        return {k: getattr(settings, k) for k in ("fixed_step", "fixed_rtol", "fixed_atol")}


SOLVER = register(Fixed())
