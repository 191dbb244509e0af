"""Gains designed for the guarantees (docs/synthesis.md, 'Design').

Independent truth: each GEVP's rate against the largest rate its answer admits, computed
as a generalised eigenvalue (no bisection, no solver), and against a solver-free search
over T; the unobservable mode's bound on δ2; the designed observer gains through the
certificate; the specification's refusals; the choice rule on hand-made points.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize

from core.errors import ScenarioError, run_cli
from core.overrides import load
from synthesis import design as SD
from synthesis.assumptions import uio_matrices

ROOT = Path(__file__).resolve().parents[1]
PAPER_DESIGN = ROOT / "scenarios" / "paper-design.toml"
A0 = np.array([[0.0, 1.0], [0.0, 0.0]])
B0 = np.array([[0.0], [1.0]])
C0 = np.array([[1.0, 1.0], [2.0, 2.0]])


def _search_lmi15(tau: float, lb1: float, starts: int = 12) -> float:
    """The largest lmi15_rate over T = τI + LLᵀ found by Nelder–Mead (no solver, no bisection)."""
    rng = np.random.default_rng(1)
    best = -math.inf

    def neg(x: np.ndarray) -> float:
        L = np.array([[x[0], 0.0], [x[1], x[2]]])
        return -SD.lmi15_rate(A0, B0, tau * np.eye(2) + L @ L.T, lb1)

    for _ in range(starts):
        x0 = rng.normal(0.0, np.sqrt(tau) * 3, 3)
        r = minimize(neg, x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12})
        best = max(best, -r.fun)
    return best


@pytest.mark.parametrize("q_max", [2.0, 10.0])
def test_lmi15_gevp_rate_is_the_largest_the_cap_admits(q_max):
    r = SD.design_lmi15(A0, B0, 1.0, q_max)
    # the answer admits its rate (eigenvalue check of the LMI at the returned T)
    assert SD.lmi15_rate(A0, B0, r.T, 1.0) >= r.delta
    assert np.linalg.eigvalsh(r.T).min() >= np.linalg.norm(B0, 2) / q_max
    assert np.linalg.norm(r.Q, 2) <= q_max
    assert r.delta == pytest.approx((1 - SD.RATE_BACKOFF) * r.delta_max)
    # no T of the constrained set does better than the bisection's rate (beyond its width)
    found = _search_lmi15(np.linalg.norm(B0, 2) / q_max, 1.0)
    assert found <= r.delta_max * (1 + 2 * SD.REL_TOL)
    assert found >= r.delta_max * (1 - 2 * SD.REL_TOL)  # and the search reaches it: it is tight


def test_lmi15_rate_grows_with_the_cap():
    rates = [SD.design_lmi15(A0, B0, 1.0, q).delta_max for q in (1.0, 4.0, 16.0)]
    assert rates[0] < rates[1] < rates[2]


def test_lmi16_gevp_rate_and_the_unobservable_mode():
    _, Phi = uio_matrices(B0, C0)
    r = SD.design_lmi16(Phi, A0, C0, 1.0)
    assert SD.lmi16_rate(Phi, A0, C0, r.Theta, r.Omega) >= r.delta
    assert np.linalg.norm(r.Theta, 2) <= 1.0
    assert np.linalg.eigvalsh(r.Omega).min() >= 1.0 - 1e-9
    # δ2 < −2 max Re λ(ΦA0 − ΘC0) for every Θ: the mode at −1 no Θ moves caps it at 2
    eig = np.linalg.eigvals(Phi @ A0 - r.Theta @ C0)
    assert r.delta <= -2 * eig.real.max() + 1e-9
    assert 1.9 < r.delta_max < 2.0


def test_given_Q_keeps_the_gain_and_its_rate_is_confirmed():
    Q = np.array([[35.4, 14.9]])
    r = SD.design_lmi15_given_Q(A0, B0, Q, 1.0)
    np.testing.assert_allclose(B0.T @ np.linalg.inv(r.T), Q, rtol=1e-6)
    assert SD.lmi15_rate(A0, B0, r.T, 1.0) >= r.delta
    # the scenario's δ1 = 0.5 is far inside what its Q admits
    assert r.delta_max > 4.0


def test_useful_rates():
    assert SD.useful_rates(1.0, 1.9) == (1.9, 2.0)
    assert SD.useful_rates(0.5, 1.9) == (1.0, 1.0)


def _design_text(extra: str) -> str:
    text = (ROOT / "scenarios" / "paper.toml").read_text()
    return text + "\n[design]\n" + extra


@pytest.mark.parametrize(
    ("extra", "key", "fix"),
    [
        ("g_min = 0.5\n", "design.u_max", "u_max = peak"),
        ("u_max = []\n", "design.u_max", "entries"),
        ("u_max = 200.0\ng_min = 0.0\n", "design.g_min", "a value > 0"),
        ("u_max = 200.0\ng_min = 1.5\n", "design.g_min", "0 < g_min <= 1"),
        ("u_max = 200.0\ng_min = -1.0\n", "design.g_min", "a value > 0"),
        ("u_max = 200.0\ng_min = 0.99\n", "design.g_min", "g_min <= 0.95"),
        ("u_max = 0.0\n", "design.u_max", "a value > 0"),
        ("u_max = 200.0\nbound_slack = 0.5\n", "design.bound_slack", ">= 1"),
        ("u_max = 200.0\nrobust_gain = 1.0\n", "design.robust_gain", "a factor > 1"),
        ("u_max = 200.0\nspeed = 1\n", "design", "speed"),
        # declared bounds must cover the scenario's own
        ("u_max = 226.0\nd = 1.0\n", "design.d", "d_ir >= each follower's d"),
        ("u_max = 226.0\nalpha = 1.0\n", "design.alpha", "alpha >= leader.alpha"),
    ],
)
def test_bad_specifications_are_refused_in_one_line(tmp_path, extra, key, fix):
    f = tmp_path / "bad.toml"
    f.write_text(_design_text(extra))
    with pytest.raises(ScenarioError) as exc:
        load(f)
    msg = str(exc.value)
    assert "\n" not in msg and key in msg and fix in msg, msg


def test_a_scenario_without_design_is_refused_by_design_run(capsys):
    from design.cli import main

    code = run_cli(main, ["run", str(ROOT / "scenarios" / "paper.toml")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "[design]" in err and "u_max" in err, err


def test_without_design_the_scenario_is_unchanged():
    sc = load(ROOT / "scenarios" / "paper.toml")
    assert sc.design is None


def test_the_projection_interval_of_a_design_holds_one():
    from design.controller import candidate_overrides

    sc = load(PAPER_DESIGN)
    for g_min in (0.2, 0.5, 0.95):
        ov = candidate_overrides(sc, 40.0, 40.0)
        ov["controller.g_min"] = g_min
        lo, hi = 1.0, 1.0 / ov["controller.g_min"]
        assert lo <= 1.0 <= hi


def test_balanced_gains_make_the_three_rates_equal():
    from design.controller import balanced
    from verify.bounds import theorem2_constants

    sc = load(PAPER_DESIGN)
    k2, sigma = balanced(sc, 40.0)
    ov = {
        "controller.k1": 40.0,
        "controller.k2": k2.tolist(),
        "controller.sigma": sigma.tolist(),
    }
    s2 = load(PAPER_DESIGN, ov, "balanced")
    c = theorem2_constants(s2, 0)
    assert c.provable
    # Ω = min{2λ_min(K)/λ_max(M), k2, σ}: all three equal
    assert 2 * 40.0 / c.lam_max_M == pytest.approx(k2[0]) == pytest.approx(c.Omega_var)


def _point(peak, tc, d1, holds=True):
    from design.controller import Point

    n = len(peak)
    return Point(
        "candidate", 1.0, 1.0, list(peak), list(tc), [1.0] * n, list(d1), 0.5, holds, True, True, {}
    )


def test_the_choice_rule_on_hand_made_points():
    from design.controller import choose

    a = _point([100, 100], [10, 10], [1.0, 1.0])  # slow, best bound
    b = _point([150, 300], [2, 2], [1.4, 1.4])  # faster, bound within 1.5x, 2 over budget
    c = _point([150, 150], [1, 1], [2.0, 2.0])  # fastest, bound beyond 1.5x
    d = _point([150, 150], [0.5, 0.5], [1.2, 1.2], holds=False)  # a failing row: never
    got = choose([a, b, c, d], np.array([200.0, 200.0]), 1.5)
    assert got[0] is b and got[1] is a
    assert choose([a, b, c], np.array([50.0, 200.0]), 1.5)[0] is None


def test_the_refusal_names_the_budget_and_what_would_work():
    from design.run import _refuse_budget

    sc = load(PAPER_DESIGN)
    pts = [_point([230.0] * 5, [1] * 5, [1.0] * 5), _point([240.0] * 5, [1] * 5, [1.0] * 5)]
    msg = str(_refuse_budget(sc, pts, 1))
    assert "\n" not in msg and "design.u_max" in msg and "u_max >= 230" in msg, msg


@pytest.mark.parametrize(
    ("lambda1", "lambda2", "phi", "u"),
    [(6.87, 2.0, 0.005, 2.0), (6.87, 4.0, 0.01, 2.0), (0.0, 4.0, 0.01, 2.0), (1.0, 3.0, 0.02, 1.2)],
)
def test_layer_residual_is_where_the_scalar_observer_error_settles(lambda1, lambda2, phi, u):
    """ė = u − λ1e − λ2e/(|e| + φ) (eq. (9)'s v against a constant unknown input, Q = B0 = 1)
    integrated to rest settles at layer_residual; with λ2 > u it is below φu/(λ2 − u)."""
    from scipy.integrate import solve_ivp

    def f(_t, e):  # noqa: ANN001, ANN202
        return u - lambda1 * e - lambda2 * e / (np.abs(e) + phi)

    sol = solve_ivp(f, (0.0, 50.0), [0.0], method="LSODA", rtol=1e-12, atol=1e-14)
    e_end = float(sol.y[0, -1])
    assert f(0.0, np.array([e_end]))[0] == pytest.approx(0.0, abs=1e-9)
    assert SD.layer_residual(lambda1, lambda2, phi, u) == pytest.approx(e_end, rel=1e-8)
    if lambda2 > u:
        assert e_end <= phi * u / (lambda2 - u) * (1 + 1e-9)
    else:  # λ2 = u: the linear term alone holds it, near sqrt(uφ/λ1)
        assert e_end == pytest.approx(np.sqrt(u * phi / lambda1), rel=0.1)


def test_the_robust_term_keeps_the_layer_slope_and_refuses_a_floor_at_phi0():
    """λ2 = robust_gain·α and φ_min scaled with it (λ2/φ_min is the scenario's); a floor that
    would reach φ_i(0) is refused in one line naming design.robust_gain."""
    from core.errors import SynthesisError

    sc = load(PAPER_DESIGN)
    r = SD.design_robust_term(sc.observer, 2.0, 3.0)
    assert r.lambda2 == pytest.approx(6.0)
    assert r.lambda2 / r.phi_min == pytest.approx(sc.observer.lambda2 / sc.observer.phi_min)
    assert (r.given_lambda2, r.given_phi_min) == (sc.observer.lambda2, sc.observer.phi_min)
    with pytest.raises(SynthesisError) as exc:
        SD.design_robust_term(sc.observer, 2.0, 500.0)  # φ_min = 2.5 > φ_i(0) = 1
    assert "design.robust_gain" in str(exc.value) and "\n" not in str(exc.value)


def test_designed_observer_gains_certify(monkeypatch):
    """The observer's designed keys go through synthesis and its whole certificate."""
    from synthesis.api import synthesize

    monkeypatch.setattr(SD, "FRONT_POINTS", 2)
    sc = load(PAPER_DESIGN)
    od = SD.observer_design(sc)
    assert od.delta1 > sc.observer.delta1 and od.delta2 > sc.observer.delta2
    g = synthesize(load(PAPER_DESIGN, od.overrides(), "designed"))
    assert g.certificate["passed"], g.certificate
    assert g.delta1 == pytest.approx(od.delta1) and g.delta2 == pytest.approx(od.delta2)
    assert g.lambda2 == pytest.approx(2.0 * sc.leader.alpha)  # design.robust_gain = 2


def test_a_stored_design_is_reused_only_for_its_own_scenario_and_procedure(tmp_path):
    import json

    from design.run import FORMAT, VARIANT, procedure_sha256, stored_overrides

    sc = load(PAPER_DESIGN)
    folder = tmp_path / f"{sc.name}-{VARIANT}"
    folder.mkdir()
    ov = {"observer.delta1": 1.5, "controller.k1": [40.0] * 5}
    rec = {
        "format": FORMAT,
        "scenario_sha256": sc.sha256,
        "procedure_sha256": procedure_sha256(),
        "overrides": ov,
    }
    (folder / "design.json").write_text(json.dumps(rec))
    assert stored_overrides(PAPER_DESIGN, {}, None, tmp_path) == ov
    # designed by another version of the procedure (e.g. before it chose γ): designed again
    (folder / "design.json").write_text(json.dumps({**rec, "procedure_sha256": "0" * 64}))
    assert stored_overrides(PAPER_DESIGN, {}, None, tmp_path) is None
    rec["scenario_sha256"] = "0" * 64  # written for another scenario (or an edited file)
    (folder / "design.json").write_text(json.dumps(rec))
    assert stored_overrides(PAPER_DESIGN, {}, None, tmp_path) is None
    (folder / "design.json").write_text("{not json")
    assert stored_overrides(PAPER_DESIGN, {}, None, tmp_path) is None


def test_the_design_keys_reach_the_command_line_unchanged():
    from core.overrides import parse_override
    from design.cli import _set_args

    ov = {
        "observer.Theta": [[0.19591445707, 0.391828914142], [0.003782872584, 0.007565745168]],
        "observer.lambda1": "synthesize",
        "controller.k1": [40.0, 40.0, 40.0, 40.0, 40.0],
        "controller.g_min": 0.5,
    }
    args = _set_args(ov)
    back = dict(parse_override(a) for a in args[1::2])
    assert back == ov


def test_a_budget_no_candidate_meets_is_refused_by_make_design(monkeypatch, tmp_path):
    """make_design's path to the refusal, with the simulations replaced by fixed points."""
    from design import run as R

    class _Obs:
        delta1 = delta2 = 1.0

        def overrides(self):
            return {}

    monkeypatch.setattr("synthesis.design.observer_design", lambda sc: _Obs())
    monkeypatch.setattr(R, "candidates", lambda sc: [(20.0, 40.0), (40.0, 40.0)])
    monkeypatch.setattr(R, "evaluate", lambda *a, **k: _point([225.4] * 5, [2.0] * 5, [1.0] * 5))
    f = tmp_path / "tight.toml"
    f.write_text(PAPER_DESIGN.read_text().replace("u_max = 226.0", "u_max = 100.0"))
    with pytest.raises(R.DesignError) as exc:
        R.make_design(f, out_root=tmp_path, progress=False)
    msg = str(exc.value)
    assert "\n" not in msg and "design.u_max: 100 for follower 1" in msg
    assert "use u_max >= 225.4" in msg, msg


def test_a_declared_disturbance_bound_reaches_theorem2s_constants(tmp_path):
    from design.controller import candidate_overrides
    from verify.bounds import theorem2_constants

    f = tmp_path / "d.toml"
    f.write_text(_design_text("u_max = 226.0\nd = 6.0\n"))
    sc = load(f)
    s2 = load(f, candidate_overrides(sc, 40.0, 40.0), "cand")
    np.testing.assert_array_equal(s2.followers[0].d, [6.0, 6.0])
    c = theorem2_constants(s2, 0)
    assert c.chi_v == pytest.approx(0.5 * s2.controller.k2[0] * 72.0)


def test_demo_passes_a_scenario_without_design_to_verify_unchanged(monkeypatch):
    import verify.__main__ as V
    from design.cli import demo

    seen = []
    monkeypatch.setattr(V, "main", lambda argv: seen.append(argv) or 0)
    args = [str(ROOT / "scenarios" / "paper.toml"), "--no-gif", "--set", "options.sign_width=0.04"]
    assert demo(args) == 0
    assert seen == [["demo", *args]]


def test_demo_runs_the_stored_design_of_a_design_scenario(monkeypatch, tmp_path):
    import json

    import verify.__main__ as V
    from design.cli import demo
    from design.run import FORMAT, VARIANT, procedure_sha256

    sc = load(PAPER_DESIGN)
    folder = tmp_path / f"{sc.name}-{VARIANT}"
    folder.mkdir()
    ov = {"observer.delta1": 1.5, "controller.k1": [40.0] * 5}
    rec = {
        "format": FORMAT,
        "scenario_sha256": sc.sha256,
        "procedure_sha256": procedure_sha256(),
        "overrides": ov,
    }
    (folder / "design.json").write_text(json.dumps(rec))
    seen = []
    monkeypatch.setattr(V, "main", lambda argv: seen.append(argv) or 0)
    assert demo([str(PAPER_DESIGN), "--out", str(tmp_path), "--no-gif"]) == 0
    argv = seen[0]
    assert argv[:5] == ["demo", str(PAPER_DESIGN), "--out", str(tmp_path), "--no-gif"]
    assert "observer.delta1=1.5" in argv and argv[-2:] == ["--variant", VARIANT]


def test_a_study_on_a_design_base_runs_its_designed_gains(monkeypatch, tmp_path):
    import design.run as R
    from sweep.sampler import make_sample
    from sweep.study import StudyError, load_study

    study = tmp_path / "s.toml"
    study.write_text(
        f'name = "s"\nbase = "{PAPER_DESIGN}"\ncount = 2\nseed = 1\n'
        '[set]\n"controller.Lambda" = 30.0\n'
    )
    monkeypatch.setattr(R, "OUT_ROOT", tmp_path)
    with pytest.raises(StudyError) as exc:  # no design yet: refused in one line
        load_study(study)
    assert "\n" not in str(exc.value) and "make design" in str(exc.value)
    _design_record(tmp_path, monkeypatch, {"controller.k1": [40.0] * 5, "controller.Lambda": 80.0})
    s = make_sample(load_study(study), 0).scenario
    assert np.all(s.controller.k1 == 40.0)
    assert np.all(s.controller.Lambda == 30.0)  # the study's own [set] wins


def _design_record(tmp_path, monkeypatch, overrides: dict) -> None:
    """A design.json of paper-design.toml with ``overrides``, where design.run reads it."""
    import json

    import design.run as R

    sc = load(PAPER_DESIGN)
    folder = tmp_path / f"{sc.name}-{R.VARIANT}"
    folder.mkdir(exist_ok=True)
    rec = {
        "format": R.FORMAT,
        "scenario_sha256": sc.sha256,
        "procedure_sha256": R.procedure_sha256(),
        "overrides": overrides,
    }
    (folder / "design.json").write_text(json.dumps(rec))
    monkeypatch.setattr(R, "OUT_ROOT", tmp_path)


def test_compare_gains_runs_the_same_draws_with_the_base_gains(monkeypatch, tmp_path):
    from sweep.sampler import make_sample
    from sweep.study import load_study

    _design_record(tmp_path, monkeypatch, {"controller.k1": [40.0] * 5, "controller.k2": 7.0})
    study = tmp_path / "s.toml"
    study.write_text(
        f'name = "s"\nbase = "{PAPER_DESIGN}"\ncount = 3\nseed = 1\ncompare_gains = true\n'
        '[set]\n"controller.k2" = 6.0\n'
        '[params]\n"followers[1].p0" = { uniform = [10.0, 30.0], size = 2 }\n'
    )
    s = load_study(study)
    assert s.compare_gains and s.designed == {"controller.k1": [40.0] * 5}
    given = s.given()
    assert given.fixed == {"controller.k2": 6.0} and not given.compare_gains
    paper = load(PAPER_DESIGN).controller
    for k in range(3):
        a, b = make_sample(s, k), make_sample(given, k)
        assert a.params == b.params  # the same draws
        assert np.all(a.scenario.controller.k1 == 40.0)
        assert np.array_equal(b.scenario.controller.k1, paper.k1)  # the base's own
        assert np.all(a.scenario.controller.k2 == 6.0) and np.all(b.scenario.controller.k2 == 6.0)


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ("compare_gains = 1\n", "is not a boolean"),
        ('compare_gains = "yes"\n', "is not a boolean"),
    ],
)
def test_bad_compare_gains_is_one_line(monkeypatch, tmp_path, body, says):
    from sweep.study import StudyError, load_study

    _design_record(tmp_path, monkeypatch, {})
    study = tmp_path / "s.toml"
    study.write_text(f'name = "s"\nbase = "{PAPER_DESIGN}"\ncount = 1\nseed = 1\n{body}')
    with pytest.raises(StudyError) as exc:
        load_study(study)
    assert (
        "\n" not in str(exc.value) and "compare_gains" in str(exc.value) and says in str(exc.value)
    )
    plain = tmp_path / "p.toml"
    plain.write_text(
        f'name = "p"\nbase = "{ROOT / "scenarios" / "paper.toml"}"\ncount = 1\nseed = 1\n'
        "compare_gains = true\n"
    )
    with pytest.raises(StudyError, match=r"compare_gains: needs a base with a \[design\] table"):
        load_study(plain)


