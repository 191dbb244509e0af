"""Certified synthesis on the paper's scenario: LMIs re-checked by eigenvalues, assumptions."""

from __future__ import annotations

from dataclasses import replace

import cvxpy as cp
import numpy as np
import pytest
from helpers import ROOT

from core.errors import SynthesisError
from core.graph import check_network
from core.scenario import Graph, load_scenario
from synthesis import certify, synthesize
from synthesis.assumptions import (
    check_leader,
    control_zeros,
    invariant_zeros,
    system_pencil,
    uio_matrices,
    uio_zeros,
)
from synthesis.certificate import k1_bound
from synthesis.lmi import min_lambda_bar1_for_Q, synth_T

A0 = np.array([[0.0, 1.0], [0.0, 0.0]])
B0 = np.array([[0.0], [1.0]])
C0 = np.array([[1.0, 1.0], [2.0, 2.0]])
Q_PAPER = np.array([[35.4, 14.9]])


@pytest.fixture(scope="module")
def paper():
    return load_scenario(ROOT / "scenarios" / "paper.toml")


@pytest.fixture(scope="module")
def paper_synth():
    return load_scenario(ROOT / "scenarios" / "paper-synth.toml")


@pytest.fixture(scope="module")
def g_paper(paper):
    return synthesize(paper)


@pytest.fixture(scope="module")
def g_synth(paper_synth):
    return synthesize(paper_synth)


def _lmax(M):
    return np.linalg.eigvalsh(0.5 * (M + M.T))[-1]


def _lmin(M):
    return np.linalg.eigvalsh(0.5 * (M + M.T))[0]


# --------------------------------------------------------------------------- UIO / Assumption 2
def test_uio_matrices_analytic():
    Gamma, Phi = uio_matrices(B0, C0)
    # docs/reading.md, 'Unknown-input observer': Γ = B0 (C0B0)ᵀ/5, Φ = [[1, 0], [-1, 0]], ΦA0 = [[0, 1], [0, -1]]
    np.testing.assert_allclose(Gamma, [[0, 0], [0.2, 0.4]], atol=1e-15)
    np.testing.assert_allclose(Phi, [[1, 0], [-1, 0]], atol=1e-15)
    np.testing.assert_allclose(Phi @ A0, [[0, 1], [0, -1]], atol=1e-15)
    np.testing.assert_allclose(Phi @ B0, 0, atol=1e-15)


def test_paper_zero_is_minus_one_and_pencil_drops_rank():
    lc = check_leader(A0, B0, C0)
    assert lc.zeros.shape == (1,)
    assert abs(lc.zeros[0] - (-1.0)) < 1e-9
    # independent: the 4x3 pencil has rank 2 at s = -1 and rank 3 elsewhere
    assert np.linalg.matrix_rank(system_pencil(A0, B0, C0, -1.0)) == 2
    assert np.linalg.matrix_rank(system_pencil(A0, B0, C0, 0.37)) == 3
    assert "agrees" in lc.cross_check


@pytest.mark.parametrize("C", [[[1.0, -1.0], [2.0, -2.0]], [[1.0, -1.0], [-2.0, 2.0]]])
def test_unstable_invariant_zero_rejected_by_name(C):
    with pytest.raises(SynthesisError, match=r"Assumption 2 fails: invariant zero\(s\) 1 "):
        check_leader(A0, B0, np.array(C))


def test_rank_condition_rejected():
    with pytest.raises(SynthesisError, match=r"rank\(C0 B0\) = 0"):
        check_leader(A0, B0, np.array([[1.0, 0.0]]))


def test_zeros_match_python_control_on_square_systems():
    rng = np.random.default_rng(7)
    for _ in range(60):
        m, p = int(rng.integers(2, 6)), int(rng.integers(1, 3))
        A, B, C = (
            rng.standard_normal((m, m)),
            rng.standard_normal((m, p)),
            rng.standard_normal((p, m)),
        )
        z, cz = invariant_zeros(A, B, C), control_zeros(A, B, C)
        assert len(z) == len(cz)
        for s in z:
            assert np.min(np.abs(cz - s)) < 1e-6 * (1 + abs(s))


