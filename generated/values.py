"""The values generated/'s modules pass each other: settings, run status, trajectories.

The package's import leaf: it imports nothing from ``generated`` (a contract in
``pyproject.toml``).
"""

from __future__ import annotations

import enum
import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from core import methods
from core.errors import BuildError, IntegrationError
from core.scenario import Integration
from core.settings import default_of


class Status(enum.Enum):
    """Why a run ended (``OK``: complete): callers test this, never the message."""

    OK = "complete"
    STEP_LIMIT = "too many steps before the next output time"
    ERROR_TEST = "error test failed repeatedly"
    CONV_FAIL = "Newton iteration failed repeatedly"
    ACCURACY = "tolerances too small for machine precision"
    RHS_FAIL = "right-hand side or residual not finite"
    LINEAR_FAIL = "linear solver failed"
    NOT_FINITE = "state is not finite"
    TOO_CLOSE = "output time too close to the current time"
    INIT_FAIL = "consistent initial conditions not found"
    TIME_LIMIT = "wall-clock time limit reached"
    FAILED = "solver failure"


_ERR = "error test failed repeatedly (step size too small)"
_CONV = "Newton iteration failed repeatedly (step size too small)"
_NO_IC = "consistent initial conditions not found"
#: SUNDIALS return-flag names (without CV_/IDA_) -> (status, readable reason)
_FLAGS: dict[str, tuple[Status, str]] = {
    "TOO_MUCH_WORK": (
        Status.STEP_LIMIT,
        "too many steps before the next output time (raise max_steps)",
    ),
    "TOO_MUCH_ACC": (Status.ACCURACY, "tolerances too small for machine precision"),
    "ERR_FAIL": (Status.ERROR_TEST, _ERR),
    "ERR_FAILURE": (Status.ERROR_TEST, _ERR),
    "CONV_FAIL": (Status.CONV_FAIL, _CONV),
    "CONV_FAILURE": (Status.CONV_FAIL, _CONV),
    "RHSFUNC_FAIL": (Status.RHS_FAIL, "right-hand side failed (NaN or Inf)"),
    "REPTD_RHSFUNC_ERR": (Status.RHS_FAIL, "solver failure"),
    "UNREC_RHSFUNC_ERR": (Status.RHS_FAIL, "solver failure"),
    "FIRST_RHSFUNC_ERR": (Status.RHS_FAIL, "solver failure"),
    "RES_FAIL": (Status.RHS_FAIL, "residual failed (NaN or Inf)"),
    "REP_RES_ERR": (Status.RHS_FAIL, "residual failed repeatedly (NaN or Inf)"),
    "FIRST_RES_FAIL": (Status.RHS_FAIL, "residual failed at the first call"),
    "LSETUP_FAIL": (Status.LINEAR_FAIL, "linear solver setup failed (singular iteration matrix)"),
    "LSOLVE_FAIL": (Status.LINEAR_FAIL, "linear solve failed"),
    "TOO_CLOSE": (Status.TOO_CLOSE, "solver failure"),
    "LINESEARCH_FAIL": (Status.INIT_FAIL, f"{_NO_IC} (line search)"),
    "NO_RECOVERY": (Status.INIT_FAIL, _NO_IC),
    "CONSTR_FAIL": (Status.FAILED, "constraint test failed"),
}


def flag_status(flag: str) -> Status:
    """The :class:`Status` of a SUNDIALS return flag (``CV_TOO_MUCH_WORK``, ``ERR_FAIL``).

    Parameters
    ----------
    flag : str
        With or without its ``CV_``/``IDA_`` prefix.
    """
    return _FLAGS.get(re.sub(r"^(?:CV|IDA)_", "", flag.strip()), (Status.FAILED,))[0]


def flag_reason(flag: str) -> str:
    """``"TOO_MUCH_WORK: too many steps ..."`` for a SUNDIALS return flag name.

    Parameters
    ----------
    flag : str
        With or without its ``CV_``/``IDA_`` prefix.
    """
    flag = re.sub(r"^(?:CV|IDA)_", "", flag)
    return f"{flag}: {_FLAGS.get(flag, (None, 'solver failure'))[1]}"


class ChunkFailure(Exception):
    """A stepper's failure to reach the end of its chunk (the engine replays and reports it).

    Parameters
    ----------
    reason : str
        One readable line (the trajectory's message).
    status : Status
    t_target : float
        The time it was working towards.
    """

    def __init__(self, reason: str, status: Status, t_target: float) -> None:
        super().__init__(reason)
        self.reason, self.status, self.t_target = reason, status, t_target


#: derivatives generated: ``jac_<name>`` (sparse), both (gmres) or ``fwd1_<name>`` (jvp)
JACOBIAN_STRATEGIES = ("sparse", "gmres", "jvp")

#: ``auto``: resolved from N by :func:`generated.largescale.choose_plan` before generating
JACOBIAN_CHOICES = ("auto", *JACOBIAN_STRATEGIES)


