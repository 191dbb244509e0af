"""A progress bar on stderr for a run, fed with the simulated time reached (tqdm)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import IO

from tqdm import tqdm

#: wall seconds before the bar first appears (short runs show none)
DELAY_SECONDS = 1.0
#: shortest wall time between two redraws
REDRAW_SECONDS = 0.1


@contextmanager
def progress_bar(
    label: str, horizon: float, enabled: bool = True, stream: IO[str] | None = None
) -> Iterator[Callable[[float], None] | None]:
    """A callback ``f(t)`` showing the simulated time ``t`` reached out of ``horizon``.

    None (no bar) when ``enabled`` is False (``--no-progress``) or ``stream`` is no terminal.

    Parameters
    ----------
    label : str
        Text before the bar.
    horizon : float
    enabled : bool
    stream : file-like, optional
        Default ``sys.stderr``.
    """
    out = stream if stream is not None else sys.stderr
    if not enabled or not out.isatty():
        yield None
        return
    total = max(float(horizon), 0.0)
    bar = tqdm(
        total=total,
        desc=label,
        unit="s",
        file=out,
        delay=DELAY_SECONDS,
        mininterval=REDRAW_SECONDS,
        bar_format="{desc} [{bar:30}] {percentage:5.1f}%  t = {n:.2f}/{total:g} s  {elapsed}",
    )

    def update(t: float) -> None:
        bar.update(min(max(float(t), 0.0), total) - bar.n)

    try:
        yield update
    finally:
        bar.close()
