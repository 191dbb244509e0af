"""The project's one error family.

Every user-facing failure is a :class:`ToolkitError` whose ``str`` is one line
naming the field and the fix. Command-line entry points catch it, print that
line to stderr and exit with status 2 (see :func:`run_cli`).
"""

from __future__ import annotations

import argparse
import errno
import os
import sys
from collections.abc import Callable
from typing import NoReturn


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
        """Record the message and the time the integrator reached.

        Parameters
        ----------
        message : str
            One-line description.
        t_reached : float, optional
            Last time the integrator reached, if known.
        """
        self.t_reached = t_reached
        super().__init__(message)


class UsageError(ToolkitError):
    """A wrong command line."""


class CliParser(argparse.ArgumentParser):
    """``argparse`` parser whose errors raise :class:`UsageError` (one line, exit 2 via
    :func:`run_cli`) instead of printing the usage and exiting; sub-parsers inherit it."""

    def error(self, message: str) -> NoReturn:
        """Raise the one-line :class:`UsageError`.

        Parameters
        ----------
        message : str
            argparse's description of what is wrong.
        """
        raise UsageError(f"{self.prog}: {message} (see --help)")


def run_cli(main: Callable[[list[str]], int], argv: list[str] | None = None) -> int:
    """Run a command-line ``main`` so that toolkit errors become one line and exit 2.

    An :class:`OSError` (read-only or full disk, a name too long, ...) becomes one line
    too (:func:`os_error_line`), exit 2: the boundary where every file-system failure of
    a command ends, so the writers need no handlers of their own.

    Parameters
    ----------
    main : callable
        ``main(argv) -> int``, the command's entry point.
    argv : list of str, optional
        Arguments; default ``sys.argv[1:]``.
    """
    try:
        return main(sys.argv[1:] if argv is None else argv)
    except ToolkitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # the file system refused: read-only, full, name too long, ...
        print(f"error: {os_error_line(exc)}", file=sys.stderr)
        return ToolkitError.exit_code
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


#: where each artifact can be redirected (named in the fix of a failed write)
_ELSEWHERE = (
    "or write elsewhere: --out DIR or HITL_OUT for outputs, HITL_BUILD_DIR for the build cache"
)


def os_error_line(exc: OSError) -> str:
    """One line for a file-system failure: the path, the reason and the fix.

    Parameters
    ----------
    exc : OSError
        Raised while reading or writing a file; ``exc.filename`` names it when known.

    Returns
    -------
    str
        E.g. ``cannot write out/paper/trajectory.csv: Read-only file system (make
        out/paper writable, or write elsewhere: ...)``.
    """
    reason = exc.strerror or type(exc).__name__
    if exc.filename is None:
        return " ".join(f"{reason} (errno {exc.errno}); check the output folder and disk".split())
    path = str(exc.filename)
    folder = os.path.dirname(path.rstrip("/")) or "."
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        msg = f"cannot write {path}: {reason} (make {folder} writable, {_ELSEWHERE})"
    elif exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        msg = f"cannot write {path}: {reason} (free space on the disk of {folder}, {_ELSEWHERE})"
    elif exc.errno == errno.ENAMETOOLONG:
        msg = f"{path}: {reason} (a shorter scenario name or --variant NAME)"
    else:
        msg = f"{path}: {reason}"
    return " ".join(msg.split())


def strict_mode(flag: bool = False) -> bool:
    """Whether strict mode is on: ``--strict`` or the ``STRICT`` environment variable.

    Parameters
    ----------
    flag : bool
        The command line's ``--strict``.

    Returns
    -------
    bool
        True for ``--strict`` or ``STRICT`` in {1, true, yes, on}; False for unset or
        {0, false, no, off, ""}.

    Raises
    ------
    UsageError
        For any other value of ``STRICT``.
    """
    env = os.environ.get("STRICT", "").strip().lower()
    if env in ("1", "true", "yes", "on"):
        return True
    if env not in ("", "0", "false", "no", "off"):
        raise UsageError(f"STRICT={env!r} is not understood (use STRICT=1 or STRICT=0)")
    return flag