def test_tall_system_with_known_zeros():
    # square SISO system with zeros at -2 and -3 (numerator s² + 5s + 6), then a repeated output
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -3.0, -3.0]])
    B = np.array([[0.0], [0.0], [1.0]])
    C = np.array([[6.0, 5.0, 1.0]])
    z = invariant_zeros(A, B, np.vstack([C, 2 * C]))
    np.testing.assert_allclose(np.sort(z.real), [-3.0, -2.0], atol=1e-7)
    # an independent second output removes both zeros (a generic tall system has none)
    assert invariant_zeros(A, B, np.vstack([C, [[1.0, 0.0, 0.0]]])).size == 0


# --------------------------------------------------------------------------- Assumption 1
def test_unreachable_follower_rejected_by_name(paper):
    A = np.array(paper.graph.adjacency)
    A[4, 3] = 0.0  # follower 5 loses its only in-edge
    with pytest.raises(SynthesisError, match=r"follower\(s\) 5 cannot be reached"):
        check_network(A, paper.graph.pinning)
    with pytest.raises(SynthesisError, match=r"follower\(s\) 5 cannot be reached"):
        synthesize(replace(paper, graph=Graph(adjacency=A, pinning=paper.graph.pinning)))


def test_paper_L_bar_and_lemma3_z(g_paper):
    # the chosen DAG: leader -> 1, 1 -> 2, 1 -> 3, {2, 3} -> 4, 4 -> 5
    L = np.array(
        [
            [1, 0, 0, 0, 0],
            [-1, 1, 0, 0, 0],
            [-1, 0, 1, 0, 0],
            [0, -1, -1, 2, 0],
            [0, 0, 0, -1, 1],
        ],
        dtype=float,
    )
    np.testing.assert_array_equal(g_paper.L_bar, L)
    v = g_paper.info["lemma3"]["variants"]
    np.testing.assert_allclose(v["lemma3"]["z"], [5, 2, 2, 1, 1], rtol=1e-12)  # by hand
    assert v["best"]["w"] >= v["lemma3"]["w"]
    assert g_paper.w == pytest.approx(max(v["best"]["w"], v["lemma3"]["w"]))


# --------------------------------------------------------------------------- LMIs, by eigenvalues
@pytest.mark.parametrize("which", ["g_paper", "g_synth"])
def test_lmis_rechecked_by_eigenvalues(which, request):
    g = request.getfixturevalue(which)
    tol = g.info["solver_tol"]
    T, Om = g.T, g.Omega
    np.testing.assert_allclose(T, T.T, atol=0)
    assert _lmin(T) > tol and _lmin(Om) > tol
    F15 = A0 @ T + T @ A0.T - g.lambda_bar1 * B0 @ B0.T + g.delta1 * T
    assert _lmax(F15) < -tol
    np.testing.assert_allclose(B0.T @ np.linalg.inv(T), g.Q, rtol=1e-6)
    Ac = g.Phi @ A0 - g.Theta @ C0
    F16 = Ac.T @ Om + Om @ Ac + g.delta2 * Om
    assert _lmax(F16) < -tol
    ev = np.linalg.eigvals(Ac)
    assert ev.real.max() < -g.delta2 / 2  # LMI (16) => decay rate δ2/2
    # the unobservable mode at -1 survives every Θ (docs/reading.md, 'Unknown-input observer')
    assert np.min(np.abs(ev + 1.0)) < 1e-9
    # Lemma 3 inequality and Theorem 1's gains
    Z = g.Z
    S = g.L_bar.T @ Z + Z @ g.L_bar
    assert _lmin(S - g.w * Z) > -1e-9
    assert g.lambda1 * g.w > g.lambda_bar1
    assert g.lambda2 >= g.alpha


