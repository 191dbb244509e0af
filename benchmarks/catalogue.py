"""The benchmark's methods and sizes: what each method runs, which is ours at N."""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import ToolkitError

SIZES = (5, 50, 500, 2000)


@dataclass(frozen=True)
class BenchMethod:
    """A benchmark method: what it runs and how.

    Attributes
    ----------
    name : str
        The benchmark's name (``c-cvode-native``).
    kind : str
        How the worker sets it up: ``scipy`` (hand-written numpy RHS), ``vm`` (CasADi's
        virtual machine, no code generation), ``ours`` (the functions of ``make sim``) or
        ``exact`` (``ours`` with the exact sign function).
    solver : str or None
        The registered integration method it runs (:func:`generated.solvers.get`).
    jacobian : str or None
        ``CodegenSettings.jacobian`` (``auto``: the plan of ``make sim``).
    cheap_build : bool
        Its build is cheap at any N: after it hits the time limit, larger N still get a
        build-only cell (build times, C size, RHS time) instead of nothing.
    """

    name: str
    kind: str
    solver: str | None = None
    jacobian: str | None = None
    cheap_build: bool = True


#: the benchmark's methods, in table order
BENCH_METHODS = {
    m.name: m
    for m in (
        BenchMethod("scipy-bdf", "scipy"),
        BenchMethod("scipy-rk45", "scipy"),
        BenchMethod("casadi-vm", "vm", "cvodes", "sparse"),
        BenchMethod("c-cvode-native", "ours", "native", "auto"),
        BenchMethod("c-cvodes-direct", "ours", "cvodes", "sparse", cheap_build=False),
        BenchMethod("c-cvodes-gmres", "ours", "cvodes", "jvp"),
        BenchMethod("c-idas", "ours", "idas", "auto"),
        BenchMethod("fixed", "exact", "fixed", cheap_build=False),
    )
}
METHODS = tuple(BENCH_METHODS)
OUTPUT_STEP = 0.1  # output grid of every method (states stored there)
#: methods whose build is cheap at any N (:attr:`BenchMethod.cheap_build`)
CHEAP_BUILDS = tuple(m.name for m in BENCH_METHODS.values() if m.cheap_build)


def integration_method(method: str) -> str:
    """The registered integration method a benchmark method runs.

    Parameters
    ----------
    method : str
        One of the CasADi/generated-C methods of :data:`METHODS`.

    Raises
    ------
    BenchError
        For a benchmark method without one (the scipy methods) or an unknown name.
    """
    m = BENCH_METHODS.get(method)
    if m is None or m.solver is None:
        raise BenchError(f"{method!r} runs no registered integration method")
    from generated import solvers

    return solvers.get(m.solver).name


def ours_method(N: int) -> str:
    """The benchmark method that is ours at N: what ``make sim`` runs for N followers.

    ``c-cvode-native`` (method ``native``, the per-agent engine, :mod:`generated.agents`)
    at every N.

    Parameters
    ----------
    N : int
        Number of followers.
    """
    if int(N) < 1:
        raise BenchError(f"N: {N} must be >= 1")
    return "c-cvode-native"


class BenchError(ToolkitError):
    """Bad benchmark arguments."""
