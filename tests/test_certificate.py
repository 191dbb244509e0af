"""The certificate as records: one check per condition, each failing on its own violation.

Independent truth: the conditions are re-evaluated here from their printed formulas
(LMI (15) written out, w as a dense generalised eigenvalue, k1's literal Kronecker
product), and each edit below violates exactly the condition named.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla
from helpers import ROOT

from core.scenario import load_scenario
from synthesis.api import synthesize
from synthesis.certificate import Certificate, Check, certify
from synthesis.gains import read_gains_file, save_gains

NAMES = (
    "shapes_finite symmetry assumption2_rank uio_Gamma_Phi assumption2_zeros gauge_H "
    "assumption1_M_matrix Z_pd lemma3_S_pd lemma3_w T_pd lmi15 Q_B0T Omega_pd lmi16 hurwitz "
    "deltas lambda1 lambda2 k1"
).split()


@pytest.fixture(scope="module")
def g():
    return synthesize(load_scenario(ROOT / "scenarios" / "paper-synth.toml"))


def _w_dense(g) -> float:
    """λ_min(L̄ᵀZ + ZL̄, Z): Lemma 3's w as a dense generalised eigenvalue."""
    S = g.L_bar.T @ g.Z + g.Z @ g.L_bar
    return float(sla.eigh(S, g.Z, eigvals_only=True)[0])


def _k1_literal(g) -> float:
    """eq. (17)'s bound from the literal (Nm)x(Nm) Kronecker product."""
    N = g.Z.shape[0]
    X = g.Phi @ g.A0 - g.Theta @ g.C0 - g.A0
    E = np.kron(g.Z @ g.H, np.linalg.inv(g.T) @ X)
    M = np.kron(np.eye(N), np.linalg.inv(g.Omega)) @ E.T @ np.kron(np.linalg.inv(g.Z), g.T) @ E
    return float(np.linalg.eigvals(M).real.max()) / (g.delta1_hat * g.delta2_hat)


def _failed(cert: Certificate) -> set[str]:
    return {c.name for c in cert.checks if not c.passed}


def test_every_condition_is_one_check_in_the_documented_order(g):
    cert = certify(g)
    assert [c.name for c in cert.checks] == NAMES
    assert cert.passed and not cert.failures() and not cert.warnings()
    assert all(isinstance(c, Check) for c in cert.checks)
    # every condition of the theory names where it comes from in the paper
    assert all(c.eq for c in cert.checks if c.name not in ("shapes_finite", "symmetry"))


def test_margins_are_the_residuals_of_the_printed_conditions(g):
    by = {c.name: c for c in certify(g).checks}
    tol = certify(g).tol
    F15 = g.A0 @ g.T + g.T @ g.A0.T - g.lambda_bar1 * g.B0 @ g.B0.T + g.delta1 * g.T
    assert by["lmi15"].margin == pytest.approx(-np.linalg.eigvalsh(F15)[-1] - tol, rel=1e-9)
    w = _w_dense(g)
    assert by["lambda1"].margin == pytest.approx(g.lambda1 * w - g.lambda_bar1, rel=1e-7)
    assert by["lambda2"].margin == pytest.approx(g.lambda2 - g.alpha, rel=1e-12)
    assert by["k1"].margin == pytest.approx(g.k1 - _k1_literal(g), rel=1e-7)
    Ac = g.Phi @ g.A0 - g.Theta @ g.C0
    assert by["hurwitz"].value == pytest.approx(np.linalg.eigvals(Ac).real.max(), rel=1e-9)


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda g: {"lambda2": g.alpha * 0.9}, {"lambda2"}),
        (lambda g: {"k1": 0.5 * _k1_literal(g)}, {"k1"}),
        (lambda g: {"lambda1": 0.9 * g.lambda_bar1 / _w_dense(g)}, {"lambda1"}),
        (lambda g: {"w": 1.1 * _w_dense(g)}, {"lemma3_w"}),
        (lambda g: {"Q": 1.01 * g.Q}, {"Q_B0T"}),
        (lambda g: {"Gamma": g.Gamma + 0.01}, {"uio_Gamma_Phi"}),
        (lambda g: {"H": 2.0 * g.H}, {"gauge_H"}),
        (lambda g: {"delta1_hat": g.delta1}, {"deltas"}),
        # k1's bound (eq. (17)) depends on Θ too
        (
            lambda g: {"Theta": g.Theta + np.array([[0.0, 0.0], [-3.0, -3.0]])},
            {"lmi16", "hurwitz", "k1"},
        ),
    ],
)
def test_each_violation_fails_its_own_check(g, edit, expected):
    cert = certify(replace(g, **edit(g)))
    assert _failed(cert) == expected
    assert not cert.passed and len(cert.failures()) == len(expected)


def test_a_remembered_certificate_is_served_only_for_equal_numbers(g):
    # the same numbers (another object, other info) get the first certificate; one number
    # changed in place after certifying gets its own, failing, certificate
    first = certify(g)
    again = certify(replace(g, info={**g.info, "scenario_sha256": "another"}))
    assert again is first and first.passed
    bad = replace(g, Q=g.Q.copy())
    assert certify(bad) is first  # equal numbers, equal certificate
    bad.Q[0, 0] *= 1.01
    assert _failed(certify(bad)) == {"Q_B0T"}


def test_a_non_finite_number_stops_at_the_first_check(g):
    T = g.T.copy()
    T[0, 0] = np.nan
    cert = certify(replace(g, T=T))
    assert [c.name for c in cert.checks] == ["shapes_finite"] and not cert.passed
    assert cert.failures()[0].startswith("shapes_finite: consistent shapes")


def test_warnings_are_the_failures_of_given_gains_only(g):
    bad = replace(g, lambda1=0.5 * g.lambda_bar1 / _w_dense(g), lambda2=0.5 * g.alpha)
    cert = certify(bad, given=("lambda1",))
    assert [w.split(":")[1].strip() for w in cert.warnings()] == ["lambda1"]
    assert [f.split(":")[0] for f in cert.failures()] == ["lambda2"]
    d = cert.to_json()
    assert d["warnings"] == cert.warnings() and d["failures"] == cert.failures()
    assert d["passed"] is False and d["given"] == ["lambda1"]


def test_json_form_survives_the_file(g, tmp_path):
    path = save_gains(g, tmp_path / "gains.json")
    stored = json.loads(path.read_text())["certificate"]
    fresh = certify(read_gains_file(path).gains).to_json()
    assert stored["checks"] == fresh["checks"]
    assert set(stored["checks"][0]) == {
        "name",
        "value",
        "margin",
        "passed",
        "detail",
        "involves",
        "eq",
    }