@pytest.mark.parametrize("name", ["faults", "steps"])
def test_the_design_studies_draw_the_samples_of_the_paper_studies(stored_designs, name):
    """studies/<name>-design.toml: the samples of studies/<name>.toml on paper-design.toml
    (the same draws; the scenario tables equal but for the name, description and [design])."""
    from sweep.sampler import make_sample
    from sweep.study import load_study

    design = load_study(ROOT / "studies" / f"{name}-design.toml")
    paper = load_study(ROOT / "studies" / f"{name}.toml")
    assert design.compare_gains and design.count == paper.count and design.seed == paper.seed
    skip = {"name", "description", "design"}
    for k in (0, 1, paper.count - 1):
        a, b = make_sample(design, k), make_sample(paper, k)
        assert a.params == b.params
        assert {x: v for x, v in a.scenario_data.items() if x not in skip} == {
            x: v for x, v in b.scenario_data.items() if x not in skip
        }


def test_designed_per_follower_gains_follow_their_followers_on_random_graphs(monkeypatch, tmp_path):
    """A [graph] study on a design base: follower i of a drawn graph is a copy of the base's
    follower i mod 5 and takes its designed gains; the base's own gains beside it."""
    from sweep.sampler import make_sample
    from sweep.study import load_study

    lam, k2 = [80.0, 80.0, 40.0, 40.0, 40.0], [1.0, 2.0, 3.0, 4.0, 5.0]
    ov = {"controller.Lambda": lam, "controller.k2": k2, "followers[2].d": [5.0, 6.0]}
    _design_record(tmp_path, monkeypatch, ov)
    study = tmp_path / "s.toml"
    study.write_text(
        f'name = "s"\nbase = "{PAPER_DESIGN}"\ncount = 4\nseed = 1\ncompare_gains = true\n'
        "[graph]\nN = [2, 12]\nedge_probability = 0.2\n"
    )
    s = load_study(study)
    paper = load(PAPER_DESIGN).controller
    sizes = set()
    for k in range(4):
        a, b = make_sample(s, k).scenario, make_sample(s.given(), k).scenario
        sizes.add(a.N)
        for i in range(a.N):
            assert np.all(a.controller.Lambda[i] == lam[i % 5]) and a.controller.k2[i] == k2[i % 5]
            assert np.all(a.followers[i].d == [5.0, 6.0]) == (i % 5 == 1)
            assert np.all(b.controller.Lambda[i] == paper.Lambda[0])
            assert a.followers[i].b0.tolist() == b.followers[i].b0.tolist()
    assert min(sizes) < 5 < max(sizes)  # cut and repeated


