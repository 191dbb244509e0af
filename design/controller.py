"""The controller's gains: candidates from Theorem 2's closed form, each simulated and verified.

Theorem 2's provable variant (docs/verification.md, 'Provable variants') gives
V̇2 ≤ −ΩV2 + χv with Ω = min{2λ_min(K)/λ_max(M), k2, σ} and
χv = ½k2‖d‖² + σg(1/g − ĝ0)²/(2γ) + n(c_s ε)²/(2k2). Hence:

- k2 = σ = 2 k1/λ_max(M) (:func:`balanced`): a larger k2 or σ raises χv without raising Ω,
  a smaller one lowers Ω; at the balance χv/Ω, hence the ultimate bound
  χ̄ = sqrt(2χv/(λ_min(M)Ω(1−δ))), barely depends on k1, while the time to the guarantee
  t_c = ln(Ω(1−δ)V2(t_s)/(χv δ))/Ω falls like 1/k1;
- γ does not enter Ω; it divides the ĝ term of χv, largest at the declared health range's
  worst end: after (k1, λ), each follower's γ is chosen from a grid of simulated and
  verified candidates (:func:`gamma_candidates`, :func:`choose_gamma`) for the smallest χ̄
  over the declared range [g_min, 1] (:func:`health_bound`);
- the projection interval is [1, 1/g_min] of the declared health range (it holds 1/g = 1);
- the one limit is the torque, which no closed form gives: each candidate (k1, λ) is
  simulated and its peak ‖u_i‖ after the start-up compared with the budget.

The constants are :func:`verify.bounds.theorem2_constants`'s (one place for the math); the
guarantees are read from the verification table of the candidate's run.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.scenario import Scenario

#: multiples of the scenario's k1 tried (the front's abscissa is their peak torque)
K1_FACTORS = (1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 14.0)
#: multiples of the scenario's λ_ir tried
LAMBDA_FACTORS = (0.5, 1.0, 2.0)
#: multiples of the scenario's γ_i tried for the ĝ law, once k1 and λ are chosen
GAMMA_FACTORS = (1.0, 3.0, 10.0, 30.0)


def balanced(scenario: Scenario, k1: float) -> tuple[np.ndarray, np.ndarray]:
    """k2_i = σ_i = 2 k1 / λ_max(M_i): the rates of Ω's three terms made equal.

    Parameters
    ----------
    scenario : Scenario
        The followers' models (λ_max(M_i) from :func:`verify.bounds.mass_bounds`).
    k1 : float
        k1ir for every follower and coordinate.
    """
    from verify.bounds import mass_bounds

    rate = np.array([2.0 * k1 / mass_bounds(scenario, i)[1] for i in range(scenario.N)])
    return rate, rate.copy()


def candidate_overrides(scenario: Scenario, k1: float, lam: float) -> dict[str, Any]:
    """The controller's keys of one candidate (k1ir = k1, λ_ir = lam, balanced k2 and σ).

    Parameters
    ----------
    scenario : Scenario
        With its ``[design]`` table (the health range).
    k1, lam : float
        k1ir and λ_ir for every follower and coordinate.
    """
    k2, sigma = balanced(scenario, k1)
    law = scenario.options.ghat_law
    out: dict[str, Any] = {
        "controller.k1": float(k1),
        "controller.Lambda": float(lam),
        "controller.k2": [float(x) for x in k2],
        "controller.g_min": float(np.min(scenario.design.g_min)),
    }
    if "sigma" in law:
        out["controller.sigma"] = [float(x) for x in sigma]
    return {**out, **disturbance_overrides(scenario)}


def disturbance_overrides(scenario: Scenario) -> dict[str, Any]:
    """``followers[i].d`` = ``design.d``: Theorem 2's χv is designed (and verified) for it.

    Parameters
    ----------
    scenario : Scenario
        With its ``[design]`` table.
    """
    if scenario.design.d is None:
        return {}
    return {
        f"followers[{i + 1}].d": [float(x) for x in row] for i, row in enumerate(scenario.design.d)
    }


def candidates(scenario: Scenario) -> list[tuple[float, float]]:
    """The (k1, λ) grid: multiples of the scenario's own, k1 within ``design.k1_max``.

    Parameters
    ----------
    scenario : Scenario
    """
    k0 = float(np.max(scenario.controller.k1))
    l0 = float(np.max(scenario.controller.Lambda))
    cap = scenario.design.k1_max
    ks = sorted({min(k0 * f, cap) if cap else k0 * f for f in K1_FACTORS})
    return [(k, l0 * f) for k in ks for f in LAMBDA_FACTORS]


@dataclass(frozen=True)
class Point:
    """One evaluated candidate: its gains and what its verified run guarantees.

    Attributes
    ----------
    label : str
        ``"designed"`` candidates by their gains; ``"given"`` for the scenario's own gains.
    k1, lam : float
        k1ir, λ_ir (the largest over followers for ``given``).
    peak : list of float
        Per follower, peak ‖u_i‖ after the start-up.
    tc : list of float
        Per follower, the start of its first ultimate-level window (t_c; inf: none).
    chi_bar : list of float
        Per follower, Theorem 2's provable χ̄ (largest over intervals).
    def1 : list of float
        Per follower, Definition 1's derived bound (largest over intervals; nan: none).
    coverage : float
        Mean share of the horizon the ultimate-level rows cover.
    holds : bool
        Every guaranteed row holds.
    covered_all : bool
        Every follower has a guaranteed tracking row.
    complete : bool
        The simulation reached the horizon.
    overrides : dict
        The controller's keys of the candidate.
    """

    label: str
    k1: float
    lam: float
    peak: list[float]
    tc: list[float]
    chi_bar: list[float]
    def1: list[float]
    coverage: float
    holds: bool
    covered_all: bool
    complete: bool
    overrides: dict[str, Any]

    def within(self, budget: np.ndarray) -> bool:
        """Whether every follower's peak torque after the start-up is within its budget.

        Parameters
        ----------
        budget : ndarray
            Per follower, ``design.u_max``.
        """
        return bool(np.all(np.asarray(self.peak) <= budget))

    @property
    def tc_max(self) -> float:
        """The time every follower's guarantee has started."""
        return max(self.tc)

    @property
    def bound(self) -> float:
        """The largest Definition 1 bound (χ̄ where no Definition 1 row exists)."""
        vals = [d if math.isfinite(d) else c for d, c in zip(self.def1, self.chi_bar, strict=True)]
        return max(vals)

    @property
    def peak_max(self) -> float:
        """The largest peak ‖u_i‖ after the start-up."""
        return max(self.peak)

    def to_json(self) -> dict[str, Any]:
        """As a JSON object (inf written as null)."""
        d = asdict(self)
        for k in ("peak", "tc", "chi_bar", "def1"):
            d[k] = [x if math.isfinite(x) else None for x in d[k]]
        return d


