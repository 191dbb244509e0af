"""The synthesis artifact: certified gains, written to and read from ``gains.json``.

This is the one interface between synthesis and everything downstream: the
closed loop, the simulation and the verification read a :class:`Gains` and
never reach back into the synthesis code.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from core.artifacts import atomic_write_text, sha256_bytes
from core.errors import SynthesisError
from core.files import FileRefused, parse_json, read_regular_file
from core.json_types import JSONObject
from core.scenario import Scenario
from synthesis.certificate_record import CertificateRecord

#: largest gains.json read (N = 50 gives some 100 kB) and its deepest nesting (matrices: 3)
MAX_GAINS_BYTES = 64 << 20
MAX_GAINS_DEPTH = 16
MATRIX_FIELDS = ("A0", "B0", "C0", "Gamma", "Phi", "Theta", "Omega", "T", "Q", "L_bar", "H", "Z")


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
    certificate : CertificateRecord
        The JSON form of a :class:`synthesis.certificate.Certificate`
        (:meth:`~synthesis.certificate.Certificate.to_json`): ``{"checks": [{"name",
        "value", "margin", "passed", "detail", "involves", "eq"}...], "warnings": [...],
        "failures": [...], "passed": bool, "tol": float, "given": [...], "notes": [...]}``.
        ``warnings`` are failed checks involving only scenario-given gains; ``failures``
        is empty in any file ``make synth`` writes.
    info : JSONObject
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
    certificate: CertificateRecord = field(default_factory=lambda: CertificateRecord())
    info: JSONObject = field(default_factory=dict)

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


def _fix(source: str) -> str:
    return f"(delete {source} and re-run make synth)"


def _matrix(v: Any, name: str, source: str) -> np.ndarray:
    """A field as a finite 2-D float array, or a one-line error naming it."""
    try:
        a = np.array(v, dtype=float)
    except (ValueError, TypeError):
        raise SynthesisError(
            f"{source}: field {name!r} is not a rectangular array of numbers {_fix(source)}"
        ) from None
    if a.ndim > 2:
        raise SynthesisError(
            f"{source}: field {name!r} has {a.ndim} dimensions, not 2 {_fix(source)}"
        )
    if not np.all(np.isfinite(a)):
        raise SynthesisError(f"{source}: field {name!r} is not finite {_fix(source)}")
    return np.atleast_2d(a) if a.ndim < 2 else a


def _scalar(v: Any, name: str, source: str) -> float:
    """A field as a finite float (not a bool, string or null), or a one-line error."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise SynthesisError(
            f"{source}: field {name!r} is {type(v).__name__}, not a number {_fix(source)}"
        )
    x = float(v)
    if not math.isfinite(x):
        raise SynthesisError(f"{source}: field {name!r} = {x} is not finite {_fix(source)}")
    return x


def gains_from_dict(d: Any, *, source: str = "gains") -> Gains:
    """Rebuild :class:`Gains` from a JSON dictionary (no re-synthesis, no certification).

    Parameters
    ----------
    d : dict
        Parsed ``gains.json``; ``certificate`` and ``info`` may be absent.
    source : str
        Name of the source used in error messages (the file path).

    Raises
    ------
    SynthesisError
        One line naming the field: missing, not a rectangular array of numbers, not a
        number, not finite, or the top level is not a JSON object.
    """
    if not isinstance(d, dict):
        raise SynthesisError(
            f"{source}: top level is {type(d).__name__}, not a JSON object {_fix(source)}"
        )
    kw: dict[str, Any] = {}
    for f in fields(Gains):
        if f.name not in d:
            if f.name in ("certificate", "info"):
                kw[f.name] = {}
                continue
            raise SynthesisError(f"{source}: key {f.name!r} is missing {_fix(source)}")
        v = d[f.name]
        if f.name in MATRIX_FIELDS:
            kw[f.name] = _matrix(v, f.name, source)
        elif f.name in ("certificate", "info"):
            if not isinstance(v, dict):
                raise SynthesisError(
                    f"{source}: field {f.name!r} is {type(v).__name__}, not an object "
                    f"{_fix(source)}"
                )
            kw[f.name] = v
        else:
            kw[f.name] = _scalar(v, f.name, source)
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


@dataclass(frozen=True)
class GainsFile:
    """A ``gains.json`` parsed but not yet certified.

    Attributes
    ----------
    gains : Gains
        The numbers as stored (certificate not yet re-checked).
    sha256 : str
        SHA-256 of the bytes parsed (the ones the gains come from).
    scenario_sha256 : str or None
        The scenario hash the file claims.
    """

    gains: Gains
    sha256: str
    scenario_sha256: str | None


def read_gains_file(path: str | Path) -> GainsFile:
    """Read and parse a ``gains.json`` once (no certification).

    Parameters
    ----------
    path : str or Path
        A ``gains.json`` file.

    Raises
    ------
    SynthesisError
        Unreadable, not a regular file of at most :data:`MAX_GAINS_BYTES` (a FIFO or
        ``/dev/zero`` is refused unread), nested deeper than :data:`MAX_GAINS_DEPTH`,
        not UTF-8, not JSON, or a malformed field (one line naming it).
    """
    path = Path(path)
    try:
        data = read_regular_file(path, MAX_GAINS_BYTES)
    except OSError as exc:
        raise SynthesisError(
            f"{path}: cannot be read ({exc.strerror}); run make synth first"
        ) from None
    except FileRefused as exc:
        raise SynthesisError(f"{path}: {exc} (give a gains.json written by make synth)") from None
    try:
        d = parse_json(data, MAX_GAINS_DEPTH)
    except FileRefused as exc:
        raise SynthesisError(f"{path}: not a gains file: it {exc} {_fix(str(path))}") from None
    except UnicodeDecodeError:
        raise SynthesisError(f"{path}: not UTF-8 text (corrupt) {_fix(str(path))}") from None
    except json.JSONDecodeError as exc:
        raise SynthesisError(
            f"{path}: not valid JSON ({exc.msg} at line {exc.lineno}) {_fix(str(path))}"
        ) from None
    g = gains_from_dict(d, source=str(path))
    claimed = d.get("scenario_sha256")
    return GainsFile(g, sha256_bytes(data), claimed if isinstance(claimed, str) else None)


