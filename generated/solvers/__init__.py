"""The integration methods, by name: one :class:`Solver` per module, found through the registry.

::

    from generated import solvers
    solvers.get("native")        # the Solver instance; a ToolkitError lists the known names
    solvers.names()              # ('cvodes', 'native', 'idas', 'fixed', ...)
    solvers.register(MySolver()) # a new method (see docs/ARCHITECTURE.md)

The built-in methods (``cvodes``, ``native``, ``idas``, ``fixed``) are registered the
first time the registry is consulted, so importing this package stays cheap and the
method modules may import the integration engine freely.
"""

from __future__ import annotations

import importlib

from core.errors import IntegrationError
from core.scenario import declare_method, withdraw_method
from generated.solvers.base import FORMS, BuildPlan, Solver, Status, flag_status

__all__ = [
    "BuildPlan",
    "Solver",
    "Status",
    "flag_status",
    "get",
    "names",
    "register",
    "unregister",
]

#: the built-in methods' modules, in the order :func:`names` lists them
BUILTIN = ("cvodes", "native", "idas", "fixed")

_REGISTRY: dict[str, Solver] = {}
_loaded = False


def _load_builtins() -> None:
    global _loaded
    if not _loaded:
        _loaded = True
        for module in BUILTIN:
            importlib.import_module(f"generated.solvers.{module}")


def register(solver: Solver, *, replace: bool = False) -> Solver:
    """Make ``solver`` available under ``solver.name``.

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
        For a name taken (without ``replace``), not a plain word, or an unknown form.
    """
    name = getattr(solver, "name", "")
    if not (isinstance(name, str) and name.replace("-", "").replace("_", "").isalnum()):
        raise IntegrationError(f"solver name {name!r}: a plain word (letters, digits, - and _)")
    if solver.form not in FORMS:
        raise IntegrationError(f"solver {name!r}: form {solver.form!r} is not one of {FORMS}")
    if name in _REGISTRY and not replace and _REGISTRY[name] is not solver:
        raise IntegrationError(f"solver {name!r} is registered already (pass replace=True)")
    _REGISTRY[name] = solver
    declare_method(name, fixed_step=solver.fixed_step)  # scenario files may name it
    return solver


def unregister(name: str) -> None:
    """Remove a method (tests that register a toy method clean up with this).

    Parameters
    ----------
    name : str
    """
    _REGISTRY.pop(name, None)
    withdraw_method(name)


def names() -> tuple[str, ...]:
    """The registered method names (built-ins first)."""
    _load_builtins()
    return tuple(_REGISTRY)


def get(name: str) -> Solver:
    """The :class:`Solver` registered as ``name``.

    Parameters
    ----------
    name : str

    Raises
    ------
    IntegrationError
        For an unknown name, in one line listing the known ones.
    """
    _load_builtins()
    solver = _REGISTRY.get(name)
    if solver is None:
        raise IntegrationError(
            f"integration method {name!r} is unknown; known: {', '.join(_REGISTRY)}"
        )
    return solver
