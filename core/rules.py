"""Rules between scenario settings, checked by :meth:`core.scenario.Scenario.validate`.

Each :class:`Rule` names the setting an error names, its words in the type column of
docs/scenario-format.md and the check; :data:`RULES` lists them in the order they are checked.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from core import methods

if TYPE_CHECKING:
    from core.model import Scenario

Problem = tuple[str, str]  # (what is wrong, what is expected)


@dataclass(frozen=True)
class Rule:
    """A rule between settings, checked once, by :meth:`Scenario.validate`.

    Attributes
    ----------
    key : str
        The setting an error names.
    text : str
        Its words in the type column of docs/scenario-format.md (``"< delta1"``);
        empty for a rule that applies only in some cases.
    broken : callable
        ``(what is wrong, what is expected)`` for a scenario that breaks it, else None.
    """

    key: str
    text: str
    broken: Callable[[Scenario], Problem | None]


def _delta_hat_below(k: int) -> Callable[[Scenario], Problem | None]:
    def broken(s: Scenario) -> Problem | None:
        hat, full = getattr(s.observer, f"delta{k}_hat"), getattr(s.observer, f"delta{k}")
        if hat >= full:
            return f"{hat} >= delta{k} = {full}", f"0 < delta{k}_hat < delta{k}"
        return None

    return broken


def _phi0_above_floor(s: Scenario) -> Problem | None:
    o = s.observer
    if np.any(o.phi0 <= o.phi_min):
        return "phi0 must exceed phi_min", f"phi0 > phi_min = {o.phi_min}"
    return None


def _sigma_for_sigma_laws(s: Scenario) -> Problem | None:
    law = s.options.ghat_law
    if "sigma" in law and np.any(s.controller.sigma <= 0):
        return f"ghat_law {law!r} needs sigma > 0", "sigma > 0"
    return None


def _g_min_below_health(s: Scenario) -> Problem | None:
    if "projection" not in s.options.ghat_law:
        return None
    g_min, worst = s.controller.g_min, min(fo.g.minimum for fo in s.followers)
    if worst < g_min * (1 - 1e-12):
        return (
            f"{g_min:g} exceeds the smallest actuator health {worst:.4g}, so the "
            f"projection of ghat onto [1, 1/g_min] excludes 1/g",
            f"g_min <= {worst:.4g}, or ghat_law without projection",
        )
    return None


def _exact_sign_needs_fixed_step(s: Scenario) -> Problem | None:
    if s.options.sign == "exact" and not methods.is_fixed_step(s.integration.method):
        return (
            "'exact' makes variable-step integrators chatter and fail",
            "sign = 'tanh' or 'sat', or integration.method = 'fixed'",
        )
    return None


def _step_within_horizon(key: str) -> Callable[[Scenario], Problem | None]:
    def broken(s: Scenario) -> Problem | None:
        step, horizon = getattr(s.integration, key), s.integration.horizon
        if step > horizon:
            return f"{step} exceeds the horizon {horizon}", f"{key} <= horizon"
        return None

    return broken


def _switches_fit(s: Scenario) -> Problem | None:
    """A scenario made by ``replace`` keeps its graph switches inside the horizon and the graph."""
    H, N = s.integration.horizon, s.N
    for k, sw in enumerate(s.graph.switches):
        agents = [sw.follower] + ([] if sw.neighbour is None else [sw.neighbour])
        if not 0.0 < sw.time < H or max(agents) >= N:
            return (
                f"switch {k + 1} (t = {sw.time:g} s, {sw.link}) is outside (0, {H:g}) s "
                f"or the {N} followers",
                "switch times inside (0, horizon) and agents of the graph",
            )
    return None


def _design_budget(s: Scenario) -> Problem | None:
    """A ``[design]`` table must say what torque the gains may use."""
    if s.design is not None and s.design.u_max is None:
        return (
            "is missing: a design needs a torque budget",
            "u_max = peak |u_i| allowed after the start-up, > 0 (one number or one per follower)",
        )
    return None


def _design_health(s: Scenario) -> Problem | None:
    """The declared health range must contain each follower's health over the run."""
    if s.design is None:
        return None
    for i, fo in enumerate(s.followers):
        if fo.g.minimum < s.design.g_min[i] * (1 - 1e-12):
            return (
                f"{s.design.g_min[i]:g} for follower {i + 1} exceeds its smallest health "
                f"{fo.g.minimum:.4g}",
                f"g_min <= {fo.g.minimum:.4g}",
            )
    return None


def _design_bounds(s: Scenario) -> Problem | None:
    """The declared disturbance bounds must cover the followers' own."""
    if s.design is None:
        return None
    if s.design.d is not None:
        for i, fo in enumerate(s.followers):
            own = np.asarray(fo.d, float)
            if np.any(s.design.d[i] < own * (1 - 1e-12)):
                return (
                    f"{s.design.d[i].tolist()} for follower {i + 1} is below its "
                    f"|f_ir| bound {own.tolist()}",
                    'd_ir >= each follower\'s d (given or sup |f_ir|), or d = "none"',
                )
    return None


def _design_alpha(s: Scenario) -> Problem | None:
    """The declared operator bound must cover the leader's."""
    if s.design is not None and s.design.alpha is not None and s.design.alpha < s.leader.alpha:
        return (
            f"alpha = {s.design.alpha:g} is below leader.alpha = {s.leader.alpha:g}",
            'alpha >= leader.alpha, or alpha = "none"',
        )
    return None


#: every rule between settings, in the order they are checked
RULES: tuple[Rule, ...] = (
    Rule("integration.output_step", "≤ horizon", _step_within_horizon("output_step")),
    Rule("integration.fixed_step", "≤ horizon", _step_within_horizon("fixed_step")),
    Rule("observer.delta1_hat", "< delta1", _delta_hat_below(1)),
    Rule("observer.delta2_hat", "< delta2", _delta_hat_below(2)),
    Rule("observer.phi0", "> phi_min", _phi0_above_floor),
    Rule("controller.sigma", "", _sigma_for_sigma_laws),
    Rule("controller.g_min", "", _g_min_below_health),
    Rule("options.sign", "", _exact_sign_needs_fixed_step),
    Rule("graph.switches", "", _switches_fit),
    Rule("design.u_max", "", _design_budget),
    Rule("design.g_min", "", _design_health),
    Rule("design.d", "", _design_bounds),
    Rule("design.alpha", "", _design_alpha),
)
