"""The certificate: every claim re-checked with plain numpy/scipy from the numbers alone.

:func:`certify` takes a :class:`~synthesis.gains.Gains` (solver output or a
``gains.json`` read back) and recomputes every condition the theory needs,
trusting neither the solver's status nor any stored derived value. Each condition
is one function returning a :class:`Check` (its measured value, its margin — > 0
means the condition holds with that much room — and the paper's equation); the
checks make up a :class:`Certificate`. ``involves`` lists the scenario-given gains a
check depends on, so that a failure caused only by a gain the user chose is a
*warning* rather than an error. :meth:`Certificate.to_json` is what ``gains.json``
stores under ``certificate``. The matrix inequalities are also proven rigorously
(:mod:`synthesis.verified`): those checks pass only when proven.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from core.graph import m_matrix_violation
from core.memo import MEMO
from synthesis.assumptions import (
    ZERO_RTOL,
    _rank,
    invariant_zeros,
    uio_matrices,
    uio_zeros,
)
from synthesis.certificate_record import CertificateRecord, CheckRecord
from synthesis.gains import MATRIX_FIELDS, Gains
from synthesis.lemma3 import DENSE_EIG_MAX_N, w_of
from synthesis.lmi_matrices import lmi15_matrix, lmi16_matrix
from synthesis.verified import EXACT, RUMP, Proof, prove_inequalities, proven

DEFAULT_TOL = 1e-8  # when the gains file records no solver tolerance
SYM_RTOL = 1e-9  # relative asymmetry accepted in T, Ω, Z, L̄ᵀZ + ZL̄
MATCH_RTOL = 1e-6  # relative agreement of recomputed matrices (Γ, Φ, Q = B0ᵀT⁻¹, w)
_SCALARS = (
    "lambda_bar1",
    "delta1",
    "delta2",
    "delta1_hat",
    "delta2_hat",
    "w",
    "lambda1",
    "lambda2",
    "alpha",
    "k1",
)


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


# ----------------------------------------------------------------------------- records
def _clean(x: Any) -> Any:
    """A JSON-ready number: numpy floats as floats, non-finite floats as None."""
    if isinstance(x, np.floating):
        x = float(x)
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


@dataclass(frozen=True)
class Check:
    """One condition of the certificate, evaluated.

    Attributes
    ----------
    name : str
        Stable identifier (``lmi15``, ``lambda1``, ...; docs/synthesis.md lists them).
    condition : str
        The condition in words, with the numbers it was evaluated at (JSON ``detail``).
    value : object
        The measured quantity (a number, a list, or None); JSON ``value``.
    margin : float or None
        Room by which the condition holds (> 0) or fails (≤ 0); None if not a number.
    passed : bool
        Whether the condition holds.
    involves : tuple of str
        Scenario-given gains the check depends on (a failure is then a warning).
    eq : str
        Where the condition comes from in the paper (``"eq. (15)"``, ``"Lemma 3"``).
    proved : str
        Matrix inequalities only: the matrix :mod:`synthesis.verified` proved ≻ 0.
    proofs : tuple of Proof
        Its definiteness tests; the check passes only if every rigorous one proved it.
    """

    name: str
    condition: str
    value: Any
    margin: float | None
    passed: bool
    involves: tuple[str, ...] = ()
    eq: str = ""
    proved: str = ""
    proofs: tuple[Proof, ...] = ()

    def to_json(self) -> CheckRecord:
        """``{"name", "value", "margin", "passed", "detail", "involves", "eq"}``, and
        ``"proved"``, ``"proofs"`` for a matrix inequality."""
        out: CheckRecord = {
            "name": self.name,
            "value": _clean(self.value),
            "margin": _clean(None if self.margin is None else float(self.margin)),
            "passed": bool(self.passed),
            "detail": self.condition,
            "involves": list(self.involves),
            "eq": self.eq,
        }
        if self.proofs:
            out["proved"] = self.proved
            out["proofs"] = [p.to_json() for p in self.proofs]
        return out

    def line(self) -> str:
        """The check as one line of a warning or failure message."""
        d = self.to_json()
        why = "".join(
            f"; {self.proved} not proven by {p.test}"
            for p in self.proofs
            if p.rigorous and not p.passed
        )
        return f"{self.name}: {self.condition} (value {d['value']}, margin {d['margin']}{why})"


@dataclass(frozen=True)
class Certificate:
    """Every check of :func:`certify`, and what they add up to.

    Attributes
    ----------
    checks : tuple of Check
        In a fixed order (docs/synthesis.md, 'Certificate checks').
    given : tuple of str
        Gains the scenario gave; a failed check involving only these is a warning.
    tol : float
        Strictness threshold of the LMI eigenvalue margins.
    notes : tuple of str, optional
        Remarks of the synthesis (None: no notes recorded).
    """

    checks: tuple[Check, ...]
    given: tuple[str, ...]
    tol: float
    notes: tuple[str, ...] | None = None

    def _is_warning(self, c: Check) -> bool:
        return bool(c.involves) and all(x in self.given for x in c.involves)

    def warnings(self) -> list[str]:
        """Failed checks that involve only given gains, one line each."""
        return [
            f"given {', '.join(c.involves)}: {c.line()}"
            for c in self.checks
            if not c.passed and self._is_warning(c)
        ]

    def failures(self) -> list[str]:
        """Every other failed check, one line each."""
        return [c.line() for c in self.checks if not c.passed and not self._is_warning(c)]

    @property
    def passed(self) -> bool:
        """True when no check failed (neither failures nor warnings)."""
        return all(c.passed for c in self.checks)

    def proof_summary(self) -> str:
        """How many matrix inequalities each rigorous test proved, and the least margin."""
        ineq = [c for c in self.checks if any(p.test == RUMP for p in c.proofs)]
        parts = []
        for test in (RUMP, EXACT):
            ps = [p for c in ineq for p in c.proofs if p.test == test]
            ok = [p.margin for p in ps if p.passed and p.margin is not None]
            if ps:
                least = f", least margin {min(ok):.3g}" if ok else ""
                parts.append(f"{len(ok)}/{len(ineq)} by {test}{least}")
        text = f"matrix inequalities proven: {'; '.join(parts)}" if parts else ""
        scalar = [c for c in self.checks if c.proofs and c not in ineq]
        if text and scalar:
            n_ok = sum(proven(c.proofs) for c in scalar)
            text += f"; {', '.join(c.name for c in scalar)} proven exactly: {n_ok}/{len(scalar)}"
        return text

    def to_json(self) -> CertificateRecord:
        """The ``certificate`` object of ``gains.json``.

        ``{"checks", "warnings", "failures", "passed", "tol", "given"}`` and, when
        notes were recorded, ``"notes"``.
        """
        out: CertificateRecord = {
            "checks": [c.to_json() for c in self.checks],
            "warnings": self.warnings(),
            "failures": self.failures(),
            "passed": self.passed,
            "tol": self.tol,
            "given": list(self.given),
        }
        if self.notes is not None:
            out["notes"] = list(self.notes)
        return out


# ----------------------------------------------------------------------------- the numbers
@dataclass(frozen=True)
class _Numbers:
    """What several checks share, computed once from the gains.

    Attributes
    ----------
    g : Gains
        The gains under test.
    tol : float
        Strictness threshold.
    given : tuple of str
        The scenario-given gains.
    T, Om : ndarray
        The symmetric parts of T and Ω.
    lam_T, lam_O : float
        λ_min(T), λ_min(Ω).
    z : ndarray
        diag(Z).
    L_bar : scipy.sparse.csr_matrix
        L̄ as a sparse matrix.
    w : float
        Lemma 3's w recomputed from L̄ and z (−inf if some z_i ≤ 0).
    """

    g: Gains
    tol: float
    given: tuple[str, ...]
    T: np.ndarray
    Om: np.ndarray
    lam_T: float
    lam_O: float
    z: np.ndarray
    L_bar: sp.csr_matrix
    w: float

    @classmethod
    def of(cls, g: Gains, tol: float, given: tuple[str, ...]) -> _Numbers:
        """Symmetrise T, Ω; their smallest eigenvalues; z; w (Lemma 3)."""
        T = 0.5 * (g.T + g.T.T)
        Om = 0.5 * (g.Omega + g.Omega.T)
        z = np.diag(g.Z).copy()
        Ls = sp.csr_matrix(g.L_bar)
        w = w_of(Ls, z) if float(z.min()) > 0 else -math.inf
        lam_T = float(np.linalg.eigvalsh(T)[0])
        lam_O = float(np.linalg.eigvalsh(Om)[0])
        return cls(g, tol, given, T, Om, lam_T, lam_O, z, Ls, w)

    def mark(self, name: str) -> tuple[str, ...]:
        """``(name,)`` if the scenario gave that gain, else ``()``."""
        return (name,) if name in self.given else ()


def _asym(M: np.ndarray) -> float:
    return float(np.abs(M - M.T).max() / max(1.0, np.abs(M).max()))


def _rel_dev(a: np.ndarray, ref: np.ndarray) -> float:
    """max |a − ref| relative to max(1, max |ref|)."""
    return float(np.abs(a - ref).max() / max(1.0, np.abs(ref).max()))


def _lam_max_sym(F: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(0.5 * (F + F.T))[-1])


# ----------------------------------------------------------------------------- one per condition
def check_shapes_finite(g: Gains) -> Check:
    """Consistent shapes and finite numbers (a hand-edited file may break anything).

    Parameters
    ----------
    g : Gains
        The gains under test.
    """
    m, p, N, n = g.A0.shape[0], g.B0.shape[1], g.L_bar.shape[0], g.C0.shape[0]
    want = {
        "A0": (m, m),
        "Theta": (m, n),
        "Omega": (m, m),
        "T": (m, m),
        "Q": (p, m),
        "Gamma": (m, n),
        "Phi": (m, m),
        "L_bar": (N, N),
        "H": (N, N),
        "Z": (N, N),
    }
    shapes_ok = g.C0.shape[1] == m and all(getattr(g, k).shape == s for k, s in want.items())
    finite = all(np.all(np.isfinite(getattr(g, k))) for k in MATRIX_FIELDS)
    finite = finite and all(math.isfinite(getattr(g, k)) for k in _SCALARS)
    ok = bool(shapes_ok and finite)
    return Check("shapes_finite", "consistent shapes, all numbers finite", None, None, ok)


def check_symmetry(c: _Numbers) -> Check:
    """T, Ω and Z symmetric up to :data:`SYM_RTOL`.

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    asym = max(_asym(c.g.T), _asym(c.g.Omega), _asym(c.g.Z))
    return Check(
        "symmetry", "max relative asymmetry of T, Ω, Z", asym, SYM_RTOL - asym, asym <= SYM_RTOL
    )