def evaluate(
    path: str | Path,
    overrides: dict[str, Any],
    variant: str,
    label: str,
    k1: float,
    lam: float,
    startup: float,
    out_root: Path,
) -> Point:
    """Simulate ``path`` with ``overrides`` in memory, verify it, and measure the point.

    Parameters
    ----------
    path : str or Path
        The scenario file.
    overrides : dict
        All overrides of the candidate (the user's, the observer's and the controller's).
    variant : str
        Its name suffix (nothing is written under it).
    label : str
        ``"given"`` or ``"candidate"``.
    k1, lam : float
        The candidate's k1 and λ (for the front).
    startup : float
        The start-up (s) the budget excludes.
    out_root : Path
        Where the verification would look for files (nothing is written).
    """
    from generated import api
    from verify import claims as CL
    from verify import pipeline as P
    from verify import signals as S
    from verify.headline import coverage
    from verify.rows import failed_mask

    sc = api.load(path, overrides or None, variant if overrides else None)
    gains = api.scenario_gains(sc, f"gains of the design candidate {variant}")
    codegen = api.resolve_codegen(sc.N)
    built = api.build(sc, gains, sc.integration.method, codegen)
    traj = api.simulate(built, sc, api.integrator_settings(sc, sc.integration.method, codegen))
    frame = api.trajectory_frame(built, sc, traj)
    run = P.Run(
        sc, frame, traj.x, {}, out_root / sc.name, gains=gains, closed_loop=built.closed_loop
    )
    v = P.verify_run(run, out_root=out_root)
    table = v.table
    t = frame["t"].to_numpy(float)
    view = S.TrajectoryView.of(frame)
    late = t > startup
    peak = [float(view.norm(S.Signal.U, i + 1)[late].max()) for i in range(sc.N)]
    g = table[table["kind"] == CL.Kind.GUARANTEED.value]
    tc, chi, d1 = [], [], []
    for i in range(sc.N):
        rows = g[g["agent"].astype(str) == str(i + 1)]
        chi_rows = rows[rows["claim_id"] == CL.T2_CHI.id]
        d1_rows = rows[rows["claim_id"] == CL.DEF1_DERIVED.id]
        starts = chi_rows["t_start"].to_numpy(float)
        tc.append(float(starts.min()) if len(starts) else math.inf)
        chi.append(float(chi_rows["bound"].astype(float).max()) if len(chi_rows) else math.inf)
        d1.append(float(d1_rows["bound"].astype(float).max()) if len(d1_rows) else math.nan)
    cov = coverage(table, (float(t[0]), float(t[-1])))
    return Point(
        label=label,
        k1=float(k1),
        lam=float(lam),
        peak=peak,
        tc=tc,
        chi_bar=chi,
        def1=d1,
        coverage=float(np.mean([c.covered for c in cov])) if cov else 0.0,
        holds=not bool(failed_mask(g).any()),
        covered_all=bool(cov) and all(c.tracking > 0 for c in cov),
        complete=bool(traj.complete),
        overrides={k: v for k, v in overrides.items() if k.startswith("controller.")},
    )


