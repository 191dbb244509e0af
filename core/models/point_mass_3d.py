"""3-D point-mass UAV with gravity, n = 3: position (x, y, z), z pointing up.

T = ½ m ‖v‖², V = m g0 z, so M = m I₃, C = 0, G = (0, 0, m g0): the thrust must
carry the weight, so a loss of effectiveness g_i < 1 biases the vertical channel.
"""

from __future__ import annotations

from core.models.base import ModelSpec, register


def _lagrangian(prm):
    import sympy as sp  # on first derivation only: a cached model needs no sympy

    p = list(sp.symbols("x y z", real=True))
    q = list(sp.symbols("vx vy vz", real=True))
    m, g0 = (sp.nsimplify(prm[k]) for k in ("m", "g0"))
    T = sp.Rational(1, 2) * m * sum(v**2 for v in q)  # eq. (1) with gravity: M = mI, C = 0
    V = m * g0 * p[2]
    return T, V, p, q


SPEC = register(
    ModelSpec(
        name="point_mass_3d",
        n=3,
        defaults={"m": 1.5, "g0": 9.81},  # kg, m/s²
        nonnegative=frozenset({"g0"}),  # g0 = 0: gravity-free
        lagrangian=_lagrangian,
        description="3-D point-mass UAV with gravity (z up; M = m I, C = 0, G = (0, 0, m g0))",
    )
)
