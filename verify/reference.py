"""An independent, plainly written numpy implementation of the closed-loop right-hand side.

This is "what a user writes by hand": every equation of docs/reading.md, 'Network' to 'Formation',
in vectorised numpy, with the oracle derivatives (η̈_i, η⃛_i, ḃ_i, b̈_i) worked
out with the chain rule on paper, not by automatic differentiation. It shares
no code with ``symbolic/`` beyond the scenario loader, the expression parser's
tree (evaluated here by its own dual-number walker) and the model's sympy
expressions for models other than the paper's two-link arm (whose closed forms
are written out below). Tests compare :meth:`Reference.rhs` with the CasADi
closed loop; the benchmark uses it as the hand-written baseline.

State order (docs/closed-loop.md): ``x = (η0, s_1, …, s_N)``,
``s_i = (μ_i, η_i, φ_i, p_i, q_i, θ̂_i, ĝ_i[, w_i (2m), z_i (3n)])``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla

from core.expression_tree import BinOp, Call, Neg, Node, Num, Time, Visitor, visit
from core.graph import fade_jets
from core.hold import shaped_hold
from core.scenario import Scenario
from synthesis.gains import Gains
from verify.lyapunov import sgn_eps


def _mv(Mx: np.ndarray, vx: np.ndarray) -> np.ndarray:
    """Row-wise matrix-vector products: (K, i, j) × (K, j) → (K, i)."""
    return np.einsum("kij,kj->ki", Mx, vx)


# ----------------------------------------------------------------------------- expressions
def _dual(node: Node, t: float) -> tuple[float, float]:
    """Value and d/dt of an expression tree (forward dual numbers, written out by hand)."""
    return visit(node, _Dual(t))


class _Dual(Visitor[tuple[float, float]]):
    """:func:`_dual` at time ``t``: each node's value and derivative from its children's."""

    def __init__(self, t: float) -> None:
        self.t = t

    def num(self, node: Num) -> tuple[float, float]:
        return float(node.value), 0.0

    def time(self, node: Time) -> tuple[float, float]:
        return float(self.t), 1.0

    def neg(self, node: Neg) -> tuple[float, float]:
        a, da = visit(node.arg, self)
        return -a, -da

    def binop(self, node: BinOp) -> tuple[float, float]:
        (a, da), (b, db) = visit(node.left, self), visit(node.right, self)
        op = node.op
        if op == "+":
            return a + b, da + db
        if op == "-":
            return a - b, da - db
        if op == "*":
            return a * b, da * b + a * db
        if op == "/":
            return a / b, (da * b - a * db) / b**2
        val = a**b
        dval = b * a ** (b - 1) * da if db == 0 else val * (db * math.log(a) + b * da / a)
        return val, dval

    def call(self, node: Call) -> tuple[float, float]:
        return _dual_call(node.name, [visit(x, self) for x in node.args])


def _dual_call(name: str, args: list[tuple[float, float]]) -> tuple[float, float]:
    """Value and derivative of the function ``name`` at its arguments' duals."""
    (a, da) = args[0]
    if name == "sin":
        return math.sin(a), math.cos(a) * da
    if name == "cos":
        return math.cos(a), -math.sin(a) * da
    if name == "tan":
        return math.tan(a), da / math.cos(a) ** 2
    if name == "exp":
        return math.exp(a), math.exp(a) * da
    if name == "log":
        return math.log(a), da / a
    if name == "sqrt":
        return math.sqrt(a), da / (2 * math.sqrt(a))
    if name == "abs":
        return abs(a), float(np.sign(a)) * da
    if name == "tanh":
        return math.tanh(a), (1 - math.tanh(a) ** 2) * da
    if name == "step":
        return (1.0 if a >= 0 else 0.0), 0.0
    if name == "sat":
        return min(max(a, -1.0), 1.0), (da if -1 < a < 1 else 0.0)
    if name == "smoothstep":  # 3s² − 2s³ on [0, 1], flat outside
        s = min(max(a, 0.0), 1.0)
        return s * s * (3 - 2 * s), 6 * s * (1 - s) * da
    if name == "prefilter":  # 1 − (1 + s)e^(−s) for s ≥ 0, flat before
        s = max(a, 0.0)
        return 1 - (1 + s) * math.exp(-s), s * math.exp(-s) * da
    (b, db) = args[1]
    if name == "atan2":
        r2 = a * a + b * b
        return math.atan2(a, b), (b * da - a * db) / r2
    if name == "min":
        return (a, da) if a < b else (b, db)
    if name == "max":
        return (a, da) if a > b else (b, db)
    raise ValueError(name)