def load_gains(
    path: str | Path, scenario: Scenario | None = None, *, recertify: bool = True
) -> Gains:
    """Read a ``gains.json`` and re-certify it from its numbers before anything uses it.

    The stored certificate is not trusted: :func:`recertified` re-runs
    :func:`synthesis.certificate.certify` (eigenvalue checks of LMIs (15)/(16),
    λ1 > λ̄1/w, Lemma 3, k1, shapes and finiteness) and, given the scenario, checks
    that the file was made for it.

    Parameters
    ----------
    path : str or Path
        A ``gains.json`` file.
    scenario : Scenario, optional
        The scenario the gains are for: its data fix the leader, graph, LMI
        parameters and the gains it gives, and which gains count as given.
    recertify : bool
        False only to read the numbers as they are (e.g. to inspect a broken file).

    Returns
    -------
    Gains
        With ``certificate`` replaced by the fresh one.

    Raises
    ------
    SynthesisError
        One line naming the unreadable/malformed field or the failed condition, and
        the fix. Failures are refused whatever ``STRICT`` says; failed checks that
        involve only scenario-given gains stay warnings (as at synthesis).
    """
    g = read_gains_file(path).gains
    return recertified(g, str(path), scenario) if recertify else g


def given_by(scenario: Scenario) -> tuple[str, ...]:
    """The gains the scenario gives explicitly (the rest are synthesised).

    Parameters
    ----------
    scenario : Scenario
        A loaded scenario.
    """
    obs = scenario.observer
    return tuple(k for k in ("Q", "Theta", "lambda1", "lambda2") if getattr(obs, k) is not None)


def scenario_mismatch(g: Gains, scenario: Scenario) -> str | None:
    """The first field of ``g`` that contradicts the scenario it claims to be for, or None.

    Checked: the leader (A0, B0, C0, α), the LMI parameters (λ̄1, δ1, δ2, δ̂1, δ̂2),
    every gain the scenario gives, and L̄ = H(L + B)H, H of the scenario's graph.

    Parameters
    ----------
    g : Gains
        Gains read from a file.
    scenario : Scenario
        The scenario.
    """
    from core.graph import check_network

    lead, obs = scenario.leader, scenario.observer
    want: dict[str, Any] = {"A0": lead.A0, "B0": lead.B0, "C0": lead.C0, "alpha": lead.alpha}
    for k in ("lambda_bar1", "delta1", "delta2", "delta1_hat", "delta2_hat"):
        want[k] = getattr(obs, k)
    want.update({k: getattr(obs, k) for k in given_by(scenario)})
    for name, v in want.items():
        a, b = np.asarray(getattr(g, name), dtype=float), np.asarray(v, dtype=float)
        if name in MATRIX_FIELDS:
            b = np.atleast_2d(b) if b.ndim < 2 else b
        if a.shape != b.shape or not np.array_equal(a, b):
            return f"field {name!r} differs from the scenario's"
    net = check_network(scenario.graph.adjacency, scenario.graph.pinning)
    for name, v in (("L_bar", net.L_bar.toarray()), ("H", np.diag(net.h))):
        a = getattr(g, name)
        if a.shape != v.shape or not np.allclose(a, v, rtol=1e-12, atol=0.0):
            return f"field {name!r} is not H(L + B)H of the scenario's graph"
    return None


def recertified(g: Gains, source: str, scenario: Scenario | None = None) -> Gains:
    """``g`` with a fresh certificate, or a one-line :class:`SynthesisError`.

    Parameters
    ----------
    g : Gains
        Gains read from a file.
    source : str
        The file, for messages.
    scenario : Scenario, optional
        If given, :func:`scenario_mismatch` must find nothing and the given gains are
        the scenario's (else the file's ``info["given"]``).
    """
    from synthesis.certificate import certify
    from synthesis.switching import check_topologies

    if scenario is not None:
        why = scenario_mismatch(g, scenario)
        if why is not None:
            raise SynthesisError(f"{source}: {why} (scenario {scenario.name}) {_fix(source)}")
        try:  # every topology of a switching graph, with these gains
            check_topologies(scenario, g.h, g.lambda1, g.lambda_bar1)
        except SynthesisError as exc:
            raise SynthesisError(f"{source}: {exc}") from None
        given = given_by(scenario)
    else:
        raw = g.info.get("given", [])
        given = tuple(x for x in raw if isinstance(x, str)) if isinstance(raw, list) else ()
    # the file's own list of given gains is not trusted when the scenario is known
    checked = replace(g, info={**g.info, "given": list(given)})
    try:
        cert = certify(checked, given=given)
    except (ValueError, IndexError, TypeError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise SynthesisError(
            f"{source}: certificate cannot evaluate the numbers ({type(exc).__name__}: {exc}) "
            f"{_fix(source)}"
        ) from None
    if cert.failures():
        raise SynthesisError(
            f"{source}: certificate fails: " + "; ".join(cert.failures()) + f" {_fix(source)}"
        )
    old = g.certificate if isinstance(g.certificate, dict) else {}
    return replace(checked, certificate={**old, **cert.to_json()})
