"""The effort a slot demands (verify/demanded_effort.py) against independent truth: the
two-link arm's closed forms, an analytic slot, and the torques the closed loop logged."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from helpers import PAPER, two_link_closed_form

from core.models import REGISTRY
from verify import demanded_effort as DE

ARM = REGISTRY["two_link"].defaults


def closed_form_torque(p, q, a, prm=ARM):
    """M a + C q + G of the arm, from the closed forms of docs/reading.md ('Followers')."""
    M, C, G = two_link_closed_form(p, q, **prm)
    return M @ a + C @ q + G


def test_inverse_dynamics_is_the_arm_of_the_closed_forms():
    fn = DE.inverse_dynamics("two_link", tuple(sorted(ARM.items())))
    rng = np.random.default_rng(3)
    for _ in range(20):
        p, q, a = rng.uniform(-4, 4, (3, 2))
        got = np.asarray(fn(p, q, a)).ravel()
        np.testing.assert_allclose(got, closed_form_torque(p, q, a), rtol=1e-12, atol=1e-12)


def test_demanded_effort_of_an_analytic_slot(paper_scenario, monkeypatch):
    # the slot replaced by s(t) = (sin t, 0.5 cos 2t): u* = (M s̈ + C ṡ + G − f)/g in closed
    # form; the module differentiates s numerically on the output grid
    t = np.linspace(0.0, 6.0, 601)
    s = np.stack([np.sin(t), 0.5 * np.cos(2 * t)], 1)
    sd = np.stack([np.cos(t), -np.sin(2 * t)], 1)
    sdd = np.stack([-np.sin(t), -2 * np.cos(2 * t)], 1)
    sc = paper_scenario
    monkeypatch.setattr(DE, "slots", lambda scenario, df, h: np.repeat(s[:, None], sc.N, 1))
    got = DE.demanded_effort(sc, pd.DataFrame({"t": t}), np.ones(sc.N))
    for i, fo in enumerate(sc.followers):
        assert fo.model == "two_link"
        prm = {**ARM, **fo.params}
        tau = np.array([closed_form_torque(s[k], sd[k], sdd[k], prm) for k in range(len(t))])
        f = np.stack([np.broadcast_to(e.numpy(t), t.shape) for e in fo.f], 1)
        g = np.broadcast_to(fo.g.expr.numpy(t), t.shape)
        want = np.linalg.norm((tau - f) / g[:, None], axis=1)
        # second-order differences twice (one-sided at the ends): error O(h²) everywhere
        np.testing.assert_allclose(got[:, i], want, rtol=1e-2)  # one-sided: larger constant
        np.testing.assert_allclose(got[3:-3, i], want[3:-3], rtol=2e-4)


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory):
    api = pytest.importorskip("generated.api")
    root = tmp_path_factory.mktemp("out")
    res = api.run(PAPER, variant="test-demanded-effort", out_root=root, progress=False)
    return api.load(PAPER), res.frame


def test_on_the_closed_loop_the_logged_torque_is_the_demanded_one(paper_run):
    # once the followers sit on their slots, eq. (2) leaves them the demanded torque: the
    # controller's logged u_i must agree with u_i* (an independent computation: slot and
    # model only, no controller quantity)
    sc, df = paper_run
    from verify.theorem2_rows import gauge

    t = df["t"].to_numpy()
    demand = DE.demanded_effort(sc, df, gauge(sc))
    late = t >= 5.0
    for i in range(sc.N):
        u = np.linalg.norm(df[[f"u{i + 1}_1", f"u{i + 1}_2"]].to_numpy(), axis=1)
        rel = np.abs(u[late] - demand[late, i]) / demand[late, i]
        assert np.median(rel) < 0.02, (i, np.median(rel))
        assert abs(u[late].max() - demand[late, i].max()) < 0.05 * demand[late, i].max()