def check_assumption2_rank(c: _Numbers) -> Check:
    """rank(C0B0) = rank(B0) = p (Assumption 2).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    B0, p = c.g.B0, c.g.B0.shape[1]
    r_cb, r_b = _rank(c.g.C0 @ B0), _rank(B0)
    text = f"rank(C0B0), rank(B0) must equal p = {p}"
    return Check(
        "assumption2_rank", text, [r_cb, r_b], None, r_cb == p and r_b == p, eq="Assumption 2"
    )


def check_uio_gamma_phi(c: _Numbers) -> Check:
    """The stored Γ, Φ are eq. (7)'s, and ΦB0 = 0 (needs rank(C0B0) = p).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g = c.g
    Gam, Phi = uio_matrices(g.B0, g.C0)
    phi_b0 = float(np.abs(g.Phi @ g.B0).max() / max(1.0, np.abs(g.B0).max()))
    dev = max(_rel_dev(g.Gamma, Gam), _rel_dev(g.Phi, Phi), phi_b0)
    return Check(
        "uio_Gamma_Phi",
        "Γ = B0[(C0B0)ᵀ(C0B0)]⁻¹(C0B0)ᵀ, Φ = I − ΓC0, ΦB0 = 0 (eq. (7))",
        dev,
        MATCH_RTOL - dev,
        dev <= MATCH_RTOL,
        eq="eq. (7)",
    )


