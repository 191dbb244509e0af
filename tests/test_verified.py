"""Verified certificates (synthesis/verified.py): rigorous definiteness proofs.

Independent truth: matrices with exactly known spectra built in sympy's rational arithmetic
(Q·D·Qᵀ with Q an exact rational orthogonal matrix, the Cayley transform of a skew matrix),
exact determinants, and the critical gains of each inequality computed as scipy generalised
eigenvalues. A rigorous proof must never accept a matrix that is not positive definite,
whatever floating point says.
"""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest
import scipy.linalg as sla
import sympy
from helpers import ROOT

from core.errors import SynthesisError
from core.scenario import load_scenario
from synthesis.api import synthesize
from synthesis.certificate import certify
from synthesis.gains import load_gains, save_gains
from synthesis.verified import (
    EXACT,
    NUMPY,
    RUMP,
    exact_pd,
    float_cholesky_succeeds,
    float_enclosure,
    inequalities,
    prove_pd,
    rational,
    rump_pd_at,
    rump_shift,
)

U = 2.0**-53
PROVEN = ("T_pd", "lmi15", "Omega_pd", "lmi16", "lemma3_w", "k1")


def _fr(x) -> Fraction:
    p, q = sympy.Rational(x).as_numer_denom()
    return Fraction(int(p), int(q))


def _known_spectrum(eigs, seed: int) -> np.ndarray:
    """Q diag(eigs) Qᵀ exactly, Q = (I − K)(I + K)⁻¹ rational orthogonal (K skew)."""
    rng = np.random.default_rng(seed)
    n = len(eigs)
    K = sympy.zeros(n, n)
    for i in range(n):
        for j in range(i + 1, n):
            v = sympy.Rational(int(rng.integers(-9, 10)), int(rng.integers(1, 7)))
            K[i, j], K[j, i] = v, -v
    eye = sympy.eye(n)
    Q = (eye - K) * (eye + K).inv()
    assert sympy.simplify(Q * Q.T - eye) == sympy.zeros(n, n)
    M = Q * sympy.diag(*[sympy.Rational(e) for e in eigs]) * Q.T
    return np.array([[_fr(M[i, j]) for j in range(n)] for i in range(n)], dtype=object)


def _by(proofs):
    return {p.test: p for p in proofs}


# ----------------------------------------------------------------------------- (a) known spectra
@pytest.mark.parametrize("n", [2, 3, 4, 6])
@pytest.mark.parametrize("lam_min", ["1", "1/1000", "1/10**8"])
def test_known_positive_spectrum_is_proven_with_a_margin_below_the_truth(n, lam_min):
    lam = sympy.Rational(sympy.sympify(lam_min))
    eigs = [lam] + [lam + k + 1 for k in range(n - 1)]
    M = _known_spectrum(eigs, seed=n)
    rump, exact, est = prove_pd(M)
    assert (rump.test, exact.test, est.test) == (RUMP, EXACT, NUMPY)
    assert rump.passed and exact.passed
    true = float(lam)
    assert 0 <= rump.margin < true  # a proven lower bound of λ_min
    assert rump.margin > true - 1e-12 * n  # and a tight one: only rounding is lost
    assert exact_pd(M, Fraction(rump.margin))  # exact arithmetic confirms the proven margin
    assert not exact_pd(M, _fr(lam))  # λ_min itself is not a strict margin


@pytest.mark.parametrize("n", [2, 3, 5])
def test_a_negative_eigenvalue_of_minus_1e_12_is_refused(n):
    eigs = [sympy.Rational(-1, 10**12)] + [sympy.Integer(k + 1) for k in range(n - 1)]
    M = _known_spectrum(eigs, seed=10 + n)
    rump, exact, _ = prove_pd(M)
    assert not rump.passed and rump.margin is None
    assert not exact.passed
    # the float matrix nearest to M is a different exact matrix: still indefinite (Weyl:
    # its λ_min is within n·u·‖M‖ ≈ 1e-15 of −1e-12), and still refused
    F, _ = float_enclosure(M)
    rump_f, exact_f, est_f = prove_pd(rational(F))
    assert not rump_f.passed and not exact_f.passed and est_f.margin < 0


def test_a_singular_rational_matrix_is_refused():
    V = np.array([[1, 2], [Fraction(1, 3), -1], [3, Fraction(1, 2)]], dtype=object)
    M = V @ V.T  # rank 2 in 3×3: λ_min = 0 exactly
    assert sympy.Matrix(M.tolist()).det() == 0
    rump, exact, _ = prove_pd(M)
    assert not rump.passed and not exact.passed


