"""Every public function and class has a docstring naming its parameters (python-control style).

For each module of the packages in ``PACKAGES`` except ``EXCLUDED_MODULES``: every function
and class whose name does not start with ``_`` and that is defined in that module (not
imported into it) must have a docstring; every such function, and every public method
defined in such a class, must list each of its arguments (keyword-only included;
``self``/``cls`` excepted; ``*args`` and ``**kwargs`` may be written with or without the
stars) in a numpy-style ``Parameters`` section. A class with its own ``__init__`` may
document the constructor's arguments in the class docstring or in ``__init__``'s.
Dataclasses need only the class docstring.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re
from types import ModuleType

import pytest
from helpers import PACKAGES

# modules neither imported nor checked
EXCLUDED_MODULES: set[str] = set()

_HEADER = re.compile(r"^\s*-{3,}\s*$")
_PARAM_LINE = re.compile(r"^(\*{0,2}\w+(?:\s*,\s*\*{0,2}\w+)*)\s*(?::.*)?$")


def _modules(package: str) -> list[ModuleType]:
    pkg = importlib.import_module(package)
    mods = [pkg]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."):
        if info.name not in EXCLUDED_MODULES:
            mods.append(importlib.import_module(info.name))
    return mods


def _own_doc(obj) -> str | None:
    """The object's own docstring: not inherited, and not the one dataclasses make up."""
    doc = obj.__dict__.get("__doc__") if inspect.isclass(obj) else obj.__doc__
    if not doc or not doc.strip():
        return None
    if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
        if doc.startswith(f"{obj.__name__}("):  # dataclasses' generated signature
            return None
    return doc


def documented_parameters(doc: str) -> set[str]:
    """The names listed in a numpy-style ``Parameters`` section of ``doc`` (stars kept).

    Parameters
    ----------
    doc : str
        A docstring.
    """
    lines = inspect.cleandoc(doc).splitlines()
    names: set[str] = set()
    for k in range(len(lines) - 1):
        if lines[k].strip() != "Parameters" or not _HEADER.match(lines[k + 1]):
            continue
        indent = len(lines[k]) - len(lines[k].lstrip())
        for j in range(k + 2, len(lines)):
            line = lines[j]
            if j + 1 < len(lines) and _HEADER.match(lines[j + 1]):
                break  # next section
            if not line.strip() or len(line) - len(line.lstrip()) > indent:
                continue  # blank or a description line
            m = _PARAM_LINE.match(line.strip())
            if m:
                names.update(n.strip() for n in m.group(1).split(","))
    return names


def _required(func) -> list[tuple[str, set[str]]]:
    """Each argument of ``func`` with the spellings that count as documenting it."""
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    out = []
    for p in sig.parameters.values():
        if p.name in ("self", "cls"):
            continue
        if p.kind is p.VAR_POSITIONAL:
            out.append((p.name, {p.name, f"*{p.name}"}))
        elif p.kind is p.VAR_KEYWORD:
            out.append((p.name, {p.name, f"**{p.name}"}))
        else:
            out.append((p.name, {p.name}))
    return out


def _check_function(func, where: str, extra_doc: str = "") -> list[str]:
    doc = func.__doc__ if func.__doc__ and func.__doc__.strip() else None
    required = _required(func)
    if doc is None and not extra_doc:
        return [f"{where}: no docstring"]
    listed = documented_parameters(doc or "") | documented_parameters(extra_doc)
    return [
        f"{where}: parameter {name!r} not in its Parameters section"
        for name, spellings in required
        if not spellings & listed
    ]


def _public_methods(cls) -> list[tuple[str, object]]:
    out = []
    for name, attr in cls.__dict__.items():
        if name.startswith("_"):
            continue
        if isinstance(attr, staticmethod | classmethod):
            attr = attr.__func__
        if inspect.isfunction(attr) and attr.__qualname__.startswith(cls.__qualname__ + "."):
            out.append((name, attr))
    return out


def _check_class(cls, where: str) -> list[str]:
    doc = _own_doc(cls)
    problems = [] if doc else [f"{where}: no class docstring"]
    init = cls.__dict__.get("__init__")
    if (
        inspect.isfunction(init)
        and not dataclasses.is_dataclass(cls)
        and init.__qualname__ == f"{cls.__qualname__}.__init__"
    ):
        problems += _check_function(init, f"{where}.__init__", extra_doc=doc or "")
    for name, meth in _public_methods(cls):
        problems += _check_function(meth, f"{where}.{name}")
    return problems


def _public_objects(module: ModuleType) -> list[tuple[str, object]]:
    out = []
    for name, obj in vars(module).items():
        if name.startswith("_"):
            continue
        target = inspect.unwrap(obj) if callable(obj) else obj
        if not (inspect.isfunction(target) or inspect.isclass(target)):
            continue
        if getattr(target, "__module__", None) != module.__name__:
            continue  # imported, checked where it is defined
        out.append((name, obj))
    return out


def _problems(package: str) -> list[str]:
    problems = []
    for module in _modules(package):
        for name, obj in _public_objects(module):
            where = f"{module.__name__}.{name}"
            if inspect.isclass(obj):
                problems += _check_class(obj, where)
            else:
                problems += _check_function(inspect.unwrap(obj), where)
    return problems


@pytest.mark.parametrize("package", PACKAGES)
def test_public_docstrings(package):
    problems = _problems(package)
    assert not problems, f"{len(problems)} docstring problems:\n" + "\n".join(problems)


def test_checker_sees_missing_and_present_parameters():
    def documented(a, b, *args, c=1, **kwargs):
        """Do a thing.

        Parameters
        ----------
        a, b : float
            Two numbers.
        *args
            More.
        c : int, optional
            Keyword-only. A line ``d : not a param`` deeper in is a description.
        **kwargs
            Options.

        Returns
        -------
        x : float
            Not a parameter.
        """

    def missing(a, *, key):
        """Do a thing.

        Parameters
        ----------
        a : float
            A number.
        """

    def bare(a):
        pass

    assert _check_function(documented, "documented") == []
    assert documented_parameters(documented.__doc__) == {"a", "b", "*args", "c", "**kwargs"}
    assert _check_function(missing, "missing") == [
        "missing: parameter 'key' not in its Parameters section"
    ]
    assert _check_function(bare, "bare") == ["bare: no docstring"]

    @dataclasses.dataclass
    class NoDoc:
        x: int

    @dataclasses.dataclass
    class WithDoc:
        """A value."""

        x: int

    assert _check_class(NoDoc, "NoDoc") == ["NoDoc: no class docstring"]
    assert _check_class(WithDoc, "WithDoc") == []
