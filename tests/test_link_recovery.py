"""What keeps a (graph switch, follower) pair out (verify.link_recovery): the deviation's
observer and controller parts on synthetic trajectories whose parts are known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import PAPER

from core.scenario import load_scenario
from verify.link_recovery import switch_recoveries, switch_summary
from verify.signals import Signal
from verify.synthetic import synthetic_trajectory

ANCHOR = "pinning = [1.0, 0.0, 0.0, 0.0, 0.0]\n"


def _scenario(tmp_path, t_loss: float, t_back: float):
    """paper.toml with follower 4 losing follower 2 at ``t_loss``, hearing it from ``t_back``."""
    tables = "".join(
        f"[[graph.switches]]\ntime = {t}\nfollower = 4\nneighbour = 2\nweight = {w}\n"
        for t, w in ((t_loss, 0.0), (t_back, 1.0))
    )
    text = PAPER.read_text()
    assert text.count(ANCHOR) == 1
    path = tmp_path / "s.toml"
    path.write_text(text.replace(ANCHOR, ANCHOR + "\n" + tables))
    return load_scenario(path)


def test_an_observer_that_converges_slowly_keeps_the_pairs_out(tmp_path):
    """synthetic_trajectory: e_ti = ce_i e^{-2t} (controller), η_i − η0 = c_i e^{-t/2} with
    the exact b_i (observer: ‖C0 c_i‖ e^{-t/2}); switches at 1.0 and 1.5 s."""
    sc = _scenario(tmp_path, 1.0, 1.5)
    df = synthetic_trajectory(horizon=8.0, obs_rate=0.5, track_rate=2.0)
    items = switch_recoveries(sc, df, np.ones(sc.N))
    t = df["t"].to_numpy()
    k = int(np.searchsorted(t, 1.5 + 2.0 - 1e-9))  # decaying: the worst after the limit
    for r in items:
        i = r.follower
        assert r.own == (i == 3)  # follower 4's own link switched, both times
        if r.start == 1.0:  # a window shorter than the limit: its own worst
            assert r.outcome == "undefined" and not math.isnan(r.within)
            continue
        c = np.array([1.0 + 0.2 * i, -0.5 + 0.1 * i])
        ce = np.array([5.0 + i, -3.0 + 0.5 * i])
        C0 = np.array([[1.0, 1.0], [2.0, 2.0]])
        assert r.observer == pytest.approx(np.linalg.norm(C0 @ c) * math.exp(-0.5 * t[k]), 1e-6)
        assert r.controller == pytest.approx(np.linalg.norm(ce) * math.exp(-2 * t[k]), 1e-6)
        assert r.out and r.within > 0.05 and r.observer > r.controller
    s = switch_summary(items)
    assert s["switch_out_own"] == 2 and s["switch_out_within"] == 0
    assert s["switch_out_observer"] == sum(r.observer > r.controller for r in items if r.out)
    assert s["switch_out_worst_max"] == max(r.worst for r in items if r.out)


def test_a_late_excursion_of_the_controller_counts_within_the_limit(tmp_path):
    """Fast observer and controller, then a 0.1 bump of e_t1 (and p_1) at 5-5.5 s: follower 1
    was back for the whole limit after the 2.6 s switch and out only later, by its controller."""
    sc = _scenario(tmp_path, 2.5, 2.6)
    df = synthetic_trajectory(horizon=8.0, obs_rate=3.0, track_rate=2.0)
    t = df["t"].to_numpy()
    bump = np.where((t >= 5.0) & (t <= 5.5), 0.1, 0.0)
    for sig in (Signal.P, Signal.ET):
        df[sig.column(1, 1)] += bump
    items = switch_recoveries(sc, df, np.ones(sc.N))
    (r,) = [r for r in items if r.start == 2.6 and r.follower == 0]
    assert r.outcome == "late" and r.within <= 0.05 and r.worst == pytest.approx(0.1, abs=1e-3)
    assert r.controller == pytest.approx(0.1, abs=1e-3) and r.observer < 1e-3
    others = [x for x in items if x.start == 2.6 and x.follower != 0]
    assert not any(x.out for x in others)
    s = switch_summary(items)
    assert s["switch_out_within"] == 1 and s["switch_out_observer"] == 0