def test_plain_float_cholesky_accepts_an_indefinite_matrix_that_rump_refuses():
    # exact B·Bᵀ of a random 3×2 B, rounded: numpy's eigvalsh and Cholesky call it positive
    # definite; its exact determinant is not positive
    A = np.array(
        [
            [0.2308442071455755, -0.5683184106933351, -0.6444084058435758],
            [-0.5683184106933351, 3.6280792259847057, 1.410759149403789],
            [-0.6444084058435758, 1.410759149403789, 1.8127378821119533],
        ]
    )
    exact_det = sympy.Matrix([[_fr(sympy.Rational(float(v))) for v in r] for r in A]).det()
    assert exact_det <= 0  # not positive definite (Sylvester)
    np.linalg.cholesky(A)  # LAPACK completes
    assert float_cholesky_succeeds(A) and np.linalg.eigvalsh(A)[0] > 0
    rump, exact, est = prove_pd(rational(A))
    assert est.passed  # numpy is fooled
    assert not rump.passed and not exact.passed


def test_rump_never_accepts_what_exact_arithmetic_refuses():
    # rounded B·Bᵀ with B n×(n−1): singular before rounding, so the float matrix is within
    # rounding of singular, on either side; whatever Rump proves, exact arithmetic confirms
    rng = np.random.default_rng(7)
    fooled = accepted = 0
    for _ in range(150):
        n = int(rng.integers(2, 7))
        B = rng.standard_normal((n, n - 1)) * 10.0 ** rng.integers(-3, 4, size=(1, n - 1))
        A = B @ B.T
        A = np.triu(A) + np.triu(A, 1).T  # exactly symmetric floats
        M = rational(A)
        rump, exact, _ = prove_pd(M)
        truth = exact_pd(M)
        assert exact.passed is truth
        if rump.passed:
            accepted += 1
            assert truth and exact_pd(M, Fraction(rump.margin))
        fooled += float_cholesky_succeeds(A) and not truth
    assert fooled > 0  # plain floating-point Cholesky does accept some of these
    # and none can be proven: λ_min(fl(BBᵀ)) ≤ ‖fl(BBᵀ) − BBᵀ‖₂ ≤ γ_{n−1}·tr(A) < Rump's c
    assert accepted == 0


def test_exact_arithmetic_proves_what_is_below_floating_rounding():
    M = _known_spectrum([sympy.Rational(1, 10**20), 1, 2], seed=3)
    rump, exact, _ = prove_pd(M)
    assert not rump.passed  # 1e-20 is far below the rounding of entries of size ~1
    assert exact.passed


@pytest.mark.parametrize("n", [1, 3, 8])
def test_the_formation_bound_enters_the_proof(n):
    # every M with ‖M − I‖₂ ≤ r has λ_min ≥ 1 − r, and M = (1 − r)I attains it: the test on
    # (F = I, r) may prove margin m only when m < 1 − r
    eye = np.eye(n)
    assert rump_pd_at(eye, Fraction(1, 2), 0.49)[0]
    assert not rump_pd_at(eye, Fraction(1, 2), 0.5)[0]
    assert not rump_pd_at(eye, Fraction(1), 0.0)[0]
    assert rump_pd_at(eye, Fraction(0), 1 - 1e-12)[0] and not rump_pd_at(eye, Fraction(0), 1.0)[0]


def test_rump_shift_is_the_published_constant():
    # c = (n+1)u/(1 − 2(n+1)u)·tr(A) + 4nη(2(n+1) + max a_ii), in sympy
    d = [0.5, 3.0, 1e-3]
    n, u, eta = 3, sympy.Rational(1, 2**53), sympy.Rational(1, 2**1074)
    tr = sum(sympy.Rational(v) for v in d)
    want = (n + 1) * u / (1 - 2 * (n + 1) * u) * tr + 4 * n * eta * (2 * (n + 1) + 3)
    assert _fr(want) == rump_shift(d)


# ----------------------------------------------------------------------------- the certificate
@pytest.fixture(scope="module", params=["paper", "paper-synth"])
def gains(request):
    return synthesize(load_scenario(ROOT / "scenarios" / f"{request.param}.toml"))


def test_every_inequality_is_proven_by_the_float_verified_test(gains):
    by = {c.name: c for c in certify(gains).checks}
    for name in PROVEN:
        c = by[name]
        tests = _by(c.proofs)
        assert c.passed and tests[RUMP].passed and tests[RUMP].margin > 0, name
        assert tests[EXACT].passed, name  # agent-size (≤ 2m) and N = 5: exact too
        rec = c.to_json()
        assert rec["proved"] == c.proved and [p["test"] for p in rec["proofs"]] == [
            RUMP,
            EXACT,
            NUMPY,
        ]


