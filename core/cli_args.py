"""Typed command-line values: ``type=`` converters that refuse a bad value in argparse itself.

Given as ``add_argument(..., type=count)`` to a :class:`core.errors.CliParser`, a value
that does not convert (``--runs 0``, ``--port 99999``, ``--horizon nan``) becomes one
line naming the flag and the fix, exit status 2, before the command does any work:
argparse turns the ``ArgumentTypeError`` into ``argument --runs: ...`` and
:meth:`CliParser.error` into a :class:`core.errors.UsageError`.
"""

from __future__ import annotations

import argparse
import math

#: the TCP ports a server may bind
PORTS = (1, 65535)


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def count(text: str) -> int:
    """An integer >= 1 (runs, samples, workers, seeds of a benchmark).

    Parameters
    ----------
    text : str
        The flag's value.
    """
    n = _int(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f"{n} (give a count of at least 1)")
    return n


def natural(text: str) -> int:
    """An integer >= 0 (a seed, a baseline budget that may be empty).

    Parameters
    ----------
    text : str
        The flag's value.
    """
    n = _int(text)
    if n < 0:
        raise argparse.ArgumentTypeError(f"{n} (give an integer of at least 0)")
    return n


def positive(text: str) -> float:
    """A finite number > 0 (seconds, tolerances, limits).

    Parameters
    ----------
    text : str
        The flag's value.
    """
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(x) and x > 0):
        raise argparse.ArgumentTypeError(f"{text} (give a finite number > 0)")
    return x


def port(text: str) -> int:
    """A TCP port, 1 to 65535.

    Parameters
    ----------
    text : str
        The flag's value.
    """
    n = _int(text)
    if not PORTS[0] <= n <= PORTS[1]:
        raise argparse.ArgumentTypeError(f"{n} (give a port from {PORTS[0]} to {PORTS[1]})")
    return n


def word(text: str) -> str:
    """A non-empty value without surrounding blanks (a compiler, a flag, a solver's name).

    Parameters
    ----------
    text : str
        The flag's value.
    """
    if not text.strip() or text != text.strip():
        raise argparse.ArgumentTypeError(
            f"{text!r} (give a non-empty value without blanks around it)"
        )
    return text
