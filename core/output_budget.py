"""The output stage's memory budget: how large a run's trajectory.csv may be."""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING

from core.errors import UsageError
from core.reading import ReadingContext

if TYPE_CHECKING:
    from core.model import Integration

#: peak memory per value of trajectory.csv while it is made (state table, outputs,
#: DataFrame, CSV text): 84.5 B measured (2026-12-01, paper.toml at 2e4 and 2e5 rows,
#: /usr/bin/time -v), rounded up for allocator slack
OUTPUT_BYTES_PER_VALUE = 100
#: default memory budget of the output stage, bytes; ``HITL_OUTPUT_BUDGET`` overrides it
DEFAULT_OUTPUT_BUDGET = 4_000_000_000
OUTPUT_BUDGET_ENV = "HITL_OUTPUT_BUDGET"


def output_columns(N: int, n: int, m: int) -> int:
    """Number of columns of ``trajectory.csv`` (``generated.api.column_names``).

    Parameters
    ----------
    N, n, m : int
        Followers, follower coordinates, leader states.
    """
    # t, eta0, then per follower p q eta mu phi thetahat ghat u b et eeta chi V2, then V1
    return 2 + m + N * (7 * n + 3 * m + 3)


def output_rows(horizon: float, output_step: float) -> int:
    """Number of rows of ``trajectory.csv``: the times ``0, h, ..., horizon``.

    Parameters
    ----------
    horizon, output_step : float
        ``integration.horizon`` and ``integration.output_step`` (s).
    """
    return round(horizon / output_step) + 1  # as generated.schedule.output_grid


def output_budget() -> int:
    """Memory budget of the output stage in bytes: ``$HITL_OUTPUT_BUDGET`` or the default.

    Returns
    -------
    int
        :data:`DEFAULT_OUTPUT_BUDGET` when the variable is unset or empty.

    Raises
    ------
    UsageError
        If the variable is not a positive number of bytes.
    """
    raw = os.environ.get(OUTPUT_BUDGET_ENV, "").strip()
    if not raw:
        return DEFAULT_OUTPUT_BUDGET
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise UsageError(
            f"{OUTPUT_BUDGET_ENV}={raw[:40]!r} is not a number of bytes (e.g. "
            f"{OUTPUT_BUDGET_ENV}=8e9, or unset for {DEFAULT_OUTPUT_BUDGET:.0e})"
        )
    return int(value)


def check_output_size(ctx: ReadingContext, integ: Integration, N: int, n: int, m: int) -> None:
    """Refuse, before any work, a trajectory whose making would exceed the memory budget.

    Parameters
    ----------
    ctx : ReadingContext
        The file being read (its name goes into every error).
    integ : Integration
    N : int
        Number of followers.
    n : int
        Coordinates per follower.
    m : int
        Leader states.
    """
    rows, cols = output_rows(integ.horizon, integ.output_step), output_columns(N, n, m)
    need, budget = rows * cols * OUTPUT_BYTES_PER_VALUE, output_budget()
    if need > budget:
        raise ctx.err(
            "integration.output_step",
            f"{rows} output rows x {cols} columns need about {need / 1e9:.3g} GB of memory to "
            f"write trajectory.csv, above the budget of {budget / 1e9:.3g} GB",
            f"at most {budget // (cols * OUTPUT_BYTES_PER_VALUE)} rows: a larger output_step, a "
            f"shorter horizon, or a larger budget {OUTPUT_BUDGET_ENV}=<bytes>",
        )
