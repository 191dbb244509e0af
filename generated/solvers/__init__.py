"""The integration methods' implementations, by name: one :class:`Solver` per module.

::

    from generated import solvers
    solvers.get("native")        # the Solver instance; a ToolkitError lists the known names
    solvers.names()              # ('cvodes', 'native', 'idas', 'fixed', ...)
    solvers.register(MySolver()) # a method defined outside the registry's list

The one list of methods is :mod:`core.methods` (below this layer, so that the scenario
loader and ``--method`` ask the same registry): each :class:`~core.methods.MethodSpec`
names the module that implements it, imported here the first time the method is
needed, so importing this package stays cheap and the method modules may import the
integration engine freely.
"""

from __future__ import annotations

import importlib

from core import methods
from core.errors import IntegrationError
from core.methods import MethodSpec
from generated.solvers.base import BuildPlan, Solver

__all__ = [
    "BuildPlan",
    "Solver",
    "get",
    "names",
    "register",
    "unregister",
]

_REGISTRY: dict[str, Solver] = {}


def register(solver: Solver, *, replace: bool = False) -> Solver:
    """Make ``solver`` the implementation of the method ``solver.name``.

    A method declared in :mod:`core.methods` must agree with it on ``form`` and
    ``fixed_step``; any other name is declared there from the solver's attributes (so
    scenario files and ``--method`` accept it too).

    Parameters
    ----------
    solver : Solver
    replace : bool
        Allow replacing a method registered under the same name.

    Returns
    -------
    Solver
        ``solver`` (so a module can write ``SOLVER = register(MySolver())``).

    Raises
    ------
    IntegrationError
        For a name taken (without ``replace``), not a plain word, an unknown form or a
        solver that disagrees with the method's declaration.
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

    Raises
    ------
    IntegrationError
        For an unknown name, in one line listing the known ones, or a module that does
        not register its method.
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
