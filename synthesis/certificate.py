"""The certificate: every claim re-checked with plain numpy/scipy from the numbers alone.

:func:`certify` takes a :class:`~synthesis.gains.Gains` (solver output or a
``gains.json`` read back) and recomputes every condition the theory needs,
trusting neither the solver's status nor any stored derived value. Each check
is a dict ``{"name", "value", "margin", "passed", "detail", "involves"}``:
``margin`` > 0 means the condition holds with that much room; ``involves``
lists the scenario-given gains the check depends on, so that a failure caused
only by a gain the user chose is a *warning* rather than an error.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from core.graph import m_matrix_violation
from synthesis.assumptions import (
    ZERO_RTOL,
    _rank,
    invariant_zeros,
    uio_matrices,
    uio_zeros,
)
from synthesis.gains import Gains
from synthesis.lemma3 import DENSE_EIG_MAX_N, w_of
from synthesis.lmi import lmi15_matrix, lmi16_matrix

DEFAULT_TOL = 1e-8  # when the gains file records no solver tolerance
SYM_RTOL = 1e-9  # relative asymmetry accepted in T, Ω, Z, L̄ᵀZ + ZL̄
MATCH_RTOL = 1e-6  # relative agreement of recomputed matrices (Γ, Φ, Q = B0ᵀT⁻¹, w)


def k1_bound(g: Gains) -> float:
    """λ_max((I_N ⊗ Ω⁻¹)Ēᵀ(Z⁻¹ ⊗ T)Ē)/(δ̂1δ̂2) (V1's constant k1, docs/reading.md, 'Distributed observer').

    With Ē = (ZH) ⊗ (T⁻¹X), X = ΦA0 − ΘC0 − A0, the product is Z ⊗ Ω⁻¹XᵀT⁻¹X
    (H Z H = Z for diagonal H, Z), so λ_max = max(z) · λ_max(XᵀT⁻¹X, Ω): per-agent sized.

    Parameters
    ----------
    g : Gains
        Gains supplying A0, C0, Φ, Θ, T, Ω, Z, δ̂1 and δ̂2.
    """
    X = g.Phi @ g.A0 - g.Theta @ g.C0 - g.A0
    K = X.T @ np.linalg.solve(g.T, X)
    K = 0.5 * (K + K.T)
    lam = float(sla.eigh(K, 0.5 * (g.Omega + g.Omega.T), eigvals_only=True)[-1])
    return float(np.diag(g.Z).max()) * lam / (g.delta1_hat * g.delta2_hat)  # k1 of V1, eq. (17)


def _check(
    name: str,
    value: Any,
    margin: float | None,
    passed: bool,
    detail: str,
    involves: tuple[str, ...] = (),
) -> dict[str, Any]:
    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        return x

    return {
        "name": name,
        "value": clean(value if not isinstance(value, np.floating) else float(value)),
        "margin": clean(None if margin is None else float(margin)),
        "passed": bool(passed),
        "detail": detail,
        "involves": list(involves),
    }


def _asym(M: np.ndarray) -> float:
    return float(np.abs(M - M.T).max() / max(1.0, np.abs(M).max()))


def certify(g: Gains, *, tol: float | None = None, given: tuple[str, ...] = ()) -> dict[str, Any]:
    """Re-check every condition of Theorem 1's design from the numbers in ``g``.

    Parameters
    ----------
    g : Gains
        The gains (the stored certificate and info are not trusted, except the
        recorded solver tolerance and the list of scenario-given gains).
    tol : float, optional
        Strictness threshold: an LMI holds strictly only when its eigenvalue margin
        exceeds this (default: the solver tolerance recorded in ``g.info``).
    given : tuple of str
        Gains the scenario gave explicitly (``lambda1``, ``lambda2``, ``Q``, ``Theta``);
        default: ``g.info["given"]``.

    Returns
    -------
    dict
        ``{"checks": [...], "warnings": [...], "failures": [...], "passed": bool, "tol": float}``;
        ``warnings`` names failed checks that involve only given gains, ``failures`` the rest.
    """
    if tol is None:
        tol = float(g.info.get("solver_tol", DEFAULT_TOL) or DEFAULT_TOL)
    tol = max(tol, 1e-12)
    if not given:
        given = tuple(g.info.get("given", ()))
    Qg = ("Q",) if "Q" in given else ()
    Tg = ("Theta",) if "Theta" in given else ()
    checks: list[dict[str, Any]] = []
    A0, B0, C0 = g.A0, g.B0, g.C0
    m, p = A0.shape[0], B0.shape[1]

    # --- shapes and finiteness (a hand-edited file may break anything)
    arrays = {k: getattr(g, k) for k in ("A0", "B0", "C0", "Gamma", "Phi", "Theta", "Omega", "T", "Q", "L_bar", "H", "Z")}  # fmt: skip
    finite = all(np.all(np.isfinite(a)) for a in arrays.values())
    N = g.L_bar.shape[0]
    n = C0.shape[0]
    shapes_ok = (
        A0.shape == (m, m)
        and C0.shape[1] == m
        and g.Theta.shape == (m, n)
        and g.Omega.shape == (m, m)
        and g.T.shape == (m, m)
        and g.Q.shape == (p, m)
        and g.Gamma.shape == (m, n)
        and g.Phi.shape == (m, m)
        and g.L_bar.shape == (N, N)
        and g.H.shape == (N, N)
        and g.Z.shape == (N, N)
    )
    scalars = [g.lambda_bar1, g.delta1, g.delta2, g.delta1_hat, g.delta2_hat, g.w, g.lambda1, g.lambda2, g.alpha, g.k1]  # fmt: skip
    finite = finite and all(math.isfinite(x) for x in scalars)
    checks.append(
        _check(
            "shapes_finite",
            None,
            None,
            bool(shapes_ok and finite),
            "consistent shapes, all numbers finite",
        )
    )
    if not (shapes_ok and finite):
        return _summarise(checks, given, tol)

    # --- symmetry
    asym = max(_asym(g.T), _asym(g.Omega), _asym(g.Z))
    checks.append(
        _check(
            "symmetry", asym, SYM_RTOL - asym, asym <= SYM_RTOL, "max relative asymmetry of T, Ω, Z"
        )
    )
    T = 0.5 * (g.T + g.T.T)
    Om = 0.5 * (g.Omega + g.Omega.T)

    # --- UIO matrices, eq. (7)
    r_cb = _rank(C0 @ B0)
    checks.append(
        _check(
            "assumption2_rank",
            [r_cb, _rank(B0)],
            None,
            r_cb == p and _rank(B0) == p,
            f"rank(C0B0), rank(B0) must equal p = {p}",
        )
    )
    if r_cb == p:
        Gam, Phi = uio_matrices(B0, C0)
        dev = max(
            np.abs(Gam - g.Gamma).max() / max(1.0, np.abs(Gam).max()),
            np.abs(Phi - g.Phi).max() / max(1.0, np.abs(Phi).max()),
            np.abs(g.Phi @ B0).max() / max(1.0, np.abs(B0).max()),
        )
        checks.append(
            _check(
                "uio_Gamma_Phi",
                dev,
                MATCH_RTOL - dev,
                dev <= MATCH_RTOL,
                "Γ = B0[(C0B0)ᵀ(C0B0)]⁻¹(C0B0)ᵀ, Φ = I − ΓC0, ΦB0 = 0 (eq. (7))",
            )
        )
        zs = invariant_zeros(A0, B0, C0)
        zu = uio_zeros(A0, B0, C0)  # second implementation; the worst of both counts
        worst = max([-math.inf] + [float(z.real) for z in (*zs, *zu)])
        checks.append(
            _check(
                "assumption2_zeros",
                [[float(s.real), float(s.imag)] for s in zs],
                -worst,
                worst < 0,
                f"invariant zeros of (A0, B0, C0) in Re(s) < 0 (pencil with SVD rank test at {ZERO_RTOL:g}, and unobservable modes of (ΦA0, C0))",
            )
        )

    # --- Assumption 1 and gauge
    h = np.diag(g.H)
    gauge_ok = bool(np.all(np.abs(np.abs(h) - 1) == 0) and np.all(g.H == np.diag(h)))
    checks.append(_check("gauge_H", None, None, gauge_ok, "H diagonal with entries ±1"))
    Ls = sp.csr_matrix(g.L_bar)
    why = m_matrix_violation(Ls)
    checks.append(
        _check(
            "assumption1_M_matrix",
            None,
            None,
            why is None,
            "L̄ = H(L+B)H a nonsingular M-matrix" + ("" if why is None else f": {why}"),
        )
    )

    # --- Lemma 3
    z = np.diag(g.Z).copy()
    zdiag = bool(np.all(g.Z == np.diag(z)))
    zmin = float(z.min())
    checks.append(
        _check("Z_pd", zmin, zmin, zdiag and zmin > 0, "Z diagonal with z_i > 0 (Lemma 3)")
    )
    if zmin > 0:
        if N <= DENSE_EIG_MAX_N:
            S = g.L_bar.T * z + z[:, None] * g.L_bar
            lam_s = float(np.linalg.eigvalsh(0.5 * (S + S.T))[0])
            checks.append(
                _check("lemma3_S_pd", lam_s, lam_s, lam_s > 0, "λ_min(L̄ᵀZ + ZL̄) > 0 (Lemma 3)")
            )
        w = w_of(Ls, z)
        ok = w > 0 and g.w <= w * (1 + MATCH_RTOL) + 1e-12
        checks.append(
            _check(
                "lemma3_w",
                w,
                w,
                ok,
                f"w = λ_min(Z^-1/2(L̄ᵀZ+ZL̄)Z^-1/2) = {w:.6g} > 0, stored w = {g.w:.6g} not larger",
            )
        )
    else:
        w = -math.inf

    # --- LMI (15) and Q = B0ᵀT⁻¹
    lam_T = float(np.linalg.eigvalsh(T)[0])
    checks.append(_check("T_pd", lam_T, lam_T - tol, lam_T > tol, "λ_min(T) > tol", Qg))
    F15 = lmi15_matrix(A0, B0, T, g.lambda_bar1, g.delta1)  # eq. (15)
    lam15 = float(np.linalg.eigvalsh(0.5 * (F15 + F15.T))[-1])
    checks.append(
        _check(
            "lmi15",
            lam15,
            -lam15 - tol,
            -lam15 > tol and lam_T > tol,
            f"λ_max(A0T + TA0ᵀ − λ̄1B0B0ᵀ + δ1T) < −tol, λ̄1 = {g.lambda_bar1:g}, δ1 = {g.delta1:g} (eq. (15))",
            Qg,
        )
    )
    if lam_T > 0:
        Qr = B0.T @ np.linalg.inv(T)
        dq = float(np.abs(Qr - g.Q).max() / max(1.0, np.abs(g.Q).max()))
    else:
        dq = math.inf
    checks.append(
        _check("Q_B0T", dq, MATCH_RTOL - dq, dq <= MATCH_RTOL, "Q = B0ᵀT⁻¹ (relative)", Qg)
    )

    # --- LMI (16) and the UIO error matrix
    lam_O = float(np.linalg.eigvalsh(Om)[0])
    checks.append(_check("Omega_pd", lam_O, lam_O - tol, lam_O > tol, "λ_min(Ω) > tol", Tg))
    Ac = g.Phi @ A0 - g.Theta @ C0
    F16 = lmi16_matrix(g.Phi, A0, C0, g.Theta, Om, g.delta2)  # eq. (16)
    lam16 = float(np.linalg.eigvalsh(0.5 * (F16 + F16.T))[-1])
    checks.append(
        _check(
            "lmi16",
            lam16,
            -lam16 - tol,
            -lam16 > tol and lam_O > tol,
            f"λ_max((ΦA0−ΘC0)ᵀΩ + Ω(ΦA0−ΘC0) + δ2Ω) < −tol, δ2 = {g.delta2:g} (eq. (16))",
            Tg,
        )
    )
    re = float(np.linalg.eigvals(Ac).real.max())
    checks.append(
        _check(
            "hurwitz", re, -re - tol, -re > tol, "max Re λ(ΦA0 − ΘC0) < 0 (UIO error decays)", Tg
        )
    )

    # --- gains of Theorem 1
    dl = (
        g.delta1 > 0
        and g.delta2 > 0
        and 0 < g.delta1_hat < g.delta1
        and 0 < g.delta2_hat < g.delta2
        and g.lambda_bar1 > 0
    )
    checks.append(
        _check(
            "deltas",
            [g.delta1, g.delta1_hat, g.delta2, g.delta2_hat],
            None,
            dl,
            "δ1, δ2, λ̄1 > 0, 0 < δ̂1 < δ1, 0 < δ̂2 < δ2",
        )
    )
    l1 = g.lambda1 * w - g.lambda_bar1
    checks.append(
        _check(
            "lambda1",
            g.lambda1 * w,
            l1,
            l1 > 0,
            f"λ1·w > λ̄1: {g.lambda1:g}·{w:.6g} vs {g.lambda_bar1:g} (needs λ1 > {g.lambda_bar1 / w if w > 0 else math.inf:.6g})",
            ("lambda1",) if "lambda1" in given else (),
        )
    )
    l2 = g.lambda2 - g.alpha
    checks.append(
        _check(
            "lambda2",
            g.lambda2,
            l2,
            l2 >= 0,
            f"λ2 ≥ α = {g.alpha:g} (the proof needs ‖u0‖ ≤ α ≤ λ2)",
            ("lambda2",) if "lambda2" in given else (),
        )
    )
    if lam_T > 0 and lam_O > 0 and zmin > 0 and g.delta1_hat > 0 and g.delta2_hat > 0:
        kb = k1_bound(g)
        checks.append(
            _check(
                "k1",
                g.k1,
                g.k1 - kb,
                g.k1 > kb,
                f"k1 > λ_max((I⊗Ω⁻¹)Ēᵀ(Z⁻¹⊗T)Ē)/(δ̂1δ̂2) = {kb:.6g} (V1, eq. (17))",
            )
        )
    else:
        checks.append(_check("k1", g.k1, None, False, "cannot evaluate: T, Ω or Z not positive"))
    return _summarise(checks, given, tol)


def _summarise(checks: list[dict[str, Any]], given: tuple[str, ...], tol: float) -> dict[str, Any]:
    warnings: list[str] = []
    failures: list[str] = []
    for c in checks:
        if c["passed"]:
            continue
        inv = c["involves"]
        line = f"{c['name']}: {c['detail']} (value {c['value']}, margin {c['margin']})"
        if inv and all(x in given for x in inv):
            warnings.append(f"given {', '.join(inv)}: {line}")
        else:
            failures.append(line)
    return {
        "checks": checks,
        "warnings": warnings,
        "failures": failures,
        "passed": not failures and not warnings,
        "tol": tol,
        "given": list(given),
    }
