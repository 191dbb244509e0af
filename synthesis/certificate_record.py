"""The certificate as ``gains.json`` stores it: the JSON form of
:class:`synthesis.certificate.Certificate`, typed for the readers of ``Gains.certificate``.
"""

from __future__ import annotations

from typing import NotRequired, TypedDict

from core.json_types import JSONValue


class ProofRecord(TypedDict):
    """One definiteness test of a check's matrix (:meth:`synthesis.verified.Proof.to_json`).

    ``test`` is ``"rump-cholesky"``, ``"exact-rational"`` or ``"numpy-eigvalsh"``; ``margin``
    the m with λ_min > m proven (the rigorous tests) or numpy's λ_min estimate.
    """

    test: str
    passed: bool
    margin: float | None
    detail: str


class CheckRecord(TypedDict):
    """One check (:meth:`synthesis.certificate.Check.to_json`); non-finite numbers are None.

    ``proofs`` (matrix inequalities only): the tests of :mod:`synthesis.verified` that were run
    on the check's matrix, and ``proved`` the matrix they were run on.
    """

    name: str
    value: JSONValue
    margin: float | None
    passed: bool
    detail: str
    involves: list[str]
    eq: str
    proved: NotRequired[str]
    proofs: NotRequired[list[ProofRecord]]


class CertificateRecord(TypedDict, total=False):
    """Every check and what they add up to (:meth:`synthesis.certificate.Certificate.to_json`).

    ``warnings`` are failed checks that involve only scenario-given gains, ``failures`` the
    others; ``notes`` is present when the synthesis recorded notes. An empty record means
    not yet certified.
    """

    checks: list[CheckRecord]
    warnings: list[str]
    failures: list[str]
    passed: bool
    tol: float
    given: list[str]
    notes: list[str]