def test_paper_gains_kept_and_certificate_clean(g_paper):
    np.testing.assert_array_equal(g_paper.Q, Q_PAPER)
    assert g_paper.lambda1 == 1.9 and g_paper.lambda2 == 2.0
    assert sorted(g_paper.info["given"]) == ["Q", "lambda1", "lambda2"]
    cert = g_paper.certificate
    assert not cert["failures"]
    assert all(c["passed"] for c in cert["checks"])


def test_synth_scenario_no_warnings(g_synth):
    cert = g_synth.certificate
    assert cert["passed"] and not cert["warnings"] and not cert["failures"]
    assert g_synth.info["given"] == []
    assert g_synth.lambda1 > g_synth.lambda_bar1 / g_synth.w


def test_k1_against_explicit_kronecker(g_paper):
    # second implementation: the (N·m)x(N·m) matrix of eq. (17)'s k1, built literally
    g = g_paper
    N = g.Z.shape[0]
    X = g.Phi @ g.A0 - g.Theta @ g.C0 - g.A0
    Ebar = np.kron(g.Z @ g.H, np.linalg.inv(g.T) @ X)
    M = (
        np.kron(np.eye(N), np.linalg.inv(g.Omega))
        @ Ebar.T
        @ np.kron(np.linalg.inv(g.Z), g.T)
        @ Ebar
    )
    lam = np.linalg.eigvals(M).real.max()
    assert k1_bound(g) == pytest.approx(lam / (g.delta1_hat * g.delta2_hat), rel=1e-8)
    assert g.k1 > k1_bound(g)


# --------------------------------------------------------------------------- given Q
def _lb1_min_analytic(q1: float, q2: float, d1: float) -> float:
    """Smallest λ̄1 for which some p gives F(P) ≺ 0, P = [[p, q1], [q1, q2]] ≻ 0 (ε = 0).

    F = [[δ1p − λq1², p − λq1q2 + δ1q1], [·, 2q1 − λq2² + δ1q2]]; for 2x2, F ≺ 0 iff
    F22 < 0 and det F > 0, a concave quadratic in p: feasible iff it is positive
    somewhere on (q1²/q2, λq1²/δ1). Bisection on λ.
    """

    def feasible(lam: float) -> bool:
        b = 2 * q1 - lam * q2**2 + d1 * q2
        if b >= 0:
            return False
        a, c = lam * q1**2, -lam * q1 * q2 + d1 * q1
        lo, hi = q1**2 / q2, a / d1
        if lo >= hi:
            return False
        # det(p) = (δ1 p − a) b − (p + c)², maximised at p* = (δ1 b − 2c)/2, clipped
        pstar = min(max((d1 * b - 2 * c) / 2, lo), hi)
        return (d1 * pstar - a) * b - (pstar + c) ** 2 > 0

    lo, hi = 0.0, 10.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if feasible(mid) else (mid, hi)
    return hi


def test_given_Q_feasible_range_matches_analytic():
    for d1 in (0.1, 0.5, 1.0):
        exact = _lb1_min_analytic(35.4, 14.9, d1)
        solver = min_lambda_bar1_for_Q(A0, B0, Q_PAPER, d1)
        # the solver keeps a margin ε = 1e-6, so it sits just above the exact bound
        assert exact <= solver <= exact * (1 + 1e-4) + 1e-6
    assert _lb1_min_analytic(35.4, 14.9, 0.5) == pytest.approx(0.35246, abs=1e-4)


def test_given_gains_violations_are_named_warnings(paper):
    obs = replace(paper.observer, lambda1=0.3, lambda_bar1=0.2)  # the given Q needs λ̄1 > 0.352
    g = synthesize(replace(paper, observer=obs))
    names = {w.split(":")[1].strip() for w in g.certificate["warnings"]}
    assert "lmi15" in names  # λ̄1 = 0.2 < 0.352: the given Q fails LMI (15)
    assert not g.certificate["failures"]
    with pytest.raises(SynthesisError, match=r"\(strict\).*lmi15"):
        synthesize(replace(paper, observer=obs), strict=True)
    obs2 = replace(paper.observer, lambda1=0.1)  # λ1 w = 0.14 < λ̄1 = 1
    g2 = synthesize(replace(paper, observer=obs2))
    assert any("lambda1:" in w for w in g2.certificate["warnings"])