def test_cyclic_keys_map_per_follower_keys_only():
    from sweep.graphs import cyclic_keys

    keys = {
        "controller.k1": [1.0, 2.0, 3.0],
        "controller.Lambda": [[1.0, 1.5], [2.0, 2.5], [3.0, 3.5]],
        "controller.g_min": 0.5,
        "controller.k2": 7.0,
        "observer.Theta": [[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]],
        "followers[3].d": [0.1, 0.2],
    }
    seven = cyclic_keys(keys, 3, 7)
    assert seven["controller.k1"] == [1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 1.0]
    assert seven["controller.Lambda"][4] == [2.0, 2.5] and len(seven["controller.Lambda"]) == 7
    for same in ("controller.g_min", "controller.k2", "observer.Theta"):
        assert seven[same] == keys[same]  # not one entry per follower
    assert {k for k in seven if k.startswith("followers")} == {"followers[3].d", "followers[6].d"}
    two = cyclic_keys(keys, 3, 2)
    assert two["controller.k1"] == [1.0, 2.0] and not any(k.startswith("followers") for k in two)
    assert cyclic_keys(keys, 3, 3) == keys


def test_given_gains_runs_the_base_gains_with_and_without_the_losses(monkeypatch, tmp_path):
    """compare_gains on a study with [graph.losses] baseline: the base's gains run the
    sample and its no-loss twin; their columns come back prefixed given:."""
    from sweep import worker as W
    from sweep.results import StudyPaths
    from sweep.sampler import make_sample
    from sweep.study import load_study

    _design_record(tmp_path, monkeypatch, {"controller.k1": [40.0] * 5})
    study = tmp_path / "s.toml"
    study.write_text(
        f'name = "s"\nbase = "{PAPER_DESIGN}"\ncount = 2\nseed = 3\ncompare_gains = true\n'
        "[graph]\nN = [5, 8]\nedge_probability = 0.2\n"
        "[graph.losses]\ncount = [1, 1]\ntime = { uniform = [3.0, 5.0] }\nbaseline = true\n"
    )
    s = load_study(study)
    seen = []

    def simulate(sample, paths, keep, study, row):
        seen.append(("run", float(sample.scenario.controller.k1[0, 0])))
        return {"peak_u_late": 1.0}

    def baseline(sample, paths, **engine):
        seen.append(("no losses", float(sample.scenario.controller.k1[0, 0])))
        return {"peak_u_late_nolosses": 2.0}

    monkeypatch.setattr(W, "_simulate_and_verify", simulate)
    monkeypatch.setattr(W, "link_baseline", baseline)
    out = W.given_gains(s, make_sample(s, 1), StudyPaths(tmp_path / "out"))
    k1 = float(load(PAPER_DESIGN).controller.k1[0, 0])
    assert seen == [("run", k1), ("no losses", k1)]
    assert out == {
        "given:peak_u_late": 1.0,
        "given:peak_u_late_nolosses": 2.0,
        "given:status": "ok",
    }


