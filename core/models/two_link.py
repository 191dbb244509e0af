"""The paper's follower (section 4): a planar two-link arm, n = 2."""

from __future__ import annotations

from core.models.base import ModelSpec, register


def _lagrangian(prm):
    import sympy as sp  # on first derivation only: a cached model needs no sympy

    p1, p2 = sp.symbols("p1 p2", real=True)
    q1, q2 = sp.symbols("q1 q2", real=True)
    m1, m2, r1, r2, J1, J2, g0 = (
        sp.nsimplify(prm[k]) for k in ("m1", "m2", "r1", "r2", "J1", "J2", "g0")
    )
    # point masses at the link ends plus rotor inertias J1 (on q1) and J2 (on q1 + q2):
    # this reproduces the closed forms of docs/reading.md, 'Followers', exactly
    T = sp.Rational(1, 2) * (m1 + m2) * r1**2 * q1**2
    T += (
        sp.Rational(1, 2)
        * m2
        * (r2**2 * (q1 + q2) ** 2 + 2 * r1 * r2 * sp.cos(p2) * q1 * (q1 + q2))
    )
    T += sp.Rational(1, 2) * J1 * q1**2 + sp.Rational(1, 2) * J2 * q2**2
    V = g0 * ((m1 + m2) * r1 * sp.sin(p1) + m2 * r2 * sp.sin(p1 + p2))
    return T, V, [p1, p2], [q1, q2]


SPEC = register(
    ModelSpec(
        name="two_link",
        n=2,
        defaults={"m1": 0.5, "m2": 1.5, "r1": 1.0, "r2": 0.8, "J1": 5.0, "J2": 5.0, "g0": 9.81},
        lagrangian=_lagrangian,
        description="planar two-link arm of the paper's section 4 (M, C, G as printed)",
        nonnegative=frozenset({"g0", "J1", "J2"}),  # g0 = 0: horizontal plane; J = 0: no rotors
    )
)
