"""SUNDIALS' messages of a run: the per-call log file the native driver writes, read back.

The native driver routes SUNDIALS' logger into a per-call file (:func:`new_sundials_log`);
:func:`take_sundials_log` reads and removes it, :func:`sundials_messages` counts its
warnings and errors and :func:`sundials_summary` gives the one line the CLI prints.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path
from typing import Any

#: one SUNDIALS message line: level, module, text, optional "(file:line)" at the end
_SUNDIALS_LINE = re.compile(
    r"^\[(?P<level>ERROR|WARNING)\](?:\[rank \d+\])?(?:\[(?P<scope>[^\]]*)\])?"
    r"\[(?P<label>[^\]]*)\]\s*(?P<text>.*?)(?:\s+\([^()]*\.c:\d+\))?$"
)


def new_sundials_log() -> Path:
    """A new empty temporary file for a native run's SUNDIALS messages.

    Returns
    -------
    Path
        Passed to the driver (``hitl_options.log_path``), read back and removed by
        :func:`take_sundials_log`.
    """
    fd, name = tempfile.mkstemp(prefix="hitl-sundials-", suffix=".log")
    os.close(fd)
    return Path(name)


def take_sundials_log(path: Path | None) -> str:
    """The text a driver wrote to ``path`` (:func:`new_sundials_log`); the file removed.

    Parameters
    ----------
    path : Path or None
        None or a missing file: no messages.

    Returns
    -------
    str
    """
    if path is None:
        return ""
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return ""
    path.unlink(missing_ok=True)
    return text


def sundials_messages(log: str) -> dict[str, Any]:
    """Count SUNDIALS' messages in a run's log and give the first without its source path.

    Parameters
    ----------
    log : str
        ``Trajectory.sundials_log``: lines as the native driver writes them
        (``[WARNING][CVode] Warning: t + h = t ... (cvode.c:1234)``); SUNDIALS' own
        format (``[WARNING][rank 0][/build/path/cvode.c:1234][CVode] ...``) is read too.

    Returns
    -------
    dict
        ``count`` (messages), ``warnings``, ``errors`` and ``first``: the first message
        as ``"CVode: t + h = t on the next step ..."`` (no level word, no path), or None.
    """
    count, warnings, first = 0, 0, None
    for line in log.splitlines():
        m = _SUNDIALS_LINE.match(line.strip())
        if not m:
            continue
        count += 1
        warnings += m["level"] == "WARNING"
        if first is None:
            text = re.sub(r"^(Warning|Error):\s*", "", m["text"])
            first = f"{m['label']}: {text}" if m["label"] else text
    return {"count": count, "warnings": warnings, "errors": count - warnings, "first": first}


def sundials_summary(log: str, where: str | os.PathLike[str]) -> str | None:
    """One line for the terminal about a run's SUNDIALS messages, or None if none.

    Parameters
    ----------
    log : str
        ``Trajectory.sundials_log``.
    where : str or PathLike
        The file the messages were written to (``out/<run>/sundials.log``).

    Returns
    -------
    str or None
        e.g. ``SUNDIALS: 2 warnings (first: CVode: t + h = t on the next step ...);
        see out/run/sundials.log``.
    """
    m = sundials_messages(log)
    if not m["count"]:
        return None
    parts = [
        f"{n} {word}{'s' if n != 1 else ''}"
        for n, word in ((m["warnings"], "warning"), (m["errors"], "error"))
        if n
    ]
    return f"SUNDIALS: {', '.join(parts)} (first: {m['first']}); see {where}"