# ----------------------------------------------------------------------------- models
def _two_link(prm: dict[str, float]):
    """The paper's closed forms (docs/reading.md, 'Followers'), vectorised over agents."""
    m1, m2, r1, r2, J1, J2, g0 = (prm[k] for k in ("m1", "m2", "r1", "r2", "J1", "J2", "g0"))

    def mcg(p: np.ndarray, q: np.ndarray):
        c2 = np.cos(p[:, 1])
        m11 = (m1 + m2) * r1**2 + m2 * r2**2 + 2 * m2 * r1 * r2 * c2 + J1
        m12 = m2 * r2**2 + m2 * r1 * r2 * c2
        m22 = np.full_like(c2, m2 * r2**2 + J2)
        M = np.stack([np.stack([m11, m12], -1), np.stack([m12, m22], -1)], -2)
        c = m2 * r1 * r2 * np.sin(p[:, 1])
        C = np.stack(
            [
                np.stack([-c * q[:, 1], -c * (q[:, 0] + q[:, 1])], -1),
                np.stack([c * q[:, 0], np.zeros_like(c)], -1),
            ],
            -2,
        )
        G = np.stack(
            [
                ((m1 + m2) * r1 * np.cos(p[:, 0]) + m2 * r2 * np.cos(p[:, 0] + p[:, 1])) * g0,
                m2 * r2 * np.cos(p[:, 0] + p[:, 1]) * g0,
            ],
            -1,
        )
        return M, C, G

    return mcg


def _generic_model(name: str, prm: dict[str, float]):
    """Other models: numpy lambdas of the model's sympy M, C, G (+ D, its dissipation)."""
    import sympy as sp

    from core.models import build_model

    mod = build_model(name, prm)
    syms = list(mod.sympy_p) + list(mod.sympy_q)
    fM = sp.lambdify(syms, mod.sympy_M, "numpy")
    fC = sp.lambdify(syms, mod.sympy_C, "numpy")
    # the dissipative force D(p, q) enters eq. (2) beside G: the "G" returned is G + D
    fG = sp.lambdify(
        syms, mod.sympy_G if mod.sympy_D is None else mod.sympy_G + mod.sympy_D, "numpy"
    )

    def mcg(p: np.ndarray, q: np.ndarray):
        out = []
        for k in range(p.shape[0]):
            a = list(p[k]) + list(q[k])
            out.append(
                (
                    np.array(fM(*a), dtype=float),
                    np.array(fC(*a), dtype=float),
                    np.array(fG(*a), dtype=float).reshape(-1),
                )
            )
        return tuple(np.array([o[j] for o in out]) for j in range(3))

    return mcg