def _level_ok(p: Point, i: int, budget: np.ndarray) -> bool:
    """Point ``p`` is admissible for follower ``i``: within its budget, rows held, covered."""
    return p.peak[i] <= budget[i] and p.holds and p.covered_all and p.complete


def _bound_i(p: Point, i: int) -> float:
    return p.def1[i] if math.isfinite(p.def1[i]) else p.chi_bar[i]


def choose(points: list[Point], budget: np.ndarray, slack: float) -> list[Point | None]:
    """Per follower, the level with the earliest guarantee within its budget and bound.

    Among the evaluated levels admissible for follower i (its peak torque after the start-up
    within its budget, every guaranteed row holding, every follower covered), take the
    smallest t_c,i among those whose ultimate bound (Definition 1's, else χ̄) is at most
    ``slack`` times the best of them; ties go to the smaller bound. None: no level fits.

    Parameters
    ----------
    points : list of Point
        The evaluated candidates (common gains for every follower).
    budget : ndarray
        Per follower, the torque budget.
    slack : float
        ``design.bound_slack``.
    """
    out: list[Point | None] = []
    for i in range(len(budget)):
        ok = [p for p in points if _level_ok(p, i, budget)]
        if not ok:
            out.append(None)
            continue
        best = min(_bound_i(p, i) for p in ok)
        near = [p for p in ok if _bound_i(p, i) <= slack * best]
        out.append(min(near, key=lambda p: (p.tc[i], _bound_i(p, i))))
    return out


def assemble(scenario: Scenario, chosen: list[Point]) -> dict[str, Any]:
    """The controller's keys with each follower's chosen level (per-follower lists).

    Parameters
    ----------
    scenario : Scenario
    chosen : list of Point
        One per follower (:func:`choose`, none None).
    """
    per = [candidate_overrides(scenario, p.k1, p.lam) for p in chosen]
    out: dict[str, Any] = {
        "controller.k1": [p.k1 for p in chosen],
        "controller.Lambda": [p.lam for p in chosen],
        "controller.k2": [o["controller.k2"][i] for i, o in enumerate(per)],
        "controller.g_min": per[0]["controller.g_min"],
    }
    for key in ("controller.sigma", "controller.gamma"):
        if key in per[0]:
            out[key] = [o[key][i] for i, o in enumerate(per)]
    return out


def health_bound(scenario: Scenario, i: int) -> float:
    """Theorem 2's provable χ̄_i over follower i's declared health range [g_min_i, 1].

    The ĝ term of χv is convex in g, so the constants of a piece whose health spans the
    range (:func:`verify.bounds.theorem2_constants` with ``health=(g_min_i, 1, 0)``) bound
    every constant health the design tolerates; inf when the variant is not provable.

    Parameters
    ----------
    scenario : Scenario
        With its ``[design]`` table and the candidate's gains.
    i : int
        0-based follower.
    """
    from verify.bounds import VerifyConfig, theorem2_constants

    g_min = float(np.asarray(scenario.design.g_min, float)[i])
    c = theorem2_constants(scenario, i, VerifyConfig(), health=(g_min, 1.0, 0.0))
    return float(c.chi_bar_var) if c.provable else math.inf


def gamma_candidates(scenario: Scenario) -> list[list[float]]:
    """γ_i of each candidate: the scenario's own times :data:`GAMMA_FACTORS` (first: its own).

    Parameters
    ----------
    scenario : Scenario
    """
    g0 = np.asarray(scenario.controller.gamma, float)
    return [[float(x) for x in g0 * f] for f in GAMMA_FACTORS]


@dataclass(frozen=True)
class GammaPoint:
    """One γ candidate: its γ_i, its simulated and verified run, χ̄_i over the health range.

    Attributes
    ----------
    gamma : list of float
        Per follower, γ_i.
    point : Point
        The run with the designed k1, λ, k2, σ and these γ_i.
    worst : list of float
        Per follower, :func:`health_bound`.
    """

    gamma: list[float]
    point: Point
    worst: list[float]

    def to_json(self) -> dict[str, Any]:
        """As a JSON object (inf written as null)."""
        return {
            "gamma": self.gamma,
            "worst": [x if math.isfinite(x) else None for x in self.worst],
            "point": self.point.to_json(),
        }


def choose_gamma(points: list[GammaPoint], budget: np.ndarray) -> list[GammaPoint | None]:
    """Per follower, the admissible γ candidate with the smallest χ̄ over the health range.

    Admissible for follower i: its run reaches the horizon, every guaranteed row holds,
    every follower is covered and its peak torque after the start-up is within its budget
    (a candidate whose run stops is refused). Ties go to the smaller γ_i. None: none is.

    Parameters
    ----------
    points : list of GammaPoint
    budget : ndarray
        Per follower, the torque budget.
    """
    out: list[GammaPoint | None] = []
    for i in range(len(budget)):
        ok = [p for p in points if _level_ok(p.point, i, budget)]
        out.append(min(ok, key=lambda p: (p.worst[i], p.gamma[i])) if ok else None)
    return out