def check_assumption2_zeros(c: _Numbers) -> Check:
    """Invariant zeros of (A0, B0, C0) in the open left half-plane (two implementations).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    A0, B0, C0 = c.g.A0, c.g.B0, c.g.C0
    zs = invariant_zeros(A0, B0, C0)
    zu = uio_zeros(A0, B0, C0)  # second implementation; the worst of both counts
    worst = max([-math.inf] + [float(z.real) for z in (*zs, *zu)])
    return Check(
        "assumption2_zeros",
        f"invariant zeros of (A0, B0, C0) in Re(s) < 0 (pencil with SVD rank test at "
        f"{ZERO_RTOL:g}, and unobservable modes of (ΦA0, C0))",
        [[float(s.real), float(s.imag)] for s in zs],
        -worst,
        worst < 0,
        eq="Assumption 2",
    )


def check_uio(c: _Numbers) -> list[Check]:
    """Assumption 2's rank and, when it holds, eq. (7)'s Γ, Φ and the zeros.

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    rank = check_assumption2_rank(c)
    if _rank(c.g.C0 @ c.g.B0) != c.g.B0.shape[1]:
        return [rank]
    return [rank, check_uio_gamma_phi(c), check_assumption2_zeros(c)]


def check_gauge(c: _Numbers) -> Check:
    """H diagonal with entries ±1 (the gauge of a structurally balanced graph).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    H = c.g.H
    h = np.diag(H)
    ok = bool(np.all(np.abs(np.abs(h) - 1) == 0) and np.all(H == np.diag(h)))
    return Check("gauge_H", "H diagonal with entries ±1", None, None, ok, eq="Assumption 1")


def check_m_matrix(c: _Numbers) -> Check:
    """L̄ = H(L + B)H is a nonsingular M-matrix (Assumption 1).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    why = m_matrix_violation(c.L_bar)
    text = "L̄ = H(L+B)H a nonsingular M-matrix" + ("" if why is None else f": {why}")
    return Check("assumption1_M_matrix", text, None, None, why is None, eq="Assumption 1")