def test_lmi16_infeasible_for_delta2_above_two(paper_synth):
    # the unobservable mode at -1 caps the decay: δ2 < 2 (docs/reading.md, 'Unknown-input observer')
    obs = replace(paper_synth.observer, delta2=2.2, delta2_hat=0.5)
    with pytest.raises(SynthesisError, match=r"LMI \(16\) is infeasible"):
        synthesize(replace(paper_synth, observer=obs))


def test_printed_lmi15_transposes_infeasible():
    # deviation 9.7: A0ᵀT + TA0 − λ̄1B0B0ᵀ + δ1T ≺ 0 has (1,1) entry δ1·T11 > 0
    T = cp.Variable((2, 2), symmetric=True)
    S = cp.Variable((2, 2), symmetric=True)
    F = A0.T @ T + T @ A0 - 1.0 * B0 @ B0.T + 0.5 * T
    prob = cp.Problem(cp.Minimize(0), [S == -F, S >> 1e-6 * np.eye(2), T >> 1e-6 * np.eye(2)])
    prob.solve(solver="CLARABEL")
    assert prob.status == "infeasible"


def test_certify_catches_edited_theta(g_paper):
    bad = replace(g_paper, Theta=g_paper.Theta + np.array([[0.0, 0.0], [-3.0, -3.0]]))
    cert = certify(bad)
    failed = {c.name for c in cert.checks if not c.passed}
    assert "lmi16" in failed and cert.failures() and not cert.passed
    assert certify(g_paper).passed


# --------------------------------------------------------------------------- objective, solvers
def test_lmi15_answer_is_the_analytic_centre():
    # stationarity of log det T + log det S, S = λ̄1B0B0ᵀ − (A0T + TA0ᵀ + δ1T):
    # T⁻¹ = A0ᵀS⁻¹ + S⁻¹A0 + δ1S⁻¹ (the adjoint of the Lyapunov-type map), checked in numpy
    lb1, d1 = 1.0, 0.5
    T = synth_T(A0, B0, lb1, d1).T
    S = lb1 * B0 @ B0.T - (A0 @ T + T @ A0.T + d1 * T)
    Si = np.linalg.inv(S)
    np.testing.assert_allclose(np.linalg.inv(T), A0.T @ Si + Si @ A0 + d1 * Si, atol=1e-9)
    np.testing.assert_allclose(T, [[9.0, -3.0], [-3.0, 1.5]], atol=1e-9)


def test_scs_fallback_gives_the_same_certified_answer(paper_synth, g_synth, monkeypatch):
    import synthesis.lmi as lmi

    monkeypatch.setattr(lmi, "SOLVERS", ("NOT-A-SOLVER", "SCS"))  # Clarabel "fails"
    g = synthesize(paper_synth)
    assert g.info["solver"] == "SCS" and g.info["solver_tol"] == lmi.SOLVER_TOL["SCS"]
    assert g.certificate["passed"]
    # LMI (15): the analytic centre is unique, so both solvers land on the same T
    np.testing.assert_allclose(g.T, g_synth.T, rtol=1e-8)
    # LMI (16): the min-norm point is unique but only solved to the solver's accuracy
    np.testing.assert_allclose(g.Theta, g_synth.Theta, atol=1e-3)