def test_verified_margin_is_below_numpy_and_within_rounding_of_it(gains):
    for name, ineq in inequalities(gains).items():
        rump, exact, est = prove_pd(ineq.matrix)
        F, r = float_enclosure(ineq.matrix)
        n = F.shape[0]
        # rounding scale of the test: Rump's shift of F plus the formation bound r, plus
        # LAPACK's own eigenvalue error (n+1)u·Σ|F|
        c = float(rump_shift(np.abs(np.diag(F))))
        bound = 8 * (c + float(r) + (n + 1) * U * np.abs(F).sum())
        assert rump.margin <= est.margin, name
        assert est.margin - rump.margin <= bound, (name, est.margin - rump.margin, bound)
        assert exact_pd(ineq.matrix, Fraction(rump.margin)), name  # confirmed exactly


def _critical(g, name: str) -> tuple[str, float]:
    """The gain (or LMI rate) at which the named inequality becomes singular, computed
    independently as a generalised eigenvalue."""
    T, Om = 0.5 * (g.T + g.T.T), 0.5 * (g.Omega + g.Omega.T)
    if name == "T_pd":
        return "T", float(np.linalg.eigvalsh(T)[0])
    if name == "Omega_pd":
        return "Omega", float(np.linalg.eigvalsh(Om)[0])
    if name == "lmi15":
        F = g.A0 @ T + T @ g.A0.T - g.lambda_bar1 * g.B0 @ g.B0.T + g.delta1 * T
        return "delta1", g.delta1 + float(sla.eigh(-F, T, eigvals_only=True)[0])
    if name == "lmi16":
        Ac = g.Phi @ g.A0 - g.Theta @ g.C0
        F = Ac.T @ Om + Om @ Ac + g.delta2 * Om
        return "delta2", g.delta2 + float(sla.eigh(-F, Om, eigvals_only=True)[0])
    if name == "lemma3_w":
        S = g.L_bar.T @ g.Z + g.Z @ g.L_bar
        return "w", float(sla.eigh(S, g.Z, eigvals_only=True)[0])
    X = g.Phi @ g.A0 - g.Theta @ g.C0 - g.A0
    K = X.T @ np.linalg.solve(T, X)
    lam = float(sla.eigh(0.5 * (K + K.T), Om, eigvals_only=True)[-1])
    return "k1", float(np.diag(g.Z).max()) * lam / (g.delta1_hat * g.delta2_hat)


def _nudged(g, name: str, side: float):
    """The gains with the named inequality's gain moved to (1 + side)× its boundary."""
    field, crit = _critical(g, name)
    if field in ("T", "Omega"):  # shift the matrix by (1 + side)·λ_min
        M = getattr(g, field)
        return replace(g, **{field: M - (1 + side) * crit * np.eye(M.shape[0])})
    toward = 1 + side if field in ("delta1", "delta2", "w") else 1 - side
    return replace(g, **{field: crit * toward})


@pytest.mark.parametrize("name", PROVEN)
def test_a_gain_nudged_across_its_boundary_fails_the_proof(gains, name):
    rho = 1e-5
    safe = {c.name: c for c in certify(_nudged(gains, name, -rho)).checks}[name]
    assert _by(safe.proofs)[RUMP].passed, name  # just inside: still proven
    bad = {c.name: c for c in certify(_nudged(gains, name, rho)).checks}[name]
    tests = _by(bad.proofs)
    assert not tests[RUMP].passed and not tests[EXACT].passed and not bad.passed, name
    assert f"not proven by {RUMP}" in bad.line()


def test_lambda1_is_proven_exactly_at_the_proven_w(gains):
    w_proven = gains.w * (1 - 1e-6)
    need = gains.lambda_bar1 / w_proven
    for side, ok in ((1e-9, True), (-1e-9, False)):
        c = {c.name: c for c in certify(replace(gains, lambda1=need * (1 + side))).checks}
        (p,) = c["lambda1"].proofs
        assert p.test == EXACT and p.passed is ok and c["lambda1"].passed is ok


def test_certify_command_reports_the_proofs(tmp_path, capsys):
    from synthesis.cli import main

    g = synthesize(load_scenario(ROOT / "scenarios" / "paper-synth.toml"))
    path = save_gains(g, tmp_path / "gains.json")
    assert main(["certify", str(path)]) == 0
    out = capsys.readouterr().out
    assert "matrix inequalities proven: 6/6 by rump-cholesky" in out
    assert "6/6 by exact-rational" in out


def test_every_load_reruns_the_verified_test(tmp_path):
    g = synthesize(load_scenario(ROOT / "scenarios" / "paper-synth.toml"))
    path = save_gains(g, tmp_path / "gains.json")
    loaded = load_gains(path)
    checks = {c["name"]: c for c in loaded.certificate["checks"]}
    assert all(checks[n]["proofs"][0]["test"] == RUMP for n in PROVEN)
    assert all(checks[n]["proofs"][0]["passed"] for n in PROVEN)
    # k1 just below its bound: the file is refused on load, naming the failed proof
    path = save_gains(_nudged(g, "k1", 1e-9), tmp_path / "bad.json")
    with pytest.raises(SynthesisError, match=f"k1: .*not proven by {RUMP}"):
        load_gains(path)
