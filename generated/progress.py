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
    """A callback ``f(t)`` that shows ``t`` out of ``horizon`` simulated seconds.

    The bar appears after :data:`DELAY_SECONDS` of wall time, redraws at most every
    :data:`REDRAW_SECONDS` and ends its line when the block is left. It is off when
    ``enabled`` is False (``--no-progress``) and when ``stream`` is not a terminal.

    Parameters
    ----------
    label : str
        Text before the bar.
    horizon : float
        Simulated time that counts as 100 %.
    enabled : bool
        False: yield None (no callback).
    stream : file-like, optional
        Where to draw (default ``sys.stderr``).

    Yields
    ------
    callable or None
        Call it with the simulated time reached (clipped to ``[0, horizon]``).
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
