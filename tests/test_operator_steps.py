"""The recovery time after an operator step, on signals whose answer is known."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import PAPER

from verify.operator_steps import recovery_time, step_starts


def test_recovery_time_of_a_known_signal():
    t = np.round(np.arange(0.0, 10.0, 0.01), 10)
    dev = np.where((t >= 4.0) & (t < 5.3), 1.0, 0.01)  # off its slot from 4 s to 5.3 s
    assert recovery_time(t, dev, 4.0, 8.0, 0.05) == pytest.approx(1.3)
    assert recovery_time(t, dev, 6.0, 8.0, 0.05) == 0.0  # never above the level
    assert recovery_time(t, np.ones_like(t), 4.0, 8.0, 0.05) == math.inf  # never back
    with_nan = np.where(t < 5.0, np.nan, dev)  # undefined samples are skipped
    assert recovery_time(t, with_nan, 4.0, 8.0, 0.05) == pytest.approx(1.3)


def test_step_starts_merge_the_two_breakpoints_of_a_shaped_step():
    api = pytest.importorskip("generated.api")
    u0 = ["0.5*cos(t) + 1.2*step(t - 6) - 1.2*step(t - 9)"]
    raw = api.load(PAPER, {"leader.u0": u0}, variant="raw")
    shaped = api.load(PAPER, {"leader.u0": u0, "leader.u0_rise": 1.0}, variant="shaped")
    assert step_starts(raw) == [6.0, 9.0]
    assert step_starts(shaped) == [6.0, 9.0]  # breakpoints 6, 7, 9, 10
    assert step_starts(api.load(PAPER, None, variant="paper")) == []
