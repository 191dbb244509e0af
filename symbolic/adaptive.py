"""Adaptive laws (30): θ̂ (disturbance bounds) and ĝ (estimate of 1/g_i), with the ĝ-law options.

``ĝ`` law options (``options.ghat_law``), r = −γ χᵀΨ (docs/reading.md, 'Controller'; D3, D4
in docs/fidelity.md):

- ``paper``: ĝ̇ = r (γ = 1 is the printed law, with χᵀΨ, not the printed χᵀMΨ);
- ``sigma``: ĝ̇ = r − σ(ĝ − ĝ_ref);
- ``projection``: ĝ̇ = Proj(r) keeping ĝ in [1, 1/g_min];
- ``sigma+projection``: Proj(r − σ(ĝ − ĝ_ref)).

The projection is Lipschitz (a smoothed Pomet–Praly projection): in a band of
width δ = 1 % of the interval just outside each end, the outward part of the
rate is faded out linearly,
``Proj(r) = r − w_hi(ĝ)·max(r, 0) − w_lo(ĝ)·min(r, 0)``, with ``w`` ramping from
0 at the end of the interval to 1 at distance δ outside. Inside [1, 1/g_min]
the law is untouched; ĝ never leaves [1 − δ, 1/g_min + δ]; and because the
removed part always points outward, V̇2 is not increased as long as 1/g_i lies
in [1, 1/g_min].
"""

from __future__ import annotations

import casadi as ca

GHAT_LAWS = ("paper", "sigma", "projection", "sigma+projection")
BAND = 0.01  # projection band, fraction of the interval [1, 1/g_min]


def projection(ghat: ca.SX, rate: ca.SX, lo: float, hi: float) -> ca.SX:
    """Lipschitz projection of ``rate`` keeping ``ghat`` in ``[lo, hi]`` (see module docstring).

    Parameters
    ----------
    ghat : casadi.SX
        Current ĝ_i.
    rate : casadi.SX
        Unprojected rate of ĝ_i.
    lo, hi : float
        Interval kept, here [1, 1/g_min]; ``hi - lo <= 1e-12`` freezes ĝ (rate 0).
    """
    if hi - lo <= 1e-12:
        return 0 * rate  # interval collapsed (g_min = 1): ĝ is frozen
    delta = BAND * (hi - lo)
    w_hi = ca.fmin(ca.fmax((ghat - hi) / delta, 0.0), 1.0)
    w_lo = ca.fmin(ca.fmax((lo - ghat) / delta, 0.0), 1.0)
    return rate - w_hi * ca.fmax(rate, 0.0) - w_lo * ca.fmin(rate, 0.0)


def adaptive_function(n: int, law: str, g_min: float) -> ca.Function:
    """One follower's adaptive laws as a Function.

    Inputs ``chi, Psi, thetahat, ghat, k2, gamma, sigma, ghat_ref``; outputs
    ``thetahat_dot`` and ``ghat_dot``.

    Parameters
    ----------
    n : int
        Number of coordinates of the follower.
    law : {"paper", "sigma", "projection", "sigma+projection"}
        The ĝ law (``options.ghat_law``).
    g_min : float
        Designer's worst health; the projection keeps ĝ in [1, 1/g_min].
    """
    if law not in GHAT_LAWS:
        raise ValueError(f"unknown ghat law {law!r}")
    chi, Psi, thetahat = ca.SX.sym("chi", n), ca.SX.sym("Psi", n), ca.SX.sym("thetahat", n)
    ghat, k2, gamma, sigma, gref = (
        ca.SX.sym(s) for s in ("ghat", "k2", "gamma", "sigma", "ghat_ref")
    )
    thetahat_dot = ca.fabs(chi) - k2 * thetahat  # eq. (30), element-wise
    rate = -gamma * ca.dot(chi, Psi)  # eq. (30) with gain γ and χᵀΨ (paper prints χᵀMΨ)
    if "sigma" in law:
        rate = rate - sigma * (ghat - gref)  # σ-modification (docs/fidelity.md, D3)
    if "projection" in law:
        rate = projection(ghat, rate, 1.0, 1.0 / g_min)
    return ca.Function(
        "adaptive",
        [chi, Psi, thetahat, ghat, k2, gamma, sigma, gref],
        [thetahat_dot, rate],
        ["chi", "Psi", "thetahat", "ghat", "k2", "gamma", "sigma", "ghat_ref"],
        ["thetahat_dot", "ghat_dot"],
    )
