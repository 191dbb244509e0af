"""Checks added by registration: a new row of the bound table is one module and one line.

A module in :data:`MODULES` registers its claims (:func:`verify.claims.register`) and the
function that adds their rows (:func:`register_check`); :func:`verify.table.bounds_table`
imports the modules and calls every registered function, in registration order, after
Theorem 1, Theorem 2 and Definition 1 rows and before the ablation's (docs/ARCHITECTURE.md,
'Where new things go'). Each function reads one :class:`CheckInput`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

from core.scenario import Scenario
from synthesis.gains import Gains
from verify import signals as S
from verify.bounds import VerifyConfig
from verify.rows import Rows, Span
from verify.theorem2_rows import IntervalWindow

#: the modules whose import registers checks: a new check adds its module here
MODULES: tuple[str, ...] = ("verify.effort", "verify.demanded_effort")


@dataclass(frozen=True)
class CheckInput:
    """What a registered check reads.

    Attributes
    ----------
    scenario : Scenario
    df : verify.signals.Columns
        The trajectory (``trajectory.csv`` columns).
    gains : Gains or None
        The certified gains, when the run has them.
    config : VerifyConfig
    span : Span
        The output times and the tail window.
    windows : list of list of IntervalWindow
        Per follower, Theorem 2's intervals (:func:`verify.theorem2_rows.interval_windows`).
    """

    scenario: Scenario
    df: S.Frame
    gains: Gains | None
    config: VerifyConfig
    span: Span
    windows: list[list[IntervalWindow]]

    @property
    def view(self) -> S.TrajectoryView:
        """The trajectory's named blocks (:class:`verify.signals.TrajectoryView` of ``df``)."""
        return S.TrajectoryView.of(self.df)


RowBuilder = Callable[[Rows, CheckInput], None]
_CHECKS: list[RowBuilder] = []


def register_check(build: RowBuilder) -> RowBuilder:
    """Register ``build(rows, check_input)`` to add its rows to every bound table.

    Parameters
    ----------
    build : callable
        Appends rows of registered claims to ``rows`` (``Rows.add``); returns nothing.
    """
    if build not in _CHECKS:
        _CHECKS.append(build)
    return build


def registered_rows(R: Rows, inp: CheckInput) -> None:
    """Import :data:`MODULES` and add the rows of every registered check.

    Parameters
    ----------
    R : Rows
        Rows to append to.
    inp : CheckInput
        What the checks read.
    """
    for name in MODULES:
        importlib.import_module(name)
    for build in tuple(_CHECKS):
        build(R, inp)