def test_unbounded_lmi15_set_gets_a_recorded_cap(paper_synth):
    # A0 stable: A0 + (δ1/2)I is Hurwitz, T may grow without bound, no analytic centre
    # exists; the cap T ⪯ cap·I is added and recorded. Zero of (A0, B0, [1, 1]) at -2.
    A = np.array([[-1.0, 1.0], [0.0, -1.0]])
    lead = replace(paper_synth.leader, A0=A)
    g = synthesize(replace(paper_synth, leader=lead))
    cap = g.info["lmi15_cap"]
    assert cap is not None and np.linalg.eigvalsh(g.T)[-1] < cap
    assert np.allclose(g.info["invariant_zeros"], [[-2.0, 0.0]])
    assert g.certificate["passed"]
    F15 = A @ g.T + g.T @ A.T - g.lambda_bar1 * B0 @ B0.T + g.delta1 * g.T
    assert _lmax(F15) < -g.info["solver_tol"]


def test_given_theta_checked_not_replaced(paper, g_paper):
    good = np.array(g_paper.Theta)
    g = synthesize(replace(paper, observer=replace(paper.observer, Theta=good)))
    np.testing.assert_array_equal(g.Theta, good)
    assert "Theta" in g.info["given"] and g.certificate["passed"]
    bad = np.array([[0.0, 0.0], [-3.0, -3.0]])  # ΦA0 − ΘC0 = [[0, 1], [9, 8]]: unstable
    g = synthesize(replace(paper, observer=replace(paper.observer, Theta=bad)))
    np.testing.assert_array_equal(g.Theta, bad)
    named = {w.split(":")[1].strip() for w in g.certificate["warnings"]}
    assert {"lmi16", "hurwitz"} <= named and not g.certificate["failures"]


def _companion(den_roots, num_roots):
    """SISO controllable canonical form with the given poles and zeros (monic numerator)."""
    den, num = np.poly(den_roots), np.poly(num_roots)
    m = len(den_roots)
    A = np.zeros((m, m))
    A[:-1, 1:] = np.eye(m - 1)
    A[-1, :] = -den[1:][::-1]
    B = np.zeros((m, 1))
    B[-1] = 1.0
    C = np.zeros((1, m))
    C[0, : len(num)] = num[::-1]
    return A, B, C


def test_pencil_zeros_equal_uio_unobservable_modes_on_random_systems():
    # second implementation: zeros = unobservable modes of (ΦA0, C0) when rank(C0B0) = p
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(300):
        m = int(rng.integers(1, 7))
        p = int(rng.integers(1, min(m, 3) + 1))
        n = int(rng.integers(p, 4))
        A, B, C = (
            rng.standard_normal((m, m)),
            rng.standard_normal((m, p)),
            rng.standard_normal((n, m)),
        )
        if n > p and rng.random() < 0.5:  # dependent outputs keep the zeros of the first p
            C[p:] = rng.standard_normal((n - p, p)) @ C[:p]
        if np.linalg.svd(C @ B, compute_uv=False)[-1] < 1e-2:
            continue  # nearly singular C0B0: zeros near infinity, ill-conditioned
        z1, z2 = invariant_zeros(A, B, C), uio_zeros(A, B, C)
        assert len(z1) == len(z2)
        for s in z1:
            assert np.min(np.abs(z2 - s)) <= 1e-6 * (1 + abs(s))
        checked += len(z1)
    assert checked > 200


@pytest.mark.parametrize("root", [1.0, -1.0])
def test_triple_zero_on_tall_system(root):
    # numerator (s - root)³, relative degree 1 (C0B0 = 1), output repeated: a triple zero is
    # computed only to ~eps^(1/3); the loose tolerances must still find all three
    A, B, C = _companion([-0.5, -2.0, -3.0, -4.0], [root] * 3)
    C2 = np.vstack([C, 2 * C])
    z = invariant_zeros(A, B, C2)
    assert len(z) == 3 and np.all(np.abs(z - root) < 1e-3)
    if root > 0:
        with pytest.raises(SynthesisError, match="Assumption 2 fails"):
            check_leader(A, B, C2)
    else:
        assert len(check_leader(A, B, C2).zeros) == 3
