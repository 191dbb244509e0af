"""Planar point-mass UAV, n = 2: horizontal position (x, y) of a vehicle of mass ``m``.

T = ½ m (ẋ² + ẏ²), V = 0, so M = m I₂, C = 0, G = 0: the simplest follower that
satisfies eq. (2), with the paper's faults g_i, f_i acting on the two force channels.
"""

from __future__ import annotations

from core.models.base import ModelSpec, register


def _lagrangian(prm):
    import sympy as sp  # on first derivation only: a cached model needs no sympy

    p = list(sp.symbols("x y", real=True))
    q = list(sp.symbols("vx vy", real=True))
    m = sp.nsimplify(prm["m"])
    T = sp.Rational(1, 2) * m * (q[0] ** 2 + q[1] ** 2)  # eq. (1): M = mI, C = 0, G = 0
    return T, sp.Integer(0), p, q


SPEC = register(
    ModelSpec(
        name="point_mass_2d",
        n=2,
        defaults={"m": 1.5},  # kg, a small multirotor
        lagrangian=_lagrangian,
        description="planar point-mass UAV (horizontal x, y; M = m I, C = 0, G = 0)",
    )
)