def test_gains_summary_counts_each_gain_set():
    """Hand-made results: two ok samples of two followers and a failed one, with the given
    gains' columns beside."""
    import pandas as pd

    from sweep.coverage import GIVEN, gains_lines, gains_summary

    nan = math.nan
    table = pd.DataFrame(
        {
            "id": [0, 1, 2],
            "status": ["ok", "ok", "failed: x"],
            "guaranteed_held": [True, False, nan],
            "coverage": [0.9, 0.8, nan],
            "ultimate_from:1": [2.0, 3.0, nan],
            "ultimate_from:2": [2.5, nan, nan],
            f"{GIVEN}status": ["ok", "ok", "ok"],
            f"{GIVEN}guaranteed_held": [True, True, True],
            f"{GIVEN}coverage": [0.4, 0.3, 0.35],
            f"{GIVEN}ultimate_from:1": [nan, 12.0, 13.0],
            f"{GIVEN}ultimate_from:2": [nan, nan, 14.0],
        }
    )
    d = gains_summary(table)
    assert (d["samples"], d["ok"], d["held"]) == (3, 2, 1)
    assert d["coverage_mean"] == pytest.approx(0.85) and d["coverage_min"] == 0.8
    assert (d["follower_samples"], d["ultimate"], d["all_ultimate"]) == (4, 3, 1)
    g = gains_summary(table, GIVEN)
    assert (g["ok"], g["held"], g["ultimate"], g["all_ultimate"]) == (3, 3, 3, 1)
    assert g["coverage_min"] == 0.3
    assert (d["from_median"], d["from_max"]) == (2.5, 3.0)
    assert (g["from_median"], g["from_max"]) == (13.0, 14.0)
    lines = gains_lines(table)
    assert lines[-2].startswith("| designed") and "| 3 of 4 (75.0%) | 1 of 2 |" in lines[-2]
    assert lines[-1].startswith("| given") and "| 30.0% |" in lines[-1]


