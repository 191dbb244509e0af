"""Where η̈_i, ḃ_i and b̈_i come from (docs/reading.md, 'Controller'; docs/fidelity.md, D9).

Eq. (29) uses η̈_i and, with a rotating formation, ḃ_i and b̈_i (hence η⃛_i).
The paper does not say how a follower obtains them. Two options:

``oracle``
    Exact time derivatives along the observer network's flow by forward-mode
    AD (``jtimes``). Agent i's observer flow is ``ṡ_i = f(s_i, ψ_i)`` with ψ_i
    linear in the neighbours' η_j and in y0, so
    ``s̈_i = J·(ṡ_i, ψ̇_i)`` and ``s⃛_i = d/dt[J·(ṡ_i, ψ̇_i)]`` need ψ̇_i and ψ̈_i,
    i.e. the neighbours' η̇_j, η̈_j and ẏ0, ÿ0 (through u0(t) and u̇0(t)). They
    are computed in passes over the network: η̇ of all agents → ψ̇ → η̈ of all
    agents → ψ̈ (see :mod:`symbolic.closed_loop`).
``filtered``
    Each follower runs local linear state-variable filters on its own signals:
    a critically damped second-order filter on η̇_i (its derivative state
    estimates η̈_i) and a third-order one on b_i (estimates ḃ_i, b̈_i), all
    poles at −ω (``options.filter_bandwidth``). Extra states, no
    finite differences of sampled data.
"""

from __future__ import annotations

import casadi as ca


def flow_jets(flow: ca.Function) -> tuple[ca.Function, ca.Function]:
    """First and second time derivatives of a local flow ``ṡ = f(s, ψ; prm)`` by forward AD.

    Parameters
    ----------
    flow : casadi.Function
        Inputs ``(so, psi, prm)``, first output ``sodot``.

    Returns
    -------
    D1 : casadi.Function
        ``(so, psi, prm, dso, dpsi) -> ddso`` with ``ddso = ∂f/∂s·dso + ∂f/∂ψ·dpsi``.
    D2 : casadi.Function
        ``(so, psi, prm, dso, dpsi, ddso, ddpsi) -> dddso``, the time derivative of D1's
        output along ``(ṡ, ψ̇, s̈, ψ̈)``.
    """
    so = ca.SX.sym("so", flow.size1_in(0))
    psi = ca.SX.sym("psi", flow.size1_in(1))
    prm = ca.SX.sym("prm", flow.size1_in(2))
    dso, dpsi = ca.SX.sym("dso", so.numel()), ca.SX.sym("dpsi", psi.numel())
    ddso, ddpsi = ca.SX.sym("ddso", so.numel()), ca.SX.sym("ddpsi", psi.numel())
    f = flow(so, psi, prm)[0] if flow.n_out() > 1 else flow(so, psi, prm)
    d1 = ca.jtimes(f, ca.vertcat(so, psi), ca.vertcat(dso, dpsi))
    d2 = ca.jtimes(
        d1, ca.vertcat(so, psi, dso, dpsi), ca.vertcat(dso, dpsi, ddso, ddpsi)
    )  # d/dt of d1 along the flow: J·(s̈, ψ̈) + f''[ṡ, ψ̇]²
    D1 = ca.Function(
        "D1", [so, psi, prm, dso, dpsi], [d1], ["so", "psi", "prm", "dso", "dpsi"], ["ddso"]
    )
    D2 = ca.Function(
        "D2",
        [so, psi, prm, dso, dpsi, ddso, ddpsi],
        [d2],
        ["so", "psi", "prm", "dso", "dpsi", "ddso", "ddpsi"],
        ["dddso"],
    )
    return D1, D2


def filter_sizes(m: int, n: int) -> tuple[int, int]:
    """Numbers of filter states: (2m for η̇_i, 3n for b_i).

    Parameters
    ----------
    m : int
        Leader state size.
    n : int
        Coordinates per follower.
    """
    return 2 * m, 3 * n


def filter_function(m: int, n: int, omega: float) -> ca.Function:
    """Local derivative filters of one follower.

    ``w = (w1, w2)``: ``ẇ1 = w2``, ``ẇ2 = ω²(η̇_i − w1) − 2ω w2``, transfer
    ω²/(s+ω)² to w1, so ``w2`` estimates η̈_i. ``z = (z1, z2, z3)``:
    ``ż1 = z2``, ``ż2 = z3``, ``ż3 = ω³(b_i − z1) − 3ω² z2 − 3ω z3``, transfer
    ω³/(s+ω)³ to z1, so ``z2``, ``z3`` estimate ḃ_i, b̈_i. The estimates lag
    the true derivatives by about 3/ω (2/ω for w2): exact for a derivative that
    is constant, a lag error of (3/ω)·(next derivative) otherwise.

    Parameters
    ----------
    m : int
        Leader state size (η̇_i has m entries).
    n : int
        Coordinates per follower (b_i has n entries).
    omega : float
        Filter bandwidth ω in rad/s (``options.filter_bandwidth``).

    Returns
    -------
    casadi.Function
        ``(w, z, etadot, b) -> (wdot, zdot, etaddot_hat, bdot_hat, bddot_hat)``.
    """
    w = ca.SX.sym("w", 2 * m)
    z = ca.SX.sym("z", 3 * n)
    etadot = ca.SX.sym("etadot", m)
    b = ca.SX.sym("b", n)
    w1, w2 = w[:m], w[m:]
    z1, z2, z3 = z[:n], z[n : 2 * n], z[2 * n :]
    wdot = ca.vertcat(w2, omega**2 * (etadot - w1) - 2 * omega * w2)
    zdot = ca.vertcat(z2, z3, omega**3 * (b - z1) - 3 * omega**2 * z2 - 3 * omega * z3)
    return ca.Function(
        "filters",
        [w, z, etadot, b],
        [wdot, zdot, w2, z2, z3],
        ["w", "z", "etadot", "b"],
        ["wdot", "zdot", "etaddot_hat", "bdot_hat", "bddot_hat"],
    )