def check_lemma3(c: _Numbers) -> list[Check]:
    """Z diagonal positive; λ_min(L̄ᵀZ + ZL̄) > 0 (N small); w recomputed ≥ stored w.

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g, z = c.g, c.z
    zmin = float(z.min())
    zdiag = bool(np.all(g.Z == np.diag(z)))
    text = "Z diagonal with z_i > 0 (Lemma 3)"
    out = [Check("Z_pd", text, zmin, zmin, zdiag and zmin > 0, eq="Lemma 3")]
    if zmin <= 0:
        return out
    if g.L_bar.shape[0] <= DENSE_EIG_MAX_N:
        S = g.L_bar.T * z + z[:, None] * g.L_bar
        lam_s = float(np.linalg.eigvalsh(0.5 * (S + S.T))[0])
        text = "λ_min(L̄ᵀZ + ZL̄) > 0 (Lemma 3)"
        out.append(Check("lemma3_S_pd", text, lam_s, lam_s, lam_s > 0, eq="Lemma 3"))
    w = c.w
    ok = w > 0 and g.w <= w * (1 + MATCH_RTOL) + 1e-12
    text = f"w = λ_min(Z^-1/2(L̄ᵀZ+ZL̄)Z^-1/2) = {w:.6g} > 0, stored w = {g.w:.6g} not larger"
    out.append(Check("lemma3_w", text, w, w, ok, eq="Lemma 3"))
    return out


def check_lmi15(c: _Numbers) -> list[Check]:
    """T ≻ tol·I, LMI (15) strictly, and Q = B0ᵀT⁻¹.

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g, tol, lam_T, Qg = c.g, c.tol, c.lam_T, c.mark("Q")
    lam15 = _lam_max_sym(lmi15_matrix(g.A0, g.B0, c.T, g.lambda_bar1, g.delta1))  # eq. (15)
    text15 = (
        f"λ_max(A0T + TA0ᵀ − λ̄1B0B0ᵀ + δ1T) < −tol, λ̄1 = {g.lambda_bar1:g}, "
        f"δ1 = {g.delta1:g} (eq. (15))"
    )
    dq = _rel_dev(g.B0.T @ np.linalg.inv(c.T), g.Q) if lam_T > 0 else math.inf
    return [
        Check("T_pd", "λ_min(T) > tol", lam_T, lam_T - tol, lam_T > tol, Qg, "eq. (15)"),
        Check("lmi15", text15, lam15, -lam15 - tol, -lam15 > tol and lam_T > tol, Qg, "eq. (15)"),
        Check(
            "Q_B0T", "Q = B0ᵀT⁻¹ (relative)", dq, MATCH_RTOL - dq, dq <= MATCH_RTOL, Qg, "Theorem 1"
        ),
    ]