@dataclass(frozen=True)
class CodegenSettings:
    """Every option of code generation, compilation and the integrators' linear algebra
    (docs/simulation.md, "Code generation and the build cache")."""

    compiler: str = "gcc"
    #: -O0 compiles 3-4x faster on large files, but the right-hand side then runs slower
    optimization: str = "-O1"
    kernel_optimization: str = "-O3"  # the per-agent kernels: small sources, hot loops
    extra_cflags: tuple[str, ...] = ()  # after -shared -fPIC
    jacobian: str = "sparse"  # one of JACOBIAN_CHOICES
    linear_solver: str = "csparse"  # CasADi Linsol plugin of CVODES/IDAS and ROS2
    expand: bool = True  # MX to SX before generating
    cse: bool = True  # common-subexpression elimination
    build_root: str | None = None  # None: generated.codegen.cache_root
    timeout: float = 900.0  # seconds per compilation
    codegen_options: tuple[tuple[str, Any], ...] = field(default=(("with_header", False),))

    def __post_init__(self) -> None:
        if self.jacobian not in JACOBIAN_CHOICES:
            raise BuildError(
                f"CodegenSettings.jacobian: {self.jacobian!r} is not allowed "
                f"(expected one of {', '.join(JACOBIAN_CHOICES)})"
            )
        if not ca.has_linsol(self.linear_solver):
            raise BuildError(
                f"CodegenSettings.linear_solver: {self.linear_solver!r} is not a CasADi "
                "linear solver plugin (expected csparse, qr, ldl or lapacklu)"
            )

    @property
    def cflags(self) -> tuple[str, ...]:
        """The complete compiler flags, in order."""
        return ("-shared", "-fPIC", self.optimization, *self.extra_cflags)

    def key_fields(self) -> dict[str, Any]:
        """The settings that enter the cache key (the build root does not)."""
        d = asdict(self)
        d.pop("build_root")
        d.pop("timeout")
        d["codegen_options"] = [list(p) for p in self.codegen_options]
        return d


@dataclass(frozen=True)
class IntegratorSettings:
    """How to integrate (docs/simulation.md, "Integration methods")."""

    # the scenario's [integration] defaults: core.scenario.Integration owns them
    method: str = default_of(Integration, "method")
    rtol: float = default_of(Integration, "rtol")
    atol: float = default_of(Integration, "atol")
    max_steps: int = default_of(Integration, "max_steps")  # between two output times
    fixed_step: float = default_of(Integration, "fixed_step")  # the largest step of fixed
    chunk: float = 1.0  # simulated seconds per integrator call
    # fixed's safeguard: an output interval whose error estimate exceeds 1 is recomputed
    # as two halves, at most fixed_max_halvings deep; loose so the exact sign's chattering passes
    fixed_rtol: float = 1e-3
    fixed_atol: float = 1e-3
    fixed_max_halvings: int = 30
    newton_scheme: str = "direct"  # CVODES/IDAS (generated.largescale)
    linear_solver: str = "csparse"  # CVODES/IDAS direct Newton, and fixed
    algebraic_atol: float = 1e30  # IDAS: z's abstolv; 1e30 leaves z out of the Newton test
    extra_options: tuple[tuple[str, Any], ...] = ()  # merged last into CVODES/IDAS options

    def __post_init__(self) -> None:
        if self.method not in methods.names():
            raise IntegrationError(
                f"IntegratorSettings.method: {self.method!r} is not one of "
                f"{', '.join(methods.names())}"
            )
        positive = ("rtol", "atol", "fixed_step", "chunk", "fixed_rtol", "fixed_atol")
        for name in (*positive, "algebraic_atol"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise IntegrationError(f"IntegratorSettings.{name}: {v!r} must be a number > 0")
        if not 0 <= int(self.fixed_max_halvings) <= 30:
            raise IntegrationError(
                f"IntegratorSettings.fixed_max_halvings: {self.fixed_max_halvings} not in [0, 30]"
            )
        if int(self.max_steps) < 1:
            raise IntegrationError(f"IntegratorSettings.max_steps: {self.max_steps} must be >= 1")


@dataclass(frozen=True)
class Trajectory:
    """States at the output times, complete or up to a failure (docs/simulation.md)."""

    t: np.ndarray  # (K,)
    x: np.ndarray  # (K, nx)
    z: np.ndarray | None  # (K, nz): algebraic states (IDAS only)
    method: str
    status: Status
    t_reached: float  # the last output time reached
    message: str  # empty when complete, else the reason (method, time reached, flag)
    stats: dict[str, float] = field(default_factory=dict)  # counters, wall_seconds
    sundials_log: str = ""  # a native run's SUNDIALS warnings and errors, one a line
    t_stop: float = math.nan  # where the native driver stood when it returned
    #: the state at t_stop: tells a run-away state from a stalled integrator
    x_stop: np.ndarray | None = None

    @property
    def complete(self) -> bool:
        """True when every output time was reached (``status is Status.OK``)."""
        return self.status is Status.OK

    def largest_at_stop(self) -> int | None:
        """Index of the largest ``|x_stop|`` entry (a non-finite one first); None without it."""
        if self.x_stop is None:
            return None
        return int(np.argmax(np.nan_to_num(np.abs(self.x_stop), nan=np.inf)))

    def raise_if_incomplete(self) -> None:
        """Raise :class:`IntegrationError` (with ``t_reached``) when incomplete."""
        if not self.complete:
            raise IntegrationError(self.message, self.t_reached)


def stop_note(t_stop: float, state: str, value: float) -> str:
    """The clause a failure's message gains: where CVODE stood and its largest state there.

    Parameters
    ----------
    t_stop : float
    state : str
        The name of the largest entry of ``x_stop``.
    value : float
    """
    return (
        f"; at CVODE's last step, t = {t_stop:.7g} s, the largest state is {state} = "
        f"{value:.3g} in magnitude"
    )
