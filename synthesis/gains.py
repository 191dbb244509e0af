"""The synthesis artifact: certified gains, written to and read from ``gains.json``.

This is the one interface between synthesis and everything downstream: the
closed loop, the simulation and the verification read a :class:`Gains` and
never reach back into the synthesis code.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from symbolic.artifacts import atomic_write_text
from symbolic.errors import SynthesisError

_MATRICES = ("A0", "B0", "C0", "Gamma", "Phi", "Theta", "Omega", "T", "Q", "L_bar", "H", "Z")


@dataclass(frozen=True)
class Gains:
    """Everything the closed loop and the verification need from synthesis.

    Attributes
    ----------
    A0, B0, C0 : ndarray
        The leader matrices the gains were designed for.
    Gamma, Phi : ndarray
        UIO matrices, eq. (7): Γ = B0[(C0B0)ᵀ(C0B0)]⁻¹(C0B0)ᵀ, Φ = I − ΓC0.
    Theta : ndarray
        m×n, makes ΦA0 − ΘC0 Hurwitz (LMI (16)).
    Omega : ndarray
        m×m, LMI (16).
    T : ndarray
        m×m, LMI (15); Q = B0ᵀT⁻¹.
    Q : ndarray
        p×m observer gain.
    lambda_bar1, delta1, delta2, delta1_hat, delta2_hat : float
        LMI parameters and the parts of the rates spent on the cross term.
    L_bar : ndarray
        N×N, L̄ = H(L + B)H.
    H : ndarray
        N×N diagonal gauge, h_i = ±1 (identity for cooperative graphs).
    Z : ndarray
        N×N diagonal, Lemma 3.
    w : float
        Lemma 3's constant, λ_min(Z^{-1/2}(L̄ᵀZ + ZL̄)Z^{-1/2}).
    lambda1, lambda2, alpha, k1 : float
        Observer gains, the input bound, and V1's constant.
    certificate : dict
        ``{"checks": [{"name", "value", "margin", "passed", "detail", "involves"}...],
        "warnings": [...], "failures": [...], "passed": bool, "tol": float, "given": [...],
        "notes": [...]}`` (see :func:`synthesis.certificate.certify`). ``warnings`` are
        failed checks involving only scenario-given gains; ``failures`` is empty in any
        file ``make synth`` writes.
    info : dict
        Solver name, version and tolerance, strictness margin ε (``lmi_eps``), scenario
        SHA-256, the given gains, both Lemma 3 variants, the invariant zeros, and
        (Q given) the smallest λ̄1 for which the given Q satisfies LMI (15).
    """

    A0: np.ndarray
    B0: np.ndarray
    C0: np.ndarray
    Gamma: np.ndarray
    Phi: np.ndarray
    Theta: np.ndarray
    Omega: np.ndarray
    T: np.ndarray
    Q: np.ndarray
    lambda_bar1: float
    delta1: float
    delta2: float
    delta1_hat: float
    delta2_hat: float
    L_bar: np.ndarray
    H: np.ndarray
    Z: np.ndarray
    w: float
    lambda1: float
    lambda2: float
    alpha: float
    k1: float
    certificate: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def h(self) -> np.ndarray:
        """The gauge as a vector of ±1."""
        return np.diag(self.H).copy()

    @property
    def z(self) -> np.ndarray:
        return np.diag(self.Z).copy()

    def to_json_dict(self) -> dict[str, Any]:
        """The fields as JSON-ready values (arrays as nested lists).

        Also copies the solver name, its version and the scenario hash from ``info`` to
        the top level.
        """
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = np.asarray(v).tolist() if isinstance(v, np.ndarray) else v
        out["solver"] = self.info.get("solver")
        out["solver_version"] = self.info.get("solver_version")
        out["scenario_sha256"] = self.info.get("scenario_sha256")
        return out


def gains_from_dict(d: dict[str, Any], *, source: str = "gains") -> Gains:
    """Rebuild :class:`Gains` from a JSON dictionary (no re-synthesis).

    Parameters
    ----------
    d : dict
        Parsed ``gains.json``; ``certificate`` and ``info`` may be absent.
    source : str
        Name of the source used in error messages (the file path).
    """
    kw: dict[str, Any] = {}
    for f in fields(Gains):
        if f.name not in d:
            if f.name in ("certificate", "info"):
                kw[f.name] = {}
                continue
            raise SynthesisError(f"{source}: key {f.name!r} is missing (re-run make synth)")
        v = d[f.name]
        if f.name in _MATRICES:
            a = np.array(v, dtype=float)
            kw[f.name] = np.atleast_2d(a) if a.ndim < 2 else a
        elif f.name in ("certificate", "info"):
            kw[f.name] = v
        else:
            kw[f.name] = float(v)
    return Gains(**kw)


def save_gains(gains: Gains, path: str | Path) -> Path:
    """Write ``gains.json`` atomically (temporary file in the same folder, then rename).

    Parameters
    ----------
    gains : Gains
        The gains to write.
    path : str or Path
        Destination file; its folder is created.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(gains.to_json_dict(), indent=2, sort_keys=True)
    atomic_write_text(path, text)
    return path


def load_gains(path: str | Path) -> Gains:
    """Read a ``gains.json`` written by :func:`save_gains`.

    Parameters
    ----------
    path : str or Path
        A ``gains.json`` file.
    """
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except OSError as exc:
        raise SynthesisError(
            f"{path}: cannot be read ({exc.strerror}); run make synth first"
        ) from None
    except json.JSONDecodeError as exc:
        raise SynthesisError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return gains_from_dict(d, source=str(path))
