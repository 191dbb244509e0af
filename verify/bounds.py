"""The paper's closed-form claims: Theorem 1's rates, Theorem 2's bounds, Lemmas 1 and 2.

Everything here is a pure function of the scenario (and the synthesised gains);
nothing reads a trajectory. The formulas follow docs/reading.md, 'Theorem 2 bounds' and,
for the adaptive-law variants, docs/fidelity.md, D3:

- the paper's Theorem 2 (eq. (31)) applies Lemma 1 to V2 although V̇2 has no decay
  term in ĝ − 1/g, so its bound does not follow; it is reported as the *paper's
  claim*;
- with the σ-modification ĝ̇ = −γχᵀΨ − σ(ĝ − ĝ0) the same argument is valid with
  Ωv2 = min{…, σ} and χv2 + σ g (1/g − ĝ0)² / (2γ);
- with projection of ĝ onto [1, 1/g_min] (and 1/g inside), ĝ stays in the interval
  widened by the projection band, the ĝ term of V2 is bounded by its value at the
  farther end of that widened interval, W_g, and V̇2 ≤ −Ωv2 V2 + χv2 + Ωv2 W_g;
- with a boundary layer (``sign`` = tanh or sat) both variants add the layer's
  term n (c_s ε)² / (2 k2), c_s = sup_x (|x| − x sgn_1(x)) (:func:`layer_constant`).

The derivation is in docs/verification.md ("Provable variants").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from core.errors import ToolkitError
from core.memo import MEMO
from core.models import build_model
from core.scenario import Scenario
from symbolic.adaptive import BAND
from synthesis.gains import Gains


class VerifyError(ToolkitError):
    """The verification cannot run: missing artifact, bad option, inconsistent trajectory."""


@dataclass(frozen=True)
class VerifyConfig:
    """Choices the paper leaves open, used by every check (documented in docs/verification.md).

    Attributes
    ----------
    lemma1_delta : float
        δ_i of Lemma 1, 0 < δ < 1 (the paper never fixes it).
    tail_fraction : float
        The "asymptotic" window is the last ``tail_fraction`` of the horizon.
    enter_level : float
        Theorem 1: the time each ‖ē_ηi‖ enters (and stays below) this level.
    rtol : float
        Relative round-off allowance of the pointwise Lyapunov inequalities
        (scaled by the size of the terms; not a modelling tolerance).
    """

    lemma1_delta: float = 0.5
    tail_fraction: float = 0.5
    enter_level: float = 1e-2
    rtol: float = 1e-7

    def __post_init__(self) -> None:
        if not 0.0 < self.lemma1_delta < 1.0:
            raise VerifyError(f"lemma1_delta = {self.lemma1_delta}: expected 0 < delta < 1")
        if not 0.0 < self.tail_fraction <= 1.0:
            raise VerifyError(f"tail_fraction = {self.tail_fraction}: expected 0 < f <= 1")
        if self.enter_level <= 0 or self.rtol < 0:
            raise VerifyError("enter_level must be > 0 and rtol >= 0")


@dataclass(frozen=True)
class Theorem2Constants:
    """Theorem 2's constants for one follower (paper's law and the provable variant).

    Attributes
    ----------
    lam_min_M, lam_max_M : float
        inf λ_min(M_i) and sup λ_max(M_i) over the configuration space.
    Omega, chi_v : float
        Ωv2i and χv2i as printed (eq. (38)): V̇2 ≤ −Ωv2 V2 + χv2 (paper's claim).
    chi_bar : float
        χ̄_si of eq. (39)–(40) with the paper's constants.
    e_bar : ndarray
        |e_ti,r| ≤ χ̄_si / λ_ir (eq. (41), Lemma 2 with k = 0).
    edot_bar : ndarray
        |ė_ti,r| ≤ 2 χ̄_si (Lemma 2 with n = 2, k = 1, θ = λ_ir).
    variant : str
        The ĝ law in the scenario ('paper', 'sigma', 'projection', 'sigma+projection').
    provable : bool
        Whether the variant's constants give a bound that follows (paper's law: no).
    Omega_var, chi_v_var, chi_bar_var : float
        The constants with the variant's correction (docs/fidelity.md, D3); equal to the
        paper's when ``provable`` is False.
    e_bar_var, edot_bar_var : ndarray
        Lemma 2 bounds from ``chi_bar_var``.
    layer_term : float
        Part of ``chi_v_var`` from the boundary layer, n (c_s ε)² / (2 k2) (0 with the
        exact sign or when not provable).
    ghat_term : float
        Part of ``chi_v_var`` from ĝ: σ g (1/g − ĝ0)² / (2γ), or Ωv2 W_g with projection only.
    rate_term : float
        Part of ``chi_v_var`` from a varying health: sup|ġ| max(ĝ², 1/g²) / (2γ) (0 when g
        is constant on the interval).
    why_not : str
        Why the variant's bound does not follow ('' when ``provable``).
    """

    lam_min_M: float
    lam_max_M: float
    Omega: float
    chi_v: float
    chi_bar: float
    e_bar: np.ndarray
    edot_bar: np.ndarray
    variant: str
    provable: bool
    Omega_var: float
    chi_v_var: float
    chi_bar_var: float
    e_bar_var: np.ndarray
    edot_bar_var: np.ndarray
    layer_term: float = 0.0
    ghat_term: float = 0.0
    rate_term: float = 0.0
    why_not: str = ""


@MEMO.memoize("layer-constants", 8)
def layer_constant(sign: str) -> float:
    """c_s = sup_x (|x| − x sgn_1(x)): then |χ| − χ sgn_ε(χ) ≤ c_s ε for every χ.

    ``exact``: 0. ``sat``: |x| − x² on |x| ≤ 1 (0 outside), largest at |x| = ½: c = ¼.
    ``tanh``: h(x) = x (1 − tanh x) for x ≥ 0 (even), largest where
    h'(x) = 1 − tanh x − x sech² x = 0 (x* ≈ 0.6392): c ≈ 0.27846.

    Parameters
    ----------
    sign : {"exact", "sat", "tanh"}
        ``options.sign``.
    """
    if sign == "exact":
        return 0.0
    if sign == "sat":
        return 0.25
    if sign != "tanh":
        raise VerifyError(f"options.sign = {sign!r}: expected exact, sat or tanh")
    lo, hi = 0.1, 3.0  # h' > 0 at 0.1 and < 0 at 3: bisection on the unique root
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 1.0 - math.tanh(mid) - mid / math.cosh(mid) ** 2 > 0.0:
            lo = mid
        else:
            hi = mid
    x = 0.5 * (lo + hi)
    return x * (1.0 - math.tanh(x))


def chi_bar_from(chi_v: float, Omega: float, lam_min_M: float, delta: float) -> float:
    """χ̄ = sqrt(2 χv / (λ_min(M) Ω (1 − δ))), eqs. (39)–(40).

    Parameters
    ----------
    chi_v, Omega : float
        Lemma 1's ω and λ (V̇ + λV ≤ ω).
    lam_min_M : float
        Infimum of λ_min(M) over the configuration.
    delta : float
        Lemma 1's δ, 0 < δ < 1.

    Returns
    -------
    float
    """
    # eq. (39): ½λ_min‖χ‖² ≤ V2 ≤ χv/(Ω(1−δ)) (Lemma 1); eq. (40): solved for ‖χ‖
    return math.sqrt(2.0 * chi_v / (lam_min_M * Omega * (1.0 - delta)))  # eq. (40)


def lemma1_bound(chi_v: float, Omega: float, delta: float) -> float:
    """Lemma 1's ultimate level of V: ω / (λ (1 − δ)).

    Parameters
    ----------
    chi_v : float
        ω of V̇ + λV ≤ ω.
    Omega : float
        λ of V̇ + λV ≤ ω.
    delta : float
        0 < δ < 1.
    """
    return chi_v / (Omega * (1.0 - delta))  # eq. (4) (Lemma 1): V → ω/(λ(1 − δ))


def lemma1_reaching_time(Omega: float, chi_v: float, V0: float, delta: float) -> float:
    """Lemma 1's bound t_f ≤ ln(λ(1−δ)V(0)/ω) / (λδ) (0 when V(0) is already inside).

    Parameters
    ----------
    Omega, chi_v : float
        λ and ω of V̇ + λV ≤ ω.
    V0 : float
        V(0).
    delta : float
        0 < δ < 1.

    Returns
    -------
    float
    """
    if chi_v <= 0:
        return math.inf
    x = Omega * (1.0 - delta) * V0 / chi_v
    return 0.0 if x <= 1.0 else math.log(x) / (Omega * delta)  # eq. (4) (Lemma 1): t_f


def comparison_reaching_time(Omega: float, chi_v: float, V0: float, delta: float) -> float:
    """Time after which V(0)e^{−λt} + ω/λ ≤ ω/(λ(1−δ)) (comparison lemma; always valid).

    Used to report whether the paper's Lemma 1 t_f is at least the time the
    comparison lemma itself guarantees.

    Parameters
    ----------
    Omega, chi_v : float
        λ and ω of V̇ + λV ≤ ω.
    V0 : float
        V(0).
    delta : float
        0 < δ < 1.
    """
    if chi_v <= 0:
        return math.inf
    x = Omega * (1.0 - delta) * V0 / (chi_v * delta)
    return 0.0 if x <= 1.0 else math.log(x) / Omega


def provable_entry_time(
    c: Theorem2Constants, df: pd.DataFrame, agent: int, delta: float, row: int = 0
) -> float:
    """The comparison-lemma time t_c after which follower ``agent``'s provable bound holds.

    From V2(0) in the trajectory (NaN without a ``V2_<i>`` column) and the provable
    variant's constants: the start of every window that uses that bound.

    Parameters
    ----------
    c : Theorem2Constants
        Of follower ``agent`` (:func:`theorem2_constants`).
    df : DataFrame, verify.signals.Columns or verify.signals.TrajectoryView
        The trajectory.
    agent : int
        0-based follower.
    delta : float
        Lemma 1's δ (``VerifyConfig.lemma1_delta``).
    row : int
        The sample the comparison lemma starts from (time measured from it).
    """
    from verify import signals as S

    view, i = S.TrajectoryView.of(df), agent + 1
    V2_0 = float(view.scalar(S.Signal.V2, i)[row]) if view.has(S.Signal.V2, i) else math.nan
    return comparison_reaching_time(c.Omega_var, c.chi_v_var, V2_0, delta)


def lemma2_bounds(gamma_bar: float, theta: float, order: int) -> np.ndarray:
    """Lemma 2: |(d/dt + θ)^{n−1} γ| ≤ γ̄ ⇒ |γ^{(k)}| ≤ (2θ)^k γ̄ / θ^{n−1}, k = 0..n−1.

    Parameters
    ----------
    gamma_bar : float
        Bound of the filtered signal.
    theta : float
        Filter pole θ > 0.
    order : int
        n ≥ 1 (n − 1 is the filter order).

    Returns
    -------
    ndarray
        The n bounds for k = 0, …, n−1.
    """
    k = np.arange(order)
    return (2.0 * theta) ** k * gamma_bar / theta ** (order - 1)  # eq. (5) (Lemma 2)


def mass_bounds(scenario: Scenario, agent: int) -> tuple[float, float]:
    """(inf λ_min(M_i), sup λ_max(M_i)) over the configuration space of follower ``agent``.

    Parameters
    ----------
    scenario : Scenario
        The scenario (the follower's model and parameters).
    agent : int
        0-based follower index.
    """
    fo = scenario.followers[agent]
    return build_model(fo.model, fo.params).M_bounds


def theorem2_constants(
    scenario: Scenario,
    agent: int,
    config: VerifyConfig | None = None,
    health: tuple[float, float, float] | None = None,
) -> Theorem2Constants:
    """Theorem 2's constants for follower ``agent`` (0-based), eq. (31); variants: docs/fidelity.md, D3.

    Parameters
    ----------
    scenario : Scenario
    agent : int
        0-based follower index.
    config : VerifyConfig, optional
        Supplies Lemma 1's δ.
    health : (g_lo, g_hi, gdot), optional
        The range of g_i and sup |ġ_i| on the interval the constants serve
        (:class:`verify.intervals.Piece`); default the whole run's, from
        :func:`verify.intervals.health_pieces` (docs/verification.md, 'Theorem 2 on intervals').

    Returns
    -------
    Theorem2Constants
    """
    cfg = config or VerifyConfig()
    if not 0 <= agent < scenario.N:
        raise VerifyError(f"agent {agent + 1} does not exist: expected 1..{scenario.N}")
    ctrl, fo = scenario.controller, scenario.followers[agent]
    lmin, lmax = mass_bounds(scenario, agent)
    K = ctrl.k1[agent]
    k2 = float(ctrl.k2[agent])
    d = np.asarray(fo.d, dtype=float)
    lam = np.asarray(ctrl.Lambda[agent], dtype=float)
    delta = cfg.lemma1_delta

    Omega = min(2.0 * float(K.min()) / lmax, k2)  # eq. (38): Ωv2i
    chi_v = 0.5 * k2 * float(d @ d)  # eq. (38): χv2i = ½ dᵀ k2 d
    chi_bar = chi_bar_from(chi_v, Omega, lmin, delta)  # eq. (39), eq. (40): χ̄_si of (31)
    e_bar, edot_bar = _lemma2_pair(chi_bar, lam)

    law = scenario.options.ghat_law
    health = health if health is not None else _run_health(scenario, agent)
    # boundary layer: θ̂ᵀ(|χ| − χ∘sgn_ε χ) − ½k2‖θ̂‖² ≤ Σ_r (c_s ε|θ̂_r| − ½k2 θ̂_r²) ≤ n(c_s ε)²/(2k2)
    cs_eps = layer_constant(scenario.options.sign) * scenario.options.sign_width
    layer = scenario.n * cs_eps**2 / (2.0 * k2)
    Om_v, gterm, rate_term, why_not = _variant_terms(scenario, agent, Omega, health)
    provable = not why_not
    chi_vv = chi_v + gterm + layer + rate_term if provable else chi_v
    chi_bar_v = chi_bar_from(chi_vv, Om_v, lmin, delta) if provable else chi_bar
    e_bar_v, edot_bar_v = _lemma2_pair(chi_bar_v, lam)
    return Theorem2Constants(
        lam_min_M=lmin,
        lam_max_M=lmax,
        Omega=Omega,
        chi_v=chi_v,
        chi_bar=chi_bar,
        e_bar=e_bar,
        edot_bar=edot_bar,
        variant=law,
        provable=provable,
        Omega_var=Om_v,
        chi_v_var=chi_vv,
        chi_bar_var=chi_bar_v,
        e_bar_var=e_bar_v,
        edot_bar_var=edot_bar_v,
        layer_term=layer if provable else 0.0,
        ghat_term=gterm if provable else 0.0,
        rate_term=rate_term if provable else 0.0,
        why_not=why_not,
    )


def _variant_terms(
    scenario: Scenario, agent: int, Omega: float, health: tuple[float, float, float]
) -> tuple[float, float, float, str]:
    """The ĝ law's variant of eq. (38): (Ω, ĝ term, ∂V2/∂t term, why not provable or '')."""
    ctrl = scenario.controller
    law = scenario.options.ghat_law
    gamma = float(ctrl.gamma[agent])
    g_lo, g_hi, gdot = health
    ends = (g_lo, g_hi)  # the ĝ terms below are convex in g > 0: largest at an end
    Om_v, gterm, why_not = Omega, 0.0, ""
    band = BAND * (1.0 / ctrl.g_min - 1.0)
    lo, hi = 1.0 - band, 1.0 / ctrl.g_min + band  # ĝ's interval under the projection
    if "projection" in law:
        # 1/g_i inside [1, 1/g_min] at both ends of its range: then everywhere between
        why_not = next(
            (
                w
                for g in ends
                if (w := projection_why_not(scenario, agent, 1.0 / g, law == "projection"))
            ),
            "",
        )
    if "sigma" in law:  # D3 (docs/fidelity.md): σ-modification adds decay in ĝ − 1/g
        sigma = float(ctrl.sigma[agent])
        ghat0 = float(ctrl.ghat_ref[agent])
        Om_v = min(Omega, sigma)
        gterm = max(sigma * g * (1.0 / g - ghat0) ** 2 / (2.0 * gamma) for g in ends)
    elif law == "projection" and not why_not:  # ĝ stays in the band-widened interval
        gterm = max(Omega * g * max(1.0 / g - lo, hi - 1.0 / g) ** 2 / (2.0 * gamma) for g in ends)
    elif law == "paper":
        why_not = "no decay in ghat - 1/g (docs/fidelity.md, D3)"
    rate_term = 0.0
    if gdot > 0.0 and not why_not:
        if "projection" not in law:
            why_not = (
                f"outside the theory: g_{agent + 1} varies (sup |dg/dt| = {gdot:.3g}/s) and "
                "ghat has no a-priori bound without the projection"
            )
        else:  # ∂V2/∂t = (ġ/(2γ))(ĝ² − 1/g²), |ĝ² − 1/g²| ≤ max(ĝ², 1/g²)
            rate_term = gdot / (2.0 * gamma) * max(hi**2, 1.0 / g_lo**2)
    return Om_v, gterm, rate_term, why_not


def _run_health(scenario: Scenario, agent: int) -> tuple[float, float, float]:
    """(min g_i, max g_i, sup |ġ_i|) over the whole run."""
    from verify.intervals import health_pieces

    pieces = health_pieces(scenario.followers[agent].g, float(scenario.integration.horizon))
    return (
        min(p[2] for p in pieces),
        max(p[3] for p in pieces),
        max(p[4] for p in pieces),
    )


def outside_projection(scenario: Scenario, agent: int, gbar: float) -> str:
    """Why 1/g_i = ``gbar`` is outside the projection interval [1, 1/g_min] ('' if inside).

    The interval always contains 1/g = 1 (a healthy follower): its lower end is 1, and the
    projection band lies outside it (:mod:`symbolic.adaptive`).

    Parameters
    ----------
    scenario : Scenario
        Its ``controller.g_min``.
    agent : int
        0-based follower (for the message).
    gbar : float
        1/g_i.
    """
    hi = 1.0 / scenario.controller.g_min
    if not 1.0 <= gbar <= hi:
        return f"1/g_{agent + 1} = {gbar:.4g} outside the projection interval [1, {hi:.4g}]"
    return ""


def projection_why_not(scenario: Scenario, agent: int, gbar: float, needs_start: bool) -> str:
    """Why the projection's term (g/γ)(ĝ − 1/g)·(removed rate) could be positive ('' if not).

    The removed part points outward only at the ends of [1, 1/g_min], so its term is
    ≤ 0 when 1/g lies in that interval. Without σ the bound also needs ĝ(0) inside the
    band-widened interval, which the projection then keeps ĝ in.

    Parameters
    ----------
    scenario : Scenario
        Its ``controller.g_min`` and ``initial.ghat``.
    agent : int
        0-based follower.
    gbar : float
        1/g_i.
    needs_start : bool
        Whether ĝ(0) must lie in the band-widened interval (the projection-only law).
    """
    hi = 1.0 / scenario.controller.g_min
    if hi - 1.0 <= 1e-12:
        return "controller.g_min = 1 freezes ghat: the adaptive term does not cancel"
    if why := outside_projection(scenario, agent, gbar):
        return why
    band = BAND * (hi - 1.0)
    g0 = float(scenario.initial.ghat[agent])
    if needs_start and not 1.0 - band <= g0 <= hi + band:
        return f"initial.ghat = {g0:.4g} outside [{1 - band:.4g}, {hi + band:.4g}]"
    return ""


def _lemma2_pair(chi_bar: float, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per component: (|e| ≤ χ̄/λ, |ė| ≤ 2χ̄), Lemma 2 with n = 2 and θ = λ_ir (eq. (41))."""
    b = np.array([lemma2_bounds(chi_bar, float(lr), 2) for lr in lam])  # eq. (41), eq. (31)
    return b[:, 0], b[:, 1]


@dataclass(frozen=True)
class Theorem1Rates:
    """Theorem 1's decay rates of V1 (docs/reading.md, 'Distributed observer').

    Attributes
    ----------
    supported : float
        min{δ1 − δ̂1, α̃1, δ2 − δ̂2}: what the LMIs support.
    printed : float
        min{δ1, α̃1, δ2}: the paper's claim.
    alpha1_tilde : float
        min_i α1i.
    """

    supported: float
    printed: float
    alpha1_tilde: float


def theorem1_rates(scenario: Scenario, gains: Gains) -> Theorem1Rates:
    """δ̃ of Theorem 1 from the synthesised δ1, δ2, δ̂1, δ̂2 and the scenario's α1i.

    Parameters
    ----------
    scenario : Scenario
    gains : synthesis.gains.Gains

    Returns
    -------
    Theorem1Rates
    """
    a1 = float(np.min(scenario.observer.alpha1))
    sup = min(gains.delta1 - gains.delta1_hat, a1, gains.delta2 - gains.delta2_hat)
    printed = min(gains.delta1, a1, gains.delta2)
    return Theorem1Rates(supported=float(sup), printed=float(printed), alpha1_tilde=a1)


@dataclass(frozen=True)
class Theorem1Floor:
    """Theorem 1 with the φ floor: V̇1 ≤ −δ̃ V1 + c_φ (docs/verification.md, "Theorem 1 with
    the φ floor").

    Attributes
    ----------
    rate : float
        δ̃ = min{δ1 − δ̂1, α̃1, δ2 − δ̂2} (the supported rate).
    c_phi : float
        2λ2 φ_min Σ_i l̄_ii z_i (α1i + ᾱ1i)/ᾱ1i (0 without a floor).
    h : ndarray
        The gauge h_i = ±1.
    l_bar, z, alpha1_bar : ndarray
        l̄_ii, z_i and ᾱ1i: the φ term of V1 is 2λ2 Σ_i l̄_ii z_i φ_i / ᾱ1i.
    lambda2 : float
        λ2 of eq. (9).
    c0_gain : ndarray
        κ_i with ‖C0 ē_ηi‖ ≤ κ_i sqrt(ε_ηᵀ(Z ⊗ T⁻¹)ε_η + k1 ẽ_ηᵀ(I ⊗ Ω)ẽ_η).
    """

    rate: float
    c_phi: float
    h: np.ndarray
    l_bar: np.ndarray
    z: np.ndarray
    alpha1_bar: np.ndarray
    lambda2: float
    c0_gain: np.ndarray

    def phi_term(self, phi: np.ndarray) -> np.ndarray:
        """2λ2 Σ_i l̄_ii z_i φ_i / ᾱ1i (eq. (17)) for φ of shape (K, N); returns (K,).

        Parameters
        ----------
        phi : ndarray
            (K, N) values of φ_i.
        """
        return 2.0 * self.lambda2 * np.asarray(phi, float) @ (self.l_bar * self.z / self.alpha1_bar)

    def v1_bound(self, V1_start: float, dt: np.ndarray) -> np.ndarray:
        """Comparison lemma: V1(ts + dt) ≤ V1(ts) e^{−δ̃ dt} + (c_φ/δ̃)(1 − e^{−δ̃ dt}).

        Parameters
        ----------
        V1_start : float
            V1 at the start ts of the window.
        dt : ndarray
            Times since ts (≥ 0).
        """
        decay = np.exp(-self.rate * np.asarray(dt, float))
        return V1_start * decay + self.c_phi / self.rate * (1.0 - decay)

    def c0_error_bound(self, V1_bound: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """‖C0 ē_ηi‖ ≤ κ_i sqrt(V1 bound − φ term): (K, N) from V1 bounds (K,) and φ (K, N).

        Parameters
        ----------
        V1_bound : ndarray
            (K,) upper bounds of V1.
        phi : ndarray
            (K, N) φ_i at the same times.
        """
        rest = np.maximum(np.asarray(V1_bound, float) - self.phi_term(phi), 0.0)
        return np.sqrt(rest)[:, None] * self.c0_gain[None, :]


def theorem1_floor(scenario: Scenario, gains: Gains) -> Theorem1Floor:
    """Constants of Theorem 1 with the φ floor (docs/verification.md derives them).

    Parameters
    ----------
    scenario : Scenario
        Its observer (α1i, ᾱ1i, φ_min) and graph.
    gains : synthesis.gains.Gains
        T, Ω, Z, k1, λ2, the gauge and the rates.

    Returns
    -------
    Theorem1Floor
    """
    from symbolic.network import graph_matrices

    o = scenario.observer
    gm = graph_matrices(scenario.graph, gains)  # h and L + B = H L̄ H from the gains
    z = np.diag(np.atleast_2d(gains.Z)).astype(float)
    a1 = np.broadcast_to(np.asarray(o.alpha1, float), (scenario.N,))
    a1b = np.broadcast_to(np.asarray(o.alpha1_bar, float), (scenario.N,))
    lam2 = float(gains.lambda2)
    # φ̇_i = −(α1i + ᾱ1i)(φ_i − φ_min): the φ term's derivative exceeds the floor-free one by
    # 2λ2 Σ l̄_ii z_i (α1i + ᾱ1i) φ_min / ᾱ1i
    c_phi = 2.0 * lam2 * float(o.phi_min) * float(np.sum(gm.l_bar * z * (a1 + a1b) / a1b))
    # C0 ē_ηi = Σ_j (L_B⁻¹)_ij C0 (h_j ε_ηj − ẽ_ηj); max over the ellipsoid of V1's quadratic part
    C0 = np.atleast_2d(scenario.leader.C0)
    CTC = C0 @ np.atleast_2d(gains.T) @ C0.T
    COC = C0 @ np.linalg.inv(np.atleast_2d(gains.Omega)) @ C0.T
    Li2 = np.linalg.inv(gm.L_B) ** 2
    k1 = float(gains.k1)
    kappa = np.array(
        [
            # G_i P⁻¹ G_iᵀ = Σ_j (L_B⁻¹)_ij² (C0 T C0ᵀ / z_j + C0 Ω⁻¹ C0ᵀ / k1), h_j² = 1
            math.sqrt(
                max(
                    np.linalg.eigvalsh(np.sum(Li2[i] / z) * CTC + np.sum(Li2[i]) * COC / k1).max(),
                    0.0,
                )
            )
            for i in range(scenario.N)
        ]
    )
    return Theorem1Floor(
        rate=theorem1_rates(scenario, gains).supported,
        c_phi=c_phi,
        h=np.asarray(gm.h, float),
        l_bar=np.asarray(gm.l_bar, float),
        z=z,
        alpha1_bar=np.asarray(a1b, float),
        lambda2=lam2,
        c0_gain=kappa,
    )
