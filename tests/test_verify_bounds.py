"""Theorem 2 / Lemma 1 / Lemma 2 formulas and the bound-vs-actual table (no simulation).

The expected numbers are recomputed here by hand from docs/reading.md, 'Theorem 2 bounds', with
the two-link inertia matrix written out independently of the model library.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import PAPER
from hypothesis import given, settings
from hypothesis import strategies as st

from generated.api import load
from verify import signals as S
from verify.bounds import (
    VerifyConfig,
    VerifyError,
    comparison_reaching_time,
    layer_constant,
    lemma1_reaching_time,
    lemma2_bounds,
    theorem2_constants,
)
from verify.lyapunov import sgn_eps
from verify.synthetic import synthetic_trajectory
from verify.table import bounds_table, failures, to_markdown


@pytest.fixture(scope="module")
def paper(paper_scenario):
    return paper_scenario


def _two_link_eigs(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of the paper's printed M(p) as functions of c = cos p2 (section 3)."""
    m1, m2, r1, r2, J1, J2 = 0.5, 1.5, 1.0, 0.8, 5.0, 5.0
    m11 = (m1 + m2) * r1**2 + m2 * r2**2 + 2 * m2 * r1 * r2 * c + J1
    m12 = m2 * r2**2 + m2 * r1 * r2 * c
    m22 = m2 * r2**2 + J2
    tr, det = m11 + m22, m11 * m22 - m12**2
    disc = np.sqrt(tr**2 - 4 * det)
    return (tr - disc) / 2, (tr + disc) / 2


def _hand(paper, i: int, delta: float):
    c = np.linspace(-1.0, 1.0, 200001)  # every configuration: c = cos p2 covers [-1, 1]
    lo, hi = _two_link_eigs(c)
    lmin, lmax = lo.min(), hi.max()
    k1, k2, lam = 20.0, 1.0, 40.0  # Table 2
    d = np.asarray(paper.followers[i].d)
    Omega = min(2 * k1 / lmax, k2)
    chi_v = 0.5 * k2 * (d @ d)
    chi_bar = math.sqrt(2 * chi_v / (lmin * Omega * (1 - delta)))
    return lmin, lmax, Omega, chi_v, chi_bar, chi_bar / lam, 2 * chi_bar


def test_mass_bounds_are_the_configuration_extremes(paper):
    lo, hi = _two_link_eigs(np.linspace(-1, 1, 200001))
    c = theorem2_constants(paper, 0)
    assert c.lam_min_M == pytest.approx(lo.min(), rel=1e-12)
    assert c.lam_max_M == pytest.approx(hi.max(), rel=1e-12)
    assert c.lam_min_M == pytest.approx(5.0769, abs=1e-4)  # docs/reading.md: about 5.08
    assert c.lam_max_M == pytest.approx(11.2431, abs=1e-4)  # and 11.24


@pytest.mark.parametrize("delta", [0.5, 0.2])
def test_theorem2_constants_match_hand_computation(paper, delta):
    cfg = VerifyConfig(lemma1_delta=delta)
    for i in range(paper.N):
        lmin, lmax, Omega, chi_v, chi_bar, e_bar, ed_bar = _hand(paper, i, delta)
        c = theorem2_constants(paper, i, cfg)
        assert c.Omega == pytest.approx(Omega, rel=1e-12)
        assert c.chi_v == pytest.approx(chi_v, rel=1e-12)
        assert c.chi_bar == pytest.approx(chi_bar, rel=1e-10)
        np.testing.assert_allclose(c.e_bar, [e_bar, e_bar], rtol=1e-10)
        np.testing.assert_allclose(c.edot_bar, [ed_bar, ed_bar], rtol=1e-10)
    # follower 1: f = 4 sin 2t + 1 on both components -> d = (5, 5), Ω = 1 (k2 binds)
    assert np.allclose(paper.followers[0].d, 5.0, atol=1e-3)
    assert theorem2_constants(paper, 0).Omega == 1.0


def _variant(law: str):
    return load(PAPER, {"options.ghat_law": law}, variant=f"test-{law}")


