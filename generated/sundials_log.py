"""SUNDIALS' messages of a run (the log file the native driver writes, generated/agents.py)."""

from __future__ import annotations

import os
import re
from typing import Any

#: one SUNDIALS message line: level, module, text, optional "(file:line)" at the end
_SUNDIALS_LINE = re.compile(
    r"^\[(?P<level>ERROR|WARNING)\](?:\[rank \d+\])?(?:\[(?P<scope>[^\]]*)\])?"
    r"\[(?P<label>[^\]]*)\]\s*(?P<text>.*?)(?:\s+\([^()]*\.c:\d+\))?$"
)


def sundials_messages(log: str) -> dict[str, Any]:
    """Count SUNDIALS' messages in a run's log and give the first without its source path.

    Parameters
    ----------
    log : str
        ``Trajectory.sundials_log`` (SUNDIALS' own line format is read too).

    Returns
    -------
    dict
        ``count``, ``warnings``, ``errors`` and ``first``: the first message as
        ``"CVode: t + h = t on the next step ..."`` (no level word, no path), or None.
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
        The file the messages were written to.
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
