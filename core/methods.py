"""The integration methods: one registry, asked by the scenario loader, ``--method`` and the API.

A method is declared once, by a :class:`MethodSpec`: its name (what
``integration.method`` and ``--method`` accept), its form (``"ode"`` or ``"dae"``),
whether it steps with a fixed step (only those may integrate ``options.sign =
"exact"``) and the module of the solver layer that implements it. This layer never
imports that module: :mod:`generated.solvers` does, the first time the method is run.

::

    from core import methods
    methods.names()                      # ('cvodes', 'native', 'idas', 'fixed')
    methods.get("fixed").fixed_step      # True
    methods.declare(MethodSpec("lsoda", "ode", False, "mypkg.lsoda"))  # a method elsewhere

A new built-in method is one module in ``generated/solvers/`` plus one line in
:data:`BUILTIN` (docs/ARCHITECTURE.md, 'Where new things go').
"""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import IntegrationError

FORMS = ("ode", "dae")


@dataclass(frozen=True)
class MethodSpec:
    """What the rest of the toolkit knows about an integration method.

    Attributes
    ----------
    name : str
        ``integration.method`` / ``--method``: a plain word (letters, digits, - and _).
    form : str
        ``"ode"`` (ẋ = f(t, x)) or ``"dae"`` (the accelerations as algebraic states).
    fixed_step : bool
        Steps with a fixed step, so that ``options.sign = "exact"`` is allowed.
    module : str
        The module that implements it (imported by :mod:`generated.solvers` on first
        use; it ends with ``SOLVER = register(MySolver())``).
    summary : str
        One line for ``--help`` and the docs.
    """

    name: str
    form: str
    fixed_step: bool
    module: str
    summary: str = ""

    def __post_init__(self) -> None:
        word = self.name.replace("-", "").replace("_", "")
        if not (isinstance(self.name, str) and word.isalnum()):
            raise IntegrationError(
                f"method name {self.name!r}: a plain word (letters, digits, - _)"
            )
        if self.form not in FORMS:
            raise IntegrationError(
                f"method {self.name!r}: form {self.form!r} is not one of {FORMS}"
            )


#: the built-in methods, in the order :func:`names` lists them (the default first)
BUILTIN = (
    MethodSpec("cvodes", "ode", False, "generated.solvers.cvodes", "BDF (CVODES) through CasADi"),
    MethodSpec("native", "ode", False, "generated.solvers.native", "CVODE driven from C"),
    MethodSpec("idas", "dae", False, "generated.solvers.idas", "IDAS on the DAE form"),
    MethodSpec("fixed", "ode", True, "generated.solvers.fixed", "ROS2 with a fixed step"),
)

#: the live list of method names (scenario settings validate against this object)
METHODS: list[str] = [m.name for m in BUILTIN]
_SPECS: dict[str, MethodSpec] = {m.name: m for m in BUILTIN}


def declare(spec: MethodSpec, *, replace: bool = False) -> MethodSpec:
    """Add a method to the registry.

    Parameters
    ----------
    spec : MethodSpec
    replace : bool
        Allow replacing a method of the same name.

    Returns
    -------
    MethodSpec
        ``spec``.

    Raises
    ------
    IntegrationError
        For a name taken by a different method (without ``replace``).
    """
    old = _SPECS.get(spec.name)
    if old is not None and old != spec and not replace:
        raise IntegrationError(f"method {spec.name!r} is declared already (pass replace=True)")
    _SPECS[spec.name] = spec
    if spec.name not in METHODS:
        METHODS.append(spec.name)
    return spec


def withdraw(name: str) -> None:
    """Remove a method that is not built in (tests that declare a toy method use this).

    Parameters
    ----------
    name : str
    """
    if name in _SPECS and name not in {m.name for m in BUILTIN}:
        del _SPECS[name]
        METHODS.remove(name)


def names() -> tuple[str, ...]:
    """The declared method names (built-ins first)."""
    return tuple(METHODS)


def get(name: str) -> MethodSpec:
    """The :class:`MethodSpec` declared as ``name``.

    Parameters
    ----------
    name : str

    Raises
    ------
    IntegrationError
        For an unknown name, in one line listing the known ones.
    """
    spec = _SPECS.get(name)
    if spec is None:
        raise IntegrationError(
            f"integration method {name!r} is unknown; known: {', '.join(METHODS)}"
        )
    return spec


def is_fixed_step(name: str) -> bool:
    """Whether ``name`` is a declared fixed-step method (False for an unknown name).

    Parameters
    ----------
    name : str
    """
    spec = _SPECS.get(name)
    return spec is not None and spec.fixed_step
