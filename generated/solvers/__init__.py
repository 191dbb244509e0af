"""The integration methods' implementations by name (``get``, ``names``, ``register``).

The one list of methods is :mod:`core.methods`: each spec names the module that
implements it, imported on first use, so importing this package stays cheap.
"""

from __future__ import annotations

import importlib

from core import methods
from core.errors import IntegrationError
from core.methods import MethodSpec
from generated.solvers.base import BuildPlan, Solver

__all__ = ["BuildPlan", "Solver", "get", "names", "register", "unregister"]

_REGISTRY: dict[str, Solver] = {}


def register(solver: Solver, *, replace: bool = False) -> Solver:
    """Make ``solver`` the implementation of method ``solver.name`` and return it.

    A name :mod:`core.methods` declares must agree with it on ``form`` and ``fixed_step``;
    any other name is declared there from the solver's attributes.

    Parameters
    ----------
    solver : Solver
    replace : bool
        Allow replacing a method registered under the same name.
    """
    name = getattr(solver, "name", "")
    if solver.form not in methods.FORMS:
        raise IntegrationError(
            f"solver {name!r}: form {solver.form!r} is not one of {methods.FORMS}"
        )
    if name in _REGISTRY and not replace and _REGISTRY[name] is not solver:
        raise IntegrationError(f"solver {name!r} is registered already (pass replace=True)")
    spec = methods.get(name) if name in methods.names() else None
    if spec is None or replace:
        module = type(solver).__module__
        spec = MethodSpec(name, solver.form, bool(solver.fixed_step), module, solver.summary)
        methods.declare(spec, replace=True)
    if (spec.form, spec.fixed_step) != (solver.form, bool(solver.fixed_step)):
        raise IntegrationError(
            f"solver {name!r}: form {solver.form!r}, fixed_step {solver.fixed_step} disagree "
            f"with core.methods ({spec.form!r}, {spec.fixed_step})"
        )
    _REGISTRY[name] = solver
    return solver


def unregister(name: str) -> None:
    """Remove a method that is not built in (tests that register a toy method use this).

    Parameters
    ----------
    name : str
    """
    _REGISTRY.pop(name, None)
    methods.withdraw(name)


def names() -> tuple[str, ...]:
    """The method names (built-ins first): those of :func:`core.methods.names`."""
    return methods.names()


def get(name: str) -> Solver:
    """The :class:`Solver` of method ``name`` (its module imported on first use).

    Parameters
    ----------
    name : str
    """
    solver = _REGISTRY.get(name)
    if solver is None:
        spec = methods.get(name)
        importlib.import_module(spec.module)
        solver = _REGISTRY.get(name)
        if solver is None:
            raise IntegrationError(
                f"integration method {name!r}: {spec.module} does not register it "
                "(end the module with SOLVER = register(MySolver()))"
            )
    return solver