def test_health_bound_is_the_worst_end_and_its_ghat_term_falls_like_one_over_gamma():
    """χ̄ over [g_min, 1]: the larger of the constant-health χ̄ at g_min and at 1 (the ĝ term
    is convex in g), and χ̄² is affine in 1/γ (only the ĝ term of χv holds γ)."""
    from design.controller import health_bound
    from verify.bounds import VerifyConfig, theorem2_constants

    inv, sq = [], []
    for gamma in (0.01, 0.1, 1.0):
        sc = load(PAPER_DESIGN, {"controller.gamma": gamma})
        ends = [theorem2_constants(sc, 2, VerifyConfig(), health=(g, g, 0.0)) for g in (0.5, 1.0)]
        assert health_bound(sc, 2) == pytest.approx(max(c.chi_bar_var for c in ends), rel=1e-12)
        inv.append(1.0 / gamma)
        sq.append(health_bound(sc, 2) ** 2)
    slope = (sq[1] - sq[0]) / (inv[1] - inv[0])
    assert slope > 0 and sq[2] == pytest.approx(sq[0] + slope * (inv[2] - inv[0]), rel=1e-9)


def test_the_gamma_choice_refuses_runs_that_stop_rows_that_fail_and_the_budget():
    from dataclasses import replace

    from design.controller import GammaPoint, choose_gamma

    base = _point([100, 100], [2, 2], [1.0, 1.0])
    own = GammaPoint([0.01, 0.01], base, [6.0, 6.0])
    mid = GammaPoint([0.1, 0.1], replace(base, peak=[100, 250]), [4.0, 4.0])  # 2 over budget
    best = GammaPoint([0.3, 0.3], replace(base, complete=False), [3.0, 3.0])  # its run stops
    bad = GammaPoint([1.0, 1.0], replace(base, holds=False), [2.0, 2.0])  # a failing row
    got = choose_gamma([own, mid, best, bad], np.array([200.0, 200.0]))
    assert got[0] is mid and got[1] is own
    same = GammaPoint([0.03, 0.03], base, [6.0, 6.0])  # a tie goes to the smaller gamma
    assert choose_gamma([same, own], np.array([200.0, 200.0])) == [own, own]
    assert choose_gamma([own], np.array([50.0, 200.0]))[0] is None