# ----------------------------------------------------------------------------- the loop
@dataclass
class Reference:
    """Plain numpy closed loop of a scenario with given gains.

    Parameters
    ----------
    sc : Scenario
    gains : Gains
        Uses A0/B0/C0 from the scenario and Theta, Q, lambda1, lambda2, H from the gains.
    """

    sc: Scenario
    gains: Gains

    def __post_init__(self) -> None:
        sc, gn = self.sc, self.gains
        L = sc.leader
        self.A0, self.B0, self.C0 = (np.asarray(a, dtype=float) for a in (L.A0, L.B0, L.C0))
        self.m, self.n, self.N, self.p = sc.m, sc.n, sc.N, sc.p
        m, n = self.m, self.n
        CB = self.C0 @ self.B0
        self.Gamma = self.B0 @ np.linalg.inv(CB.T @ CB) @ CB.T  # eq. (7)
        self.Phi = np.eye(m) - self.Gamma @ self.C0  # eq. (7)
        Th = np.atleast_2d(np.asarray(gn.Theta, dtype=float))
        self.F = self.Phi @ self.A0 - Th @ self.C0  # eq. (8)
        self.K = (
            Th @ (np.eye(n) - self.C0 @ self.Gamma) + self.Phi @ self.A0 @ self.Gamma
        )  # eq. (7)
        self.Q = np.atleast_2d(np.asarray(gn.Q, dtype=float)).reshape(self.p, m)
        self.l1, self.l2 = float(gn.lambda1), float(gn.lambda2)
        A = np.asarray(sc.graph.adjacency, dtype=float)
        self.a0 = np.asarray(sc.graph.pinning, dtype=float)
        self.h = np.diag(np.atleast_2d(gn.H)).astype(float)
        self.LB = np.diag(np.abs(A).sum(1) + self.a0) - A
        self.a0h = self.a0 * self.h
        # a switching graph: (t_start, L + B, a0 ∘ h) of every topology, h of the gains
        self.tops = [
            (tp.t_start, np.diag(np.abs(tp.adjacency).sum(1) + tp.pinning) - tp.adjacency)
            + (tp.pinning * self.h,)
            for tp in sc.graph.topologies()
        ]
        self.fade = float(sc.graph.link_fade)
        o, c = sc.observer, sc.controller
        self.alpha_sum = np.asarray(o.alpha1) + np.asarray(o.alpha1_bar)
        self.phi_min = float(o.phi_min)
        self.Lam, self.k1 = np.asarray(c.Lambda), np.asarray(c.k1)
        self.k2, self.gam = np.asarray(c.k2), np.asarray(c.gamma)
        self.sig, self.gref = np.asarray(c.sigma), np.asarray(c.ghat_ref)
        # actuator limit per follower (None = no limit)
        self.u_max = None if c.u_max is None else np.asarray(c.u_max, dtype=float)
        self.b0 = np.array([f.b0 for f in sc.followers])
        self.opts = sc.options
        self.filtered = self.opts.derivatives == "filtered"
        self.na = 2 * m + 1 + 3 * n + 1 + ((2 * m + 3 * n) if self.filtered else 0)
        # one model evaluator per (model, params) group
        self.groups: list[tuple[np.ndarray, Any]] = []
        keys: dict[tuple, list[int]] = {}
        for i, fo in enumerate(sc.followers):
            keys.setdefault((fo.model, tuple(sorted(fo.params.items()))), []).append(i)
        for (name, items), idx in keys.items():
            prm = dict(items)
            ev = _two_link(prm) if name == "two_link" else _generic_model(name, prm)
            self.groups.append((np.array(idx), ev))

    # -- pieces
    def mcg(self, p: np.ndarray, q: np.ndarray):
        """M (N×n×n), C (N×n×n), G (N×n) of every follower at (p, q) (N×n each).

        Parameters
        ----------
        p, q : ndarray
            N×n positions and velocities of all followers.
        """
        N, n = self.N, self.n
        M, C, G = np.zeros((N, n, n)), np.zeros((N, n, n)), np.zeros((N, n))
        for idx, ev in self.groups:
            M[idx], C[idx], G[idx] = ev(p[idx], q[idx])
        return M, C, G

    def leader(self, t: float, eta0: np.ndarray):
        """u0, u̇0, η̇0 (eq. (3)) and η̈0 at time t.

        Parameters
        ----------
        t : float
            Time.
        eta0 : ndarray
            Leader state η0 (m).
        """
        L = self.sc.leader
        if L.u0 is not None:
            u, ud = np.array([_dual(e.node, t) for e in L.u0]).T
        else:
            tr = np.asarray(L.u0_trace)
            ts = tr[:, 0]
            u = L.u0_numpy(t)
            j = np.searchsorted(ts, t, side="right") - 1
            if L.u0_hold and L.u0_rise > 0:  # each jump a smoothstep ramp: u̇0 ≠ 0 on it
                cols = range(1, tr.shape[1])
                ud = np.array([shaped_hold(ts, tr[:, k], L.u0_rise, t)[1] for k in cols])
            elif L.u0_hold or t < ts[0] or t > ts[-1] or j >= len(ts) - 1:
                ud = np.zeros(self.p)
            else:
                ud = (tr[j + 1, 1:] - tr[j, 1:]) / (ts[j + 1] - ts[j])
        e0d = self.A0 @ eta0 + self.B0 @ u  # eq. (3)
        e0dd = self.A0 @ e0d + self.B0 @ ud
        return u, ud, e0d, e0dd

    def faults(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """True health g_i(t) (N) and bias f_i(t) (N×n); only the plant uses them.

        Parameters
        ----------
        t : float
            Time.
        """
        g = np.array([float(fo.g.expr.numpy(t)) for fo in self.sc.followers])
        f = np.array([[float(e.numpy(t)) for e in fo.f] for fo in self.sc.followers])
        return g, f

    def split(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Named views of the flat state (agent blocks as N×k arrays).

        Parameters
        ----------
        x : ndarray
            Flat closed-loop state.
        """
        m, n = self.m, self.n
        x = np.asarray(x, dtype=float)
        S = x[m:].reshape(self.N, self.na)
        k = 0
        out = {"eta0": x[:m]}
        names = [
            ("mu", m),
            ("eta", m),
            ("phi", 1),
            ("p", n),
            ("q", n),
            ("thetahat", n),
            ("ghat", 1),
        ]
        if self.filtered:
            names += [("w", 2 * m), ("z", 3 * n)]
        for nm, s in names:
            out[nm] = S[:, k : k + s]
            k += s
        out["phi"] = out["phi"][:, 0]
        out["ghat"] = out["ghat"][:, 0]
        return out

    def _norm_jets(self, y, yd, ydd):
        """‖y‖ per row and its first two time derivatives (zero where y = 0)."""
        if self.p == 1:
            s = np.sign(y[:, 0])
            return np.abs(y[:, 0]), s * yd[:, 0], s * ydd[:, 0]
        nr = np.linalg.norm(y, axis=1)
        safe = np.where(nr > 0, nr, 1.0)
        yyd = np.sum(y * yd, 1)
        nd = np.where(nr > 0, yyd / safe, 0.0)
        ndd = np.where(
            nr > 0, (np.sum(yd * yd, 1) + np.sum(y * ydd, 1)) / safe - yyd**2 / safe**3, 0.0
        )
        return nr, nd, ndd

    def formation(self, d, dd, ddd):
        """b_i, ḃ_i, b̈_i of the formation rule (docs/closed-loop.md), chain rule by hand.

        b_i = q(σ) D(d) b_i0 + κ(σ) b_i0 with σ = ‖d‖², D(d) = [[d1, −d2], [d2, d1]]:
        q = σ^(−1/2) and κ = 0 for σ ≥ ε²; below, with w = 1 − σ/ε², q is the cubic
        Taylor polynomial of σ^(−1/2) at ε² and κ = w⁴(5 − 4w).

        Parameters
        ----------
        d, dd, ddd : ndarray
            N×m: η̇_i, η̈_i and η⃛_i of every follower.
        """
        b0 = self.b0
        if self.n != 2 or self.m < 2:
            z = np.zeros_like(b0)
            return b0.copy(), z, z
        eps = self.opts.tau_threshold
        d, dd, ddd = d[:, :2], dd[:, :2], ddd[:, :2]
        sg = np.sum(d * d, 1)
        sgd = 2 * np.sum(d * dd, 1)
        sgdd = 2 * (np.sum(dd * dd, 1) + np.sum(d * ddd, 1))
        inner = sg < eps**2
        # dq/dσ, d²q/dσ² and dκ/dσ, d²κ/dσ² in each branch (w = 1 − σ/ε², dw/dσ = −1/ε²)
        w = np.where(inner, 1 - sg / eps**2, 0.0)
        so = np.where(inner, eps**2, sg)  # outer branch evaluated only where it is used
        q = np.where(inner, (1 + w / 2 + 3 * w**2 / 8 + 5 * w**3 / 16) / eps, so**-0.5)
        q1 = np.where(inner, -(0.5 + 0.75 * w + 15 * w**2 / 16) / eps**3, -0.5 * so**-1.5)
        q2 = np.where(inner, (0.75 + 15 * w / 8) / eps**5, 0.75 * so**-2.5)
        k = w**4 * (5 - 4 * w)
        k1 = -(20 * w**3 - 20 * w**4) / eps**2
        k2 = (60 * w**2 - 80 * w**3) / eps**4
        qd, qdd = q1 * sgd, q2 * sgd**2 + q1 * sgdd
        kd, kdd = k1 * sgd, k2 * sgd**2 + k1 * sgdd
        c, s = d[:, 0] * q, d[:, 1] * q
        cd, sd = dd[:, 0] * q + d[:, 0] * qd, dd[:, 1] * q + d[:, 1] * qd
        cdd = ddd[:, 0] * q + 2 * dd[:, 0] * qd + d[:, 0] * qdd
        sdd = ddd[:, 1] * q + 2 * dd[:, 1] * qd + d[:, 1] * qdd

        def rot(c, s, k):
            return np.stack(
                [
                    c * b0[:, 0] - s * b0[:, 1] + k * b0[:, 0],
                    s * b0[:, 0] + c * b0[:, 1] + k * b0[:, 1],
                ],
                -1,
            )

        return rot(c, s, k), rot(cd, sd, kd), rot(cdd, sdd, kdd)

    def sgn(self, x):
        """The sign function of ``options.sign`` (exact, sat or tanh with width ε).

        Parameters
        ----------
        x : ndarray
            Argument, element-wise.
        """
        return sgn_eps(x, self.opts.sign, self.opts.sign_width)

    def evaluate(self, t: float, x: np.ndarray) -> dict[str, np.ndarray]:
        """All intermediate signals at (t, x), and ``xdot``.

        Parameters
        ----------
        t : float
            Time.
        x : ndarray
            Flat closed-loop state.
        """
        S = self.split(x)
        u0, u0d, e0d, e0dd = self.leader(t, S["eta0"])
        obs = self._observer(S, e0d, e0dd, t)
        Ed, Edd, Eddd = obs["etadot"], obs["etaddot"], obs["eta3dot"]
        b, bd, bdd = self.formation(Ed, Edd, Eddd)
        out: dict[str, np.ndarray] = {}
        if self.filtered:
            out["wdot"], out["zdot"], Edd, bd, bdd = self._filters(S, Ed, b)
            Eddd = np.zeros_like(Eddd)
        q = S["q"]
        M, C, G = self.mcg(S["p"], q)
        ctl = self._controller(S, (M, C, G), Ed, Edd, b, bd, bdd)
        r = self._ghat_rate(ctl["chi"], ctl["Psi"], S["ghat"])
        g, f = self.faults(t)
        force = g[:, None] * ctl["u"] + f - _mv(C, q) - G  # eq. (2)
        qd = np.linalg.solve(M, force[..., None])[..., 0]
        parts = [obs["mudot"], Ed, obs["phidot"][:, None], q, qd, ctl["thetahatdot"], r[:, None]]
        if self.filtered:
            parts += [out["wdot"], out["zdot"]]
        out["xdot"] = np.concatenate([e0d, np.hstack(parts).reshape(-1)])
        out.update(psi=obs["psi"], ehat=obs["ehat"], v=obs["v"], etadot=Ed, etaddot=Edd)
        out.update(eta3dot=Eddd, b=b, bdot=bd, bddot=bdd, et=ctl["et"], chi=ctl["chi"])
        out.update(Psi=ctl["Psi"], u=ctl["u"], qdot=qd, u0=u0, u0dot=u0d)
        return out

    def weights(self, t: float, derivative: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``(L + B, a0 ∘ h)`` at ``t``, or its first or second time derivative.

        Raw switching (``graph.link_fade`` = 0): the topology that holds at ``t``
        (right-continuous), derivatives 0. With a fade T: each switch's change of the
        weights enters as σ((t − s_k)/T) (:func:`core.graph.fade_jets`).

        Parameters
        ----------
        t : float
            Time.
        derivative : {0, 1, 2}
        """
        T = self.fade
        if len(self.tops) == 1 or T <= 0.0:
            if derivative:
                return 0.0 * self.LB, 0.0 * self.a0h
            if len(self.tops) == 1:
                return self.LB, self.a0h
            return next(tp for tp in reversed(self.tops) if tp[0] <= t)[1:]
        L = self.tops[0][1] * (derivative == 0)
        a = self.tops[0][2] * (derivative == 0)
        for prev, top in zip(self.tops, self.tops[1:], strict=False):
            c = fade_jets((t - top[0]) / T)[derivative] / T**derivative
            L = L + c * (top[1] - prev[1])
            a = a + c * (top[2] - prev[2])
        return L, a

    def _observer(
        self, S: dict[str, np.ndarray], e0d: np.ndarray, e0dd: np.ndarray, t: float = 0.0
    ) -> dict[str, np.ndarray]:
        """The distributed observer's rates and its oracle derivatives η̇_i, η̈_i, η⃛_i.

        Parameters
        ----------
        S : dict
            The state's named views (:meth:`split`).
        e0d, e0dd : ndarray
            η̇0 and η̈0 of the leader.
        t : float
            Time (picks the topology of a switching graph).
        """
        A0, B0, C0 = self.A0, self.B0, self.C0
        y0, y0d, y0dd = C0 @ S["eta0"], C0 @ e0d, C0 @ e0dd
        E, mu, phi = S["eta"], S["mu"], S["phi"]
        LB, a0h = self.weights(t)
        a0h = a0h[:, None]
        dLB, da0h = self.weights(t, 1)  # fading weights: ψ's jets take their rates
        ddLB, dda0h = self.weights(t, 2)
        da0h, dda0h = da0h[:, None], dda0h[:, None]
        # eq. (6): ψ_i = Σ_j (|a_ij| C0η_i − a_ij C0η_j) + a_i0 (C0η_i − h_i y0)
        psi = LB @ E @ C0.T - a0h * y0
        ehat = mu + psi @ self.Gamma.T  # eq. (7)
        mud = mu @ self.F.T + psi @ self.K.T  # eq. (7)
        y = ehat @ self.Q.T
        nr = self._norm_jets(y, y, y)[0]
        D = nr + phi
        v = -self.l1 * y - self.l2 * y / D[:, None]  # eq. (9)
        Ed = E @ A0.T + v @ B0.T  # eq. (9)
        phid = -self.alpha_sum * (phi - self.phi_min)  # eq. (9), with the floor φ_min
        # oracle: differentiate the observer along the network flow (chain rule by hand)
        psid = LB @ Ed @ C0.T - a0h * y0d + dLB @ E @ C0.T - da0h * y0
        mudd = mud @ self.F.T + psid @ self.K.T
        yd = (mud + psid @ self.Gamma.T) @ self.Q.T
        phidd = -self.alpha_sum * phid
        _, nd, _ = self._norm_jets(y, yd, yd)
        Dd = nd + phid
        vd = -self.l1 * yd - self.l2 * (yd / D[:, None] - y * (Dd / D**2)[:, None])
        Edd = Ed @ A0.T + vd @ B0.T
        psidd = LB @ Edd @ C0.T - a0h * y0dd + 2 * (dLB @ Ed @ C0.T - da0h * y0d)
        psidd = psidd + ddLB @ E @ C0.T - dda0h * y0
        ydd = (mudd + psidd @ self.Gamma.T) @ self.Q.T
        _, nd, ndd = self._norm_jets(y, yd, ydd)
        Ddd = ndd + phidd
        vdd = -self.l1 * ydd - self.l2 * (
            ydd / D[:, None]
            - 2 * yd * (Dd / D**2)[:, None]
            - y * (Ddd / D**2)[:, None]
            + 2 * y * (Dd**2 / D**3)[:, None]
        )
        Eddd = Edd @ A0.T + vdd @ B0.T
        return dict(
            psi=psi, ehat=ehat, mudot=mud, v=v, phidot=phid, etadot=Ed, etaddot=Edd, eta3dot=Eddd
        )

    def _filters(
        self, S: dict[str, np.ndarray], Ed: np.ndarray, b: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        """``derivatives = "filtered"``: ẇ, ż and the filtered η̈_i, ḃ_i, b̈_i.

        Parameters
        ----------
        S : dict
            The state's named views (:meth:`split`).
        Ed : ndarray
            η̇_i (the filter's input for η̈_i).
        b : ndarray
            b_i (the filter's input for ḃ_i, b̈_i).
        """
        m, n, om = self.m, self.n, self.opts.filter_bandwidth
        w1, w2 = S["w"][:, :m], S["w"][:, m:]
        zf = S["z"]
        z1, z2, z3 = zf[:, :n], zf[:, n : 2 * n], zf[:, 2 * n :]
        wdot = np.hstack([w2, om**2 * (Ed - w1) - 2 * om * w2])
        zdot = np.hstack([z2, z3, om**3 * (b - z1) - 3 * om**2 * z2 - 3 * om * z3])
        return wdot, zdot, w2, z2, z3

    def _controller(
        self,
        S: dict[str, np.ndarray],
        mcg: tuple[np.ndarray, np.ndarray, np.ndarray],
        Ed: np.ndarray,
        Edd: np.ndarray,
        b: np.ndarray,
        bd: np.ndarray,
        bdd: np.ndarray,
    ) -> dict[str, np.ndarray]:
        """Tracking errors, the control law and the θ̂ law (eqs. (28)–(30), (42)).

        Parameters
        ----------
        S : dict
            The state's named views (:meth:`split`).
        mcg : tuple of ndarray
            M(p_i), C(p_i, q_i), G(p_i) of every follower (:meth:`mcg`).
        Ed, Edd : ndarray
            η̇_i and η̈_i as the controller sees them (filtered or oracle).
        b, bd, bdd : ndarray
            b_i, ḃ_i, b̈_i (the derivatives are dropped without feedforward).
        """
        C0 = self.C0
        bd_c, bdd_c = (bd, bdd) if self.opts.feedforward else (0 * bd, 0 * bdd)
        p, q, th, gh = S["p"], S["q"], S["thetahat"], S["ghat"]
        M, C, G = mcg
        et = p - S["eta"] @ C0.T - b  # eq. (28)
        etd = q - Ed @ C0.T - bd_c  # eq. (28)
        chi = etd + self.Lam * et  # eq. (28)
        Psi = (  # eq. (29)
            _mv(C, q)
            + G
            + _mv(M, Edd @ C0.T + bdd_c - self.Lam * etd)
            - _mv(C, chi)
            - th * self.sgn(chi)
            - self.k1 * chi
        )
        u = Psi if self.opts.ablation else gh[:, None] * Psi  # eq. (42) / eq. (29)
        if self.u_max is not None:  # the applied torque sat(u); Ψ and (30) unchanged
            lim = self.u_max[:, None]
            u = np.where(u > lim, lim, np.where(u < -lim, -lim, u))
        thd = np.abs(chi) - self.k2[:, None] * th  # eq. (30)
        return dict(et=et, chi=chi, Psi=Psi, u=u, thetahatdot=thd)

    def _ghat_rate(self, chi: np.ndarray, Psi: np.ndarray, gh: np.ndarray) -> np.ndarray:
        """dĝ_i/dt: eq. (30) with gain γ, plus the σ and projection terms of ``ghat_law``.

        Parameters
        ----------
        chi, Psi : ndarray
            χ_i and Ψ_i (N×n).
        gh : ndarray
            ĝ_i (N).
        """
        r = -self.gam * np.sum(chi * Psi, 1)  # eq. (30), ĝ law with gain γ
        law = self.opts.ghat_law
        if "sigma" in law:
            r = r - self.sig * (gh - self.gref)
        if "projection" in law:
            lo, hi = 1.0, 1.0 / self.sc.controller.g_min
            if hi - lo <= 1e-12:
                r = 0 * r
            else:
                dl = 0.01 * (hi - lo)
                whi = np.clip((gh - hi) / dl, 0, 1)  # band of width dl outside [lo, hi]
                wlo = np.clip((lo - gh) / dl, 0, 1)
                r = r - whi * np.maximum(r, 0) - wlo * np.minimum(r, 0)
        return r

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """The closed-loop right-hand side ẋ = f(t, x).

        Parameters
        ----------
        t : float
            Time.
        x : ndarray
            Flat closed-loop state.
        """
        return self.evaluate(t, x)["xdot"]


# ----------------------------------------------------------------------------- hand gains
def hand_gains(
    sc: Scenario, *, lambda1: float | None = None, lambda2: float | None = None
) -> Gains:
    """Gains chosen by hand (no LMI solver), for tests and as the benchmark's baseline.

    Θ from the observer Riccati equation of (ΦA0, C0) (a stable Θ exists under
    Assumption 2 even when (ΦA0, C0) is unobservable); Ω from the Lyapunov
    equation FᵀΩ + ΩF = −I; T⁻¹ from the scenario's Q when given
    (T⁻¹ = Qᵀ(QB0)⁻¹Q + NNᵀ, N spanning ker B0ᵀ, so B0ᵀT⁻¹ = Q), else from the
    control Riccati equation of (A0, B0); Z and w from Lemma 3 with z = (L̄ᵀ)⁻¹1;
    k1 = 1. These gains are NOT certified.

    Parameters
    ----------
    sc : Scenario
        The scenario (leader, graph and the observer gains it gives).
    lambda1, lambda2 : float, optional
        Override the observer gains λ1, λ2 (default: the scenario's, else 1.9 and
        max(2, α)).
    """
    from core.graph import check_network
    from synthesis.assumptions import uio_matrices

    L = sc.leader
    A0, B0, C0 = (np.asarray(a, dtype=float) for a in (L.A0, L.B0, L.C0))
    m, n = A0.shape[0], C0.shape[0]
    Gamma, Phi = uio_matrices(B0, C0)  # eq. (7)
    if sc.observer.Theta is not None:
        Theta = np.asarray(sc.observer.Theta, dtype=float)
    else:
        P = sla.solve_continuous_are((Phi @ A0).T, C0.T, np.eye(m), np.eye(n))
        Theta = P @ C0.T
    F = Phi @ A0 - Theta @ C0
    Omega = sla.solve_continuous_lyapunov(F.T, -np.eye(m))
    if sc.observer.Q is not None:
        Q = np.asarray(sc.observer.Q, dtype=float)
        Nb = sla.null_space(B0.T)
        Tinv = Q.T @ np.linalg.solve(Q @ B0, Q) + Nb @ Nb.T
    else:
        Tinv = sla.solve_continuous_are(A0, B0, np.eye(m), np.eye(B0.shape[1]))
        Q = B0.T @ Tinv
    net = check_network(sc.graph.adjacency, sc.graph.pinning)  # the certified gains' H and L̄
    H = np.diag(net.h)
    Lbar = net.L_bar.toarray()
    z = np.linalg.solve(Lbar.T, np.ones(sc.N))
    Z = np.diag(z)
    Zi = np.diag(z**-0.5)
    # Lemma 3's w (only V1's analysis uses it); skipped on large graphs, where it costs seconds
    w = (
        float(np.linalg.eigvalsh(Zi @ (Lbar.T @ Z + Z @ Lbar) @ Zi).min())
        if sc.N <= 200
        else np.nan
    )
    l1 = lambda1 if lambda1 is not None else (sc.observer.lambda1 or 1.9)
    l2 = lambda2 if lambda2 is not None else (sc.observer.lambda2 or max(2.0, L.alpha))
    return Gains(
        A0=A0,
        B0=B0,
        C0=C0,
        Gamma=Gamma,
        Phi=Phi,
        Theta=Theta,
        Omega=Omega,
        T=np.linalg.inv(Tinv),
        Q=Q,
        lambda_bar1=sc.observer.lambda_bar1,
        delta1=sc.observer.delta1,
        delta2=sc.observer.delta2,
        delta1_hat=sc.observer.delta1_hat,
        delta2_hat=sc.observer.delta2_hat,
        L_bar=Lbar,
        H=H,
        Z=Z,
        w=w,
        lambda1=float(l1),
        lambda2=float(l2),
        alpha=L.alpha,
        k1=1.0,
        info={"solver": "hand (verify.reference.hand_gains)", "certified": False},
    )
