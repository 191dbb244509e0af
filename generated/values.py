"""The values generated/'s modules pass each other: settings, run status, trajectories.

The package's spine: this module imports nothing from ``generated`` (the import
contract in ``pyproject.toml`` keeps it so), so every module of the package may import
it. How a library is built, how a run is integrated and what a run writes live in the
modules that use these values (:mod:`generated.codegen`, :mod:`generated.solvers`,
:mod:`generated.api`).
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
    """Why a run ended: callers test this, never the text of the message.

    ``OK`` is a complete run; every other member is an incomplete one.
    """

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


#: SUNDIALS return-flag names (without CV_/IDA_) -> status
_FLAG_STATUS = {
    "TOO_MUCH_WORK": Status.STEP_LIMIT,
    "TOO_MUCH_ACC": Status.ACCURACY,
    "ERR_FAIL": Status.ERROR_TEST,
    "ERR_FAILURE": Status.ERROR_TEST,
    "CONV_FAIL": Status.CONV_FAIL,
    "CONV_FAILURE": Status.CONV_FAIL,
    "RHSFUNC_FAIL": Status.RHS_FAIL,
    "REPTD_RHSFUNC_ERR": Status.RHS_FAIL,
    "UNREC_RHSFUNC_ERR": Status.RHS_FAIL,
    "FIRST_RHSFUNC_ERR": Status.RHS_FAIL,
    "RES_FAIL": Status.RHS_FAIL,
    "REP_RES_ERR": Status.RHS_FAIL,
    "FIRST_RES_FAIL": Status.RHS_FAIL,
    "LSETUP_FAIL": Status.LINEAR_FAIL,
    "LSOLVE_FAIL": Status.LINEAR_FAIL,
    "TOO_CLOSE": Status.TOO_CLOSE,
    "LINESEARCH_FAIL": Status.INIT_FAIL,
    "NO_RECOVERY": Status.INIT_FAIL,
}


def flag_status(flag: str) -> Status:
    """The :class:`Status` of a SUNDIALS return flag (``CV_TOO_MUCH_WORK``, ``ERR_FAIL``).

    Parameters
    ----------
    flag : str
        The flag's name with or without its ``CV_``/``IDA_`` prefix.
    """
    return _FLAG_STATUS.get(re.sub(r"^(?:CV|IDA)_", "", flag.strip()), Status.FAILED)


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


#: SUNDIALS return flags -> readable reason
_REASONS = {
    "TOO_MUCH_WORK": "too many steps before the next output time (raise max_steps)",
    "TOO_MUCH_ACC": "tolerances too small for machine precision",
    "ERR_FAIL": "error test failed repeatedly (step size too small)",
    "ERR_FAILURE": "error test failed repeatedly (step size too small)",
    "CONV_FAIL": "Newton iteration failed repeatedly (step size too small)",
    "CONV_FAILURE": "Newton iteration failed repeatedly (step size too small)",
    "RHSFUNC_FAIL": "right-hand side failed (NaN or Inf)",
    "RES_FAIL": "residual failed (NaN or Inf)",
    "REP_RES_ERR": "residual failed repeatedly (NaN or Inf)",
    "LSETUP_FAIL": "linear solver setup failed (singular iteration matrix)",
    "LSOLVE_FAIL": "linear solve failed",
    "CONSTR_FAIL": "constraint test failed",
    "FIRST_RES_FAIL": "residual failed at the first call",
    "LINESEARCH_FAIL": "consistent initial conditions not found (line search)",
    "NO_RECOVERY": "consistent initial conditions not found",
}


def flag_reason(flag: str) -> str:
    """``"TOO_MUCH_WORK: too many steps ..."`` for a SUNDIALS return flag name.

    Parameters
    ----------
    flag : str
        The flag's name with or without its ``CV_``/``IDA_`` prefix.
    """
    flag = re.sub(r"^(?:CV|IDA)_", "", flag)
    return f"{flag}: {_REASONS.get(flag, 'solver failure')}"


#: what derivative code is generated: ``jac_<name>`` (sparse), ``jac_`` and ``fwd1_``
#: (gmres) or only ``fwd1_<name>`` (jvp) (:mod:`generated.csource`)
JACOBIAN_STRATEGIES = ("sparse", "gmres", "jvp")

#: ``auto`` is resolved from the number of agents by :func:`generated.largescale.choose_plan`
#: before anything is generated
JACOBIAN_CHOICES = ("auto", *JACOBIAN_STRATEGIES)


@dataclass(frozen=True)
class CodegenSettings:
    """Every option of code generation, compilation and the integrators' linear algebra.

    Attributes
    ----------
    compiler : str
        C compiler executable (``gcc``; ``cc``/``clang`` work too).
    optimization : str
        Optimisation flag. ``-O1`` is the default: ``-O0`` compiles 3–4× faster on
        large files but the right-hand side then runs slower.
    kernel_optimization : str
        Optimisation flag of the per-agent kernel libraries (``generated/agent_kernels.py``),
        which replaces ``optimization`` there. ``-O3``: those sources are small and their
        driver's loops are hot.
    extra_cflags : tuple of str
        Appended after the fixed flags ``-shared -fPIC``.
    jacobian : str
        ``"sparse"``: ``jac_<name>`` from ``f.jacobian()`` (CasADi's sparse CCS pattern)
        with a direct sparse linear solver; ``"gmres"``: additionally
        ``fwd1_<name>`` (``f.forward(1)``, Jacobian-vector products) and the
        integrators' iterative ``newton_scheme = "gmres"`` (no factorisation, for
        large N); ``"jvp"``: only ``fwd1_<name>`` and GMRES (no Jacobian generated at
        all: code size flat in N with ``expand=False``; the fixed-step method then
        builds its Jacobian from forward sweeps).
    linear_solver : str
        Direct sparse linear solver of CVODES/IDAS and of the fixed-step method
        (a CasADi Linsol plugin: ``csparse``, ``qr``, ``ldl``, ``lapacklu`` (dense)).
    expand : bool
        Expand MX Functions to SX before generating code (flat, faster C).
    cse : bool
        Common-subexpression elimination (CasADi's ``cse`` option) on SX functions and
        their generated Jacobians before code is written: the same operations on the same
        operands, so the same results, in less code.
    build_root : str or None
        Cache root; ``None`` = ``$HITL_BUILD_DIR`` or the user cache folder
        (:func:`generated.codegen.cache_root`).
    timeout : float
        Seconds allowed for one compilation.
    codegen_options : tuple of (str, value) pairs
        Options for :class:`casadi.CodeGenerator`.
    """

    compiler: str = "gcc"
    optimization: str = "-O1"
    kernel_optimization: str = "-O3"
    extra_cflags: tuple[str, ...] = ()
    jacobian: str = "sparse"
    linear_solver: str = "csparse"
    expand: bool = True
    cse: bool = True
    build_root: str | None = None
    timeout: float = 900.0
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
    """How to integrate.

    Attributes
    ----------
    method : str
        A registered method (:func:`core.methods.names`): ``cvodes`` (BDF through
        CasADi, default), ``native`` (BDF, SUNDIALS CVODE driven from C:
        :mod:`generated.native`), ``idas`` (the DAE form) or ``fixed`` (ROS2).
    rtol, atol : float
        Relative and absolute tolerances (CVODES, IDAS).
    max_steps : int
        CVODES/IDAS ``max_num_steps``: steps allowed between two output times.
    fixed_step : float
        Largest step of the fixed-step method (each output interval is divided
        into equal steps no longer than this).
    fixed_rtol, fixed_atol : float
        Safeguard of the fixed-step method: an output interval whose embedded error
        estimate ``|h (k1 + k2)/2| / (atol + rtol |x|)`` exceeds 1 anywhere (or that
        produces NaN) is recomputed as two halves with the same number of steps each
        (bisection, recursively, at most ``fixed_max_halvings`` levels deep). Loose by design: the exact sign function's chattering (a jump in f of
        size Δ gives an estimate h Δ / 2) passes; a violent transient does not.
    fixed_max_halvings : int
    chunk : float
        Simulated seconds per integrator call (restart, progress, failure granularity).
    newton_scheme, linear_solver : str
        Linear algebra of CVODES/IDAS (see :attr:`generated.largescale.JacobianPlan.integrator_options`);
        ``linear_solver`` is also the sparse solver of the fixed-step method.
    algebraic_atol : float
        IDAS only: absolute tolerance of the algebraic states z. z is not error-tested
        (``suppress_algebraic``), so this enters only IDAS's Newton convergence test,
        with weights 1/(rtol|z| + algebraic_atol). The default 1e30 leaves z out of
        that test: in the semi-explicit form z enters ẋ, so a Newton error in z shows
        up in the x-corrections (times h/α), as in the ODE form, while testing z itself
        asks for more digits than z(x) has (docs/simulation.md).
    extra_options : tuple of (str, value) pairs
        Merged last into the CVODES/IDAS options (e.g. ``("use_preconditioner", False)``,
        ``("max_krylov", 50)`` for GMRES at large N).
    """

    # the scenario's [integration] defaults: core.scenario.Integration owns them
    method: str = default_of(Integration, "method")
    rtol: float = default_of(Integration, "rtol")
    atol: float = default_of(Integration, "atol")
    max_steps: int = default_of(Integration, "max_steps")
    fixed_step: float = default_of(Integration, "fixed_step")
    chunk: float = 1.0
    fixed_rtol: float = 1e-3
    fixed_atol: float = 1e-3
    fixed_max_halvings: int = 30
    newton_scheme: str = "direct"
    linear_solver: str = "csparse"
    algebraic_atol: float = 1e30
    extra_options: tuple[tuple[str, Any], ...] = ()

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
    """States at the output times, complete or up to a failure.

    Attributes
    ----------
    t : ndarray, shape (K,)
    x : ndarray, shape (K, nx)
    z : ndarray or None, shape (K, nz)
        Algebraic states (IDAS only).
    method : str
    status : Status
        ``Status.OK`` for a complete run, else why the integrator gave up before the
        last output time (test this, not the message).
    t_reached : float
        Last output time integrated successfully.
    message : str
        Empty when complete, else the reason (method, time reached, solver flag).
    stats : dict of str to float
        ``steps``, ``rhs_evals``, ``jac_evals``, ``lin_setups``, ``error_test_fails``,
        ``newton_fails``, ``newton_iters``, ``jtimes_evals``, ``restarts``, ``integrator_calls``,
        ``wall_seconds`` and, for CVODES/IDAS, ``last_step`` (the last step size taken).
    sundials_log : str
        SUNDIALS' warnings and errors of the run, one line each (``[WARNING][CVode]
        text (cvode.c:line)``; the native driver), empty when there were none; counted
        by :func:`generated.sundials_log.sundials_messages`.
    t_stop : float
        Where the integrator stood when it returned (the native driver; NaN for the
        others): on a failure CVODE's last internal step, between ``t_reached`` and the
        next output time; the horizon for a complete run.
    x_stop : ndarray or None, shape (nx,)
        The state at ``t_stop`` (the native driver; None for the others). On a failure
        it tells a state that ran away from an integrator that stalled on a tame one,
        which the output rows, ending at ``t_reached``, cannot.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray | None
    method: str
    status: Status
    t_reached: float
    message: str
    stats: dict[str, float] = field(default_factory=dict)
    sundials_log: str = ""
    t_stop: float = math.nan
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
        ``Trajectory.t_stop``.
    state : str
        The name of the largest entry of ``x_stop`` (e.g. ``StateLayout.name_of``).
    value : float
        Its magnitude.
    """
    return (
        f"; at CVODE's last step, t = {t_stop:.7g} s, the largest state is {state} = "
        f"{value:.3g} in magnitude"
    )