def test_a_failed_no_loss_twin_is_named_in_the_status(monkeypatch, tmp_path):
    """The sample's own run completes, its no-loss twin stops: the row says which failed."""
    from core.errors import IntegrationError
    from sweep import worker as W

    study = tmp_path / "s.toml"
    study.write_text(
        f'name = "s"\nbase = "{ROOT / "scenarios" / "paper.toml"}"\ncount = 1\nseed = 3\n'
        "[graph]\nN = [5, 6]\nedge_probability = 0.2\n"
        "[graph.losses]\ncount = [1, 1]\ntime = { uniform = [3.0, 5.0] }\nbaseline = true\n"
    )

    def twin(sample, paths, **engine):
        raise IntegrationError("native failed after t = 0 s")

    monkeypatch.setattr(W, "_simulate_and_verify", lambda *a: {"steps": 1})
    monkeypatch.setattr(W, "link_baseline", twin)
    row = W.run_sample(str(study), 0, str(tmp_path / "out"))
    assert row["status"].startswith("failed: no-loss twin: IntegrationError: native failed")
    assert row["steps"] == 1  # the sample's own columns stay


@pytest.mark.slow
def test_compare_gains_runs_the_base_gains_to_the_end(monkeypatch, tmp_path):
    """The given: run is a run like the sample's own: it completes and is verified (a run
    that raised was recorded as failed, and the report's given columns were left empty)."""
    from sweep.coverage import GIVEN
    from sweep.worker import run_sample

    _design_record(tmp_path, monkeypatch, {"controller.k1": [40.0] * 5})
    study = tmp_path / "s.toml"
    study.write_text(
        f'name = "s"\nbase = "{PAPER_DESIGN}"\ncount = 1\nseed = 1\ncompare_gains = true\n'
        '[set]\n"integration.horizon" = 2.0\n'
    )
    row = run_sample(str(study), 0, str(tmp_path / "out"))
    assert row["status"] == "ok" and row[f"{GIVEN}status"] == "ok"
    # both runs verified: rows evaluated, and the two gain sets are different runs
    assert row["guaranteed_held"] > 0 and row[f"{GIVEN}guaranteed_held"] > 0
    assert row[f"{GIVEN}steps"] != row["steps"]
