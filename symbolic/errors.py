"""The project's one error family.

Every user-facing failure is a :class:`ToolkitError` whose ``str`` is one line
naming the field and the fix. Command-line entry points catch it, print that
line to stderr and exit with status 2 (see :func:`run_cli`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable


class ToolkitError(Exception):
    """Base class: a one-line, user-facing error."""

    exit_code = 2

    def __str__(self) -> str:  # always one line
        return " ".join(super().__str__().split())


class ScenarioError(ToolkitError):
    """A scenario file is malformed or inconsistent.

    Parameters
    ----------
    file : str
        Path of the scenario file (or CSV trace).
    key : str
        Dotted key of the offending field, e.g. ``followers[2].g``.
    problem : str
        What is wrong.
    expected : str
        What is expected instead (the fix).
    """

    def __init__(self, file: str, key: str, problem: str, expected: str = "") -> None:
        self.file, self.key, self.problem, self.expected = file, key, problem, expected
        msg = f"{file}: {key}: {problem}"
        if expected:
            msg += f" (expected {expected})"
        super().__init__(msg)


class ExpressionError(ToolkitError):
    """An expression was rejected by the whitelist parser."""


class SynthesisError(ToolkitError):
    """An assumption fails, an LMI is infeasible or a certificate check fails."""


class BuildError(ToolkitError):
    """Code generation or compilation failed."""


class IntegrationError(ToolkitError):
    """An integrator gave up; carries the time reached."""

    def __init__(self, message: str, t_reached: float | None = None) -> None:
        self.t_reached = t_reached
        super().__init__(message)


def run_cli(main: Callable[[list[str]], int], argv: list[str] | None = None) -> int:
    """Run a command-line ``main`` so that toolkit errors become one line and exit 2."""
    try:
        return main(sys.argv[1:] if argv is None else argv)
    except ToolkitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