def _layer_by_grid(sign: str) -> float:
    """sup_x (|x| − x sgn_1(x)) on a fine grid (independent of the bisection in bounds.py)."""
    x = np.linspace(0.0, 10.0, 2_000_001)
    s = np.tanh(x) if sign == "tanh" else np.clip(x, -1.0, 1.0)
    return float(np.max(x - x * s))


@pytest.mark.parametrize("sign, known", [("tanh", 0.2785), ("sat", 0.25)])
def test_layer_constant_is_the_sup_of_the_slack(sign, known):
    assert layer_constant(sign) == pytest.approx(_layer_by_grid(sign), abs=1e-10)
    assert layer_constant(sign) == pytest.approx(known, abs=5e-5)
    assert layer_constant("exact") == 0.0


@settings(max_examples=200, deadline=None)
@given(st.floats(-50.0, 50.0), st.sampled_from(["tanh", "sat"]), st.floats(1e-3, 1.0))
def test_layer_slack_never_exceeds_c_eps(chi, sign, eps):
    slack = abs(chi) - chi * float(sgn_eps(np.array(chi), sign, eps))
    assert -1e-15 <= slack <= layer_constant(sign) * eps + 1e-15


def _layer_term(sc, i: int) -> float:
    c_eps = _layer_by_grid(sc.options.sign) * sc.options.sign_width
    return sc.n * c_eps**2 / (2.0 * float(sc.controller.k2[i]))


def test_projection_variant_adds_the_bounded_ghat_term():
    sc = _variant("projection")
    c = theorem2_constants(sc, 0)
    g, gmin, gam = 0.95, sc.controller.g_min, float(sc.controller.gamma[0])
    band = 0.01 * (1 / gmin - 1)  # ĝ stays in [1 − band, 1/g_min + band]
    Wg = g / (2 * gam) * max(1 / g - (1 - band), 1 / gmin + band - 1 / g) ** 2
    assert c.provable
    assert c.Omega_var == c.Omega
    expected = c.chi_v + c.Omega * Wg + _layer_term(sc, 0)
    assert c.chi_v_var == pytest.approx(expected, rel=1e-9)
    assert c.chi_bar_var > c.chi_bar


def test_projection_variant_is_not_provable_with_ghat_starting_outside():
    sc = load(PAPER, {"options.ghat_law": "projection", "initial.ghat": 2.5}, variant="t")
    c = theorem2_constants(sc, 0)
    assert not c.provable and "initial.ghat" in c.why_not


def test_sigma_variant_constants():
    sc = _variant("sigma")
    c = theorem2_constants(sc, 1)
    g, gam = 0.95, float(sc.controller.gamma[1])
    sig, g0 = float(sc.controller.sigma[1]), float(sc.controller.ghat_ref[1])
    assert c.provable
    assert c.Omega_var == pytest.approx(min(c.Omega, sig))
    expected = c.chi_v + sig * g * (1 / g - g0) ** 2 / (2 * gam) + _layer_term(sc, 1)
    assert c.chi_v_var == pytest.approx(expected, rel=1e-9)


def test_paper_law_is_not_provable():
    c = theorem2_constants(_variant("paper"), 0)
    assert not c.provable and c.chi_bar_var == c.chi_bar


def test_lemma2_second_order():
    b = lemma2_bounds(3.0, 40.0, 2)
    np.testing.assert_allclose(b, [3.0 / 40.0, 6.0])
    np.testing.assert_allclose(lemma2_bounds(1.0, 2.0, 3), [1 / 4, 1.0, 4.0])


@settings(max_examples=200, deadline=None)
@given(
    lam=st.floats(0.05, 20),
    omega=st.floats(1e-3, 1e3),
    a=st.floats(1.0001, 1e6),
    delta=st.floats(0.01, 0.99),
)
def test_lemma1_tf_bounds_the_worst_case_hitting_time(lam, omega, a, delta):
    """V' = -λV + ω exactly (the worst case) hits ω/(λ(1-δ)) no later than Lemma 1's t_f."""
    V0 = a * omega / (lam * (1 - delta))  # start outside the level
    level = omega / (lam * (1 - delta))
    # exact solution V(t) = ω/λ + (V0 - ω/λ) e^{-λt}
    t_hit = math.log((V0 - omega / lam) / (level - omega / lam)) / lam
    tf = lemma1_reaching_time(lam, omega, V0, delta)
    tc = comparison_reaching_time(lam, omega, V0, delta)
    assert tf >= t_hit * (1 - 1e-9) - 1e-12
    assert tc >= t_hit * (1 - 1e-9) - 1e-12