def check_lmi16(c: _Numbers) -> list[Check]:
    """Ω ≻ tol·I, LMI (16) strictly, and ΦA0 − ΘC0 Hurwitz (the UIO error decays).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g, tol, lam_O, Tg = c.g, c.tol, c.lam_O, c.mark("Theta")
    lam16 = _lam_max_sym(lmi16_matrix(g.Phi, g.A0, g.C0, g.Theta, c.Om, g.delta2))  # eq. (16)
    text16 = f"λ_max((ΦA0−ΘC0)ᵀΩ + Ω(ΦA0−ΘC0) + δ2Ω) < −tol, δ2 = {g.delta2:g} (eq. (16))"
    re = float(np.linalg.eigvals(g.Phi @ g.A0 - g.Theta @ g.C0).real.max())
    text_h = "max Re λ(ΦA0 − ΘC0) < 0 (UIO error decays)"
    return [
        Check("Omega_pd", "λ_min(Ω) > tol", lam_O, lam_O - tol, lam_O > tol, Tg, "eq. (16)"),
        Check("lmi16", text16, lam16, -lam16 - tol, -lam16 > tol and lam_O > tol, Tg, "eq. (16)"),
        Check("hurwitz", text_h, re, -re - tol, -re > tol, Tg, "eq. (8)"),
    ]


def check_deltas(c: _Numbers) -> Check:
    """δ1, δ2, λ̄1 > 0 and 0 < δ̂1 < δ1, 0 < δ̂2 < δ2.

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g = c.g
    ok = (
        g.delta1 > 0
        and g.delta2 > 0
        and 0 < g.delta1_hat < g.delta1
        and 0 < g.delta2_hat < g.delta2
        and g.lambda_bar1 > 0
    )
    values = [g.delta1, g.delta1_hat, g.delta2, g.delta2_hat]
    text = "δ1, δ2, λ̄1 > 0, 0 < δ̂1 < δ1, 0 < δ̂2 < δ2"
    return Check("deltas", text, values, None, ok, eq="Theorem 1")


def check_lambda1(c: _Numbers) -> Check:
    """λ1·w > λ̄1 with the recomputed w (Theorem 1).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g, w = c.g, c.w
    margin = g.lambda1 * w - g.lambda_bar1
    need = g.lambda_bar1 / w if w > 0 else math.inf
    text = f"λ1·w > λ̄1: {g.lambda1:g}·{w:.6g} vs {g.lambda_bar1:g} (needs λ1 > {need:.6g})"
    return Check("lambda1", text, g.lambda1 * w, margin, margin > 0, c.mark("lambda1"), "Theorem 1")


def check_lambda2(c: _Numbers) -> Check:
    """λ2 ≥ α (the proof needs ‖u0‖ ≤ α ≤ λ2).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g = c.g
    margin = g.lambda2 - g.alpha
    text = f"λ2 ≥ α = {g.alpha:g} (the proof needs ‖u0‖ ≤ α ≤ λ2)"
    return Check("lambda2", text, g.lambda2, margin, margin >= 0, c.mark("lambda2"), "Theorem 1")


def check_k1(c: _Numbers) -> Check:
    """k1 above V1's bound :func:`k1_bound` (needs T, Ω, Z and δ̂1, δ̂2 positive).

    Parameters
    ----------
    c : _Numbers
        The gains and the quantities the checks share.
    """
    g = c.g
    positive = c.lam_T > 0 and c.lam_O > 0 and float(c.z.min()) > 0
    if not (positive and g.delta1_hat > 0 and g.delta2_hat > 0):
        return Check("k1", "cannot evaluate: T, Ω or Z not positive", g.k1, None, False)
    kb = k1_bound(g)
    text = f"k1 > λ_max((I⊗Ω⁻¹)Ēᵀ(Z⁻¹⊗T)Ē)/(δ̂1δ̂2) = {kb:.6g} (V1, eq. (17))"
    return Check("k1", text, g.k1, g.k1 - kb, g.k1 > kb, eq="eq. (17)")


# in the order of docs/synthesis.md, 'Certificate checks'
_CONDITIONS: tuple[Callable[[_Numbers], Check | list[Check]], ...] = (
    check_symmetry,
    check_uio,
    check_gauge,
    check_m_matrix,
    check_lemma3,
    check_lmi15,
    check_lmi16,
    check_deltas,
    check_lambda1,
    check_lambda2,
    check_k1,
)


def _flatten(results: Iterable[Check | list[Check]]) -> list[Check]:
    out: list[Check] = []
    for r in results:
        out.extend(r if isinstance(r, list) else [r])
    return out


def certify(g: Gains, *, tol: float | None = None, given: tuple[str, ...] = ()) -> Certificate:
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
    Certificate
        Every check; ``warnings()`` names failed checks that involve only given gains,
        ``failures()`` the rest; ``to_json()`` is what ``gains.json`` stores. Equal numbers
        (:func:`numbers_digest`), tolerance and given gains give the certificate computed
        for them before in this process.
    """
    if tol is None:
        tol = float(g.info.get("solver_tol", DEFAULT_TOL) or DEFAULT_TOL)
    tol = max(tol, 1e-12)
    if not given:
        given = tuple(g.info.get("given", ()))
    key = (numbers_digest(g), tol, tuple(given))
    if key not in _CERTIFIED:
        _CERTIFIED[key] = _certify(g, tol, tuple(given))
    return _CERTIFIED[key]


#: certificates of this process by (numbers, tolerance, given): a study re-certifies the
#: same gains for every sample, and a certificate depends on nothing else
_CERTIFIED = MEMO.namespace("certificates", 64)


def numbers_digest(g: Gains) -> str:
    """SHA-256 of every field of ``g`` but its certificate and info (names, shapes, bytes).

    Parameters
    ----------
    g : Gains
    """
    h = hashlib.sha256()
    for f in fields(g):
        if f.name in ("certificate", "info"):
            continue
        a = np.asarray(getattr(g, f.name))
        h.update(f"{f.name}:{a.dtype.str}:{a.shape}:".encode())
        h.update(np.ascontiguousarray(a).tobytes() if a.dtype != object else repr(a).encode())
    return h.hexdigest()


def _certify(g: Gains, tol: float, given: tuple[str, ...]) -> Certificate:
    shapes = check_shapes_finite(g)
    if not shapes.passed:
        return Certificate((shapes,), given, tol)
    nums = _Numbers.of(g, tol, given)
    checks = _flatten(f(nums) for f in _CONDITIONS)
    return Certificate((shapes, *_verified(checks, g)), given, tol)


def _verified(checks: list[Check], g: Gains) -> list[Check]:
    """The matrix inequalities with their rigorous proofs (synthesis/verified.py): a check
    passes only if its numpy test and every rigorous test pass."""
    proofs = prove_inequalities(g)
    out = []
    for c in checks:
        if c.name in proofs:
            text, ps = proofs[c.name]
            c = replace(c, proved=text, proofs=ps, passed=c.passed and proven(ps))
        out.append(c)
    return out