def test_lemma1_inside_already():
    assert lemma1_reaching_time(1.0, 10.0, 1.0, 0.5) == 0.0


def test_verify_config_rejects_bad_delta():
    with pytest.raises(VerifyError, match="lemma1_delta"):
        VerifyConfig(lemma1_delta=1.0)


def test_signals_enter_time_and_decay_rate():
    t = np.linspace(0, 10, 1001)
    y = 3.0 * np.exp(-0.7 * t)
    assert S.decay_rate(t, y) == pytest.approx(0.7, rel=1e-10)
    te = S.enter_time(t, y, 1e-2)
    exact = math.log(300) / 0.7
    assert exact <= te <= exact + 0.01 + 1e-12
    assert S.enter_time(t, np.ones_like(t), 0.5) == math.inf
    assert S.enter_time(t, np.zeros_like(t), 0.5) == 0.0


def test_table_on_synthetic_trajectory(paper):
    df = synthetic_trajectory(obs_rate=1.0, track_rate=2.0)
    ab = synthetic_trajectory(track_rate=1.0)
    tb = bounds_table(paper, df, ablation=ab)
    assert list(tb.columns[:4]) == ["claim", "agent", "component", "kind"]
    # one Theorem-2 row per agent × component for the |e_t| claim
    et_rows = tb[tb["claim"].str.startswith("T2 |e_ti,r| <= chi_bar/lambda_ir (31)")]
    assert len(et_rows) == paper.N * paper.n
    for i in range(paper.N):
        _, _, _, _, chi_bar, e_bar, _ = _hand(paper, i, 0.5)
        row = tb[
            (tb["claim"] == "T2 |chi_si| <= chi_bar_si (31), paper") & (tb["agent"] == str(i + 1))
        ]
        assert row["bound"].item() == pytest.approx(chi_bar, rel=1e-10)
        sub = et_rows[et_rows["agent"] == str(i + 1)]
        np.testing.assert_allclose(sub["bound"], e_bar, rtol=1e-10)
        # observed = sup over the tail [10, 20] of |e_t,r| = |c_r| e^{-2·10}
        ce = np.array([5.0 + i, -3.0 + 0.5 * i])
        np.testing.assert_allclose(sub["observed"], np.abs(ce) * math.exp(-20), rtol=1e-9)
    # Fig. 13 rows: the synthetic ablation decays at half the rate -> enters twice as late
    fig13 = tb[tb["claim"].str.startswith("Fig. 13: time")]
    np.testing.assert_allclose(fig13["ratio"], 2.0, rtol=0.01)
    # the synthetic data satisfy every bound: no failures even when strict
    assert failures(tb, strict=True).empty
    md = to_markdown(tb)
    assert md.count("\n") == len(tb) + 1


def test_table_reports_a_violated_claim(paper):
    df = synthetic_trajectory()
    # an error growing to 1 rad on the tail, far above χ̄/λ ≈ 0.11 and above its start value
    df["et1_1"] = df["et1_1"] + np.clip((df["t"] - 10.0) / 10.0, 0.0, None)
    tb = bounds_table(paper, df)
    bad = failures(tb, strict=True)
    assert ((bad["agent"] == "1") & (bad["component"] == "1")).any()
    # the provable (projection-law) bound is a guaranteed row: it fails without --strict too
    loose = failures(tb, strict=False)
    assert (loose["claim"].str.contains("provable variant") & (loose["agent"] == "1")).any()
    assert (loose["kind"] == "guaranteed").all()


def test_table_rejects_mismatched_trajectory(paper):
    df = synthetic_trajectory(N=3)
    with pytest.raises(VerifyError, match="N=3"):
        bounds_table(paper, df)
