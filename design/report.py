"""The design report: out/<name>-designed/design.md and its two fronts as PNG figures.

- the observer: the decay rate of LMI (15) against the cap on ‖Q‖ and of LMI (16) against
  the cap on ‖Θ‖ (:func:`synthesis.design.design_lmi15`, ``design_lmi16``), the chosen rates
  and the scenario's own gains on the same axes;
- the controller: the time to the guarantee (max_i t_c) and the ultimate bound (largest
  Definition 1 bound) against the peak torque after the start-up, and the two against each
  other, every candidate, the designed gains and the scenario's own gains.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from core.artifacts import atomic_write_text
from synthesis.design import ObserverDesign, RobustTerm, layer_residual

if TYPE_CHECKING:
    from core.provenance import Provenance
    from core.scenario import Scenario
    from design.controller import Point
    from design.run import DesignResult


def _fmt(x: float, digits: int = 4) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _front(points: list[Point]) -> list[Point]:
    """The points no other point beats in both peak torque and max t_c."""
    out = []
    for p in points:
        if not any(
            q.peak_max <= p.peak_max
            and q.tc_max <= p.tc_max
            and (q.peak_max, q.tc_max) != (p.peak_max, p.tc_max)
            for q in points
        ):
            out.append(p)
    return sorted(out, key=lambda p: p.peak_max)


def _save(fig, path: Path) -> None:  # noqa: ANN001
    """Write the PNG atomically (temporary file, then rename)."""
    import os

    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fig.savefig(tmp, dpi=110, format="png")
    os.replace(tmp, path)


def observer_figure(d: DesignResult, path: Path) -> None:
    """Rate against gain norm for LMIs (15) and (16), chosen and given points marked.

    Parameters
    ----------
    d : DesignResult
    path : Path
        The PNG written.
    """
    from core.pyplot import pyplot

    plt = pyplot()

    od = d.observer
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    ax = axes[0]
    caps = [r.q_max for r in od.front15]
    ax.plot(caps, [r.delta for r in od.front15], "o-", label="largest δ1 under the cap")
    qn = float(np.linalg.norm(od.Q, 2))
    ax.plot([qn], [od.delta1], "r*", ms=14, label=f"chosen: δ1 = {od.delta1:.3g}")
    if od.given15 is not None:
        ax.plot([od.given15.q_max], [od.given15.delta_max], "ks", label="the scenario's Q (own δ1)")
        ax.plot(
            [od.given15.q_max],
            [d.base.observer.delta1],
            "kx",
            ms=10,
            label=f"the scenario's δ1 = {d.base.observer.delta1:g}",
        )
    ax.set_xscale("log")
    ax.set_xlabel("‖Q‖ (cap)")
    ax.set_ylabel("δ1 of LMI (15)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    ax = axes[1]
    caps = [r.theta_max for r in od.front16]
    ax.plot(caps, [r.delta for r in od.front16], "o-", label="largest δ2 under the cap")
    ax.plot(
        [float(np.linalg.norm(od.Theta, 2))],
        [od.delta2],
        "r*",
        ms=14,
        label=f"chosen: δ2 = {od.delta2:.3g}",
    )
    ax.axhline(
        d.base.observer.delta2,
        color="k",
        ls=":",
        label=f"the scenario's δ2 = {d.base.observer.delta2:g}",
    )
    ax.set_xscale("log")
    ax.set_xlabel("‖Θ‖ (cap)")
    ax.set_ylabel("δ2 of LMI (16)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def controller_figure(d: DesignResult, path: Path) -> None:
    """max_i t_c and the ultimate bound against peak torque; chosen and given gains marked.

    Parameters
    ----------
    d : DesignResult
    path : Path
        The PNG written.
    """
    from core.pyplot import pyplot

    plt = pyplot()

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    budget = float(np.max(d.base.design.u_max))
    ok = [p for p in d.points if p.holds and p.covered_all]
    front = _front(ok)
    for ax, what, label in (
        (axes[0], lambda p: p.tc_max, "time to the guarantee max_i t_c (s)"),
        (axes[1], lambda p: p.bound, "ultimate bound max_i (Definition 1) "),
    ):
        ax.scatter(
            [p.peak_max for p in ok],
            [what(p) for p in ok],
            c="0.6",
            s=18,
            label="candidates (one level for every follower)",
        )
        ax.plot(
            [p.peak_max for p in front],
            [what(p) for p in front],
            "b-",
            lw=1,
            label="front (torque against t_c)",
        )
        ax.plot([d.designed.peak_max], [what(d.designed)], "r*", ms=14, label="designed")
        ax.plot([d.given.peak_max], [what(d.given)], "ks", label="the scenario's gains")
        ax.axvline(budget, color="r", ls=":", label=f"budget {budget:g}")
        ax.set_xlabel("peak ‖u_i‖ after the start-up")
        ax.set_ylabel(label)
        ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    ax = axes[2]  # the trade the budget leaves: time to the guarantee against its level
    inb = [p for p in ok if p.within(np.asarray(d.base.design.u_max, float))]
    out = [p for p in ok if p not in inb]
    ax.scatter(
        [p.tc_max for p in inb],
        [p.bound for p in inb],
        c="b",
        s=18,
        label="candidates within the budget",
    )
    ax.scatter(
        [p.tc_max for p in out], [p.bound for p in out], c="0.7", s=18, label="over the budget"
    )
    ax.plot([d.designed.tc_max], [d.designed.bound], "r*", ms=14, label="designed")
    ax.plot([d.given.tc_max], [d.given.bound], "ks", label="the scenario's gains")
    ax.set_xlabel("time to the guarantee max_i t_c (s)")
    ax.set_ylabel("ultimate bound max_i (Definition 1)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _row(name: str, p: Point) -> str:
    return (
        f"| {name} | {_fmt(p.k1)} | {_fmt(p.lam)} | {_fmt(p.peak_max)} | {_fmt(p.tc_max, 3)} | "
        f"{_fmt(max(p.chi_bar))} | {_fmt(p.bound)} | {p.coverage:.0%} | "
        f"{'yes' if p.holds else 'NO'} |"
    )


def _gamma_lines(d: DesignResult) -> list[str]:
    """The ĝ law's γ candidates: per follower χ̄ over the declared health range, the run."""
    if not d.gammas:
        return []
    g = np.asarray(d.base.design.g_min, float)
    out = [
        "",
        "## The ĝ law's γ",
        "",
        "Each row is one simulated and verified run with the designed k1, λ, k2, σ and γ_i "
        "(the first: the scenario's own); χ̄_i over the declared health range [g_min_i, 1] "
        f"(g_min = {', '.join(_fmt(x) for x in g)}) from Theorem 2's closed form. Per follower "
        "the admissible row (run complete, rows hold, every follower covered, within budget) "
        "with the smallest χ̄_i is taken.",
        "",
        "| γ_i | peak ‖u_i‖ | max t_c (s) | χ̄_i over [g_min, 1] | χ̄_i of the run | complete | rows hold |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in d.gammas:
        q = p.point
        out.append(
            f"| {', '.join(_fmt(x) for x in p.gamma)} | "
            f"{', '.join(_fmt(x) for x in q.peak)} | {_fmt(q.tc_max, 3)} | "
            f"{', '.join(_fmt(x) for x in p.worst)} | {', '.join(_fmt(x) for x in q.chi_bar)} | "
            f"{'yes' if q.complete else 'NO'} | {'yes' if q.holds else 'NO'} |"
        )
    return out


def _observer_lines(od: ObserverDesign, sc: Scenario) -> list[str]:
    """The observer's chosen rates and gains, and its robust term's design."""
    return [
        f"Chosen: δ1 = {od.delta1:.4g}, δ2 = {od.delta2:.4g} (δ̂ = δ/2), "
        f"‖Q‖ = {np.linalg.norm(od.Q, 2):.4g} ({'designed' if od.designed_Q else 'the scenario’s, kept'}), "
        f"‖Θ‖ = {np.linalg.norm(od.Theta, 2):.4g} ({'designed' if od.designed_Theta else 'the scenario’s, kept'}); "
        f"the scenario's δ1 = {sc.observer.delta1:g}, δ2 = {sc.observer.delta2:g}.",
        "",
        *_robust_lines(od.robust, sc),
    ]


def _robust_lines(r: RobustTerm, sc: Scenario) -> list[str]:
    """The robust term's design: λ2, φ_min, and the layer residual against the scenario's."""
    alpha = sc.design.alpha if sc.design.alpha is not None else sc.leader.alpha
    mine = layer_residual(0.0, r.lambda2, r.phi_min, alpha)
    given = layer_residual(0.0, r.given_lambda2, r.given_phi_min, alpha)
    return [
        f"Robust term of eq. (9): λ2 = {r.lambda2:.4g}, φ_min = {r.phi_min:.4g} "
        f"(the scenario's {r.given_lambda2:.4g}, {r.given_phi_min:.4g}; layer slope "
        f"λ2/φ_min = {r.slope:.4g} kept). Residual ‖Qê‖ at which the term balances "
        f"‖u0‖ = α = {alpha:g} without the linear term: {_fmt(mine)} "
        f"(the scenario's: {_fmt(given)}"
        + ("; with λ2 = α only the linear term bounds it)." if math.isinf(given) else ")."),
    ]


def write_report(d: DesignResult, folder: Path, prov: Provenance) -> Path:
    """design.md and figures/design_observer.png, figures/design_controller.png.

    Parameters
    ----------
    d : DesignResult
    folder : Path
        The designed scenario's folder.
    prov : Provenance
        Date, commit and machine of this design.
    """
    from core.provenance import provenance_line

    figs = folder / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    observer_figure(d, figs / "design_observer.png")
    controller_figure(d, figs / "design_controller.png")
    od, sc = d.observer, d.base
    lines = [
        f"# Design of `{sc.name}`",
        "",
        provenance_line(prov) + f"; the design took {d.seconds:.1f} s.",
        "",
        "How each gain is chosen: docs/synthesis.md, 'Design'. The designed scenario is "
        f"`{sc.path}` with the overrides below (`make demo SCENARIO={sc.path}` runs it).",
        "",
        "## Observer (LMIs (15), (16))",
        "",
        *_observer_lines(od, sc),
        "",
        "| ‖Q‖ cap | largest δ1 | ‖Θ‖ cap | largest δ2 |",
        "|---|---|---|---|",
    ]
    for r15, r16 in zip(od.front15, od.front16, strict=False):
        lines.append(
            f"| {r15.q_max:.4g} | {r15.delta_max:.4g} | {r16.theta_max:.4g} | {r16.delta_max:.4g} |"
        )
    if od.given15 is not None:
        lines += [
            "",
            f"The scenario's Q (‖Q‖ = {od.given15.q_max:.4g}) admits δ1 up to "
            f"{od.given15.delta_max:.4g}.",
        ]
    lines += [
        "",
        "![observer front](figures/design_observer.png)",
        "",
        "## Controller (Theorem 2, provable variant)",
        "",
        f"Budget: peak ‖u_i‖ after {sc.design.startup:g} s ≤ "
        f"{', '.join(_fmt(x) for x in np.asarray(sc.design.u_max, float))}; "
        f"bound slack {sc.design.bound_slack:g}. Each row is one simulated and verified run "
        "(k1, λ the same for every follower; k2 = σ = 2k1/λ_max(M)).",
        "",
        "| gains | k1 | λ | peak ‖u_i‖ | max t_c (s) | max χ̄ | ultimate bound | coverage | rows hold |",
        "|---|---|---|---|---|---|---|---|---|",
        _row("the scenario's", d.given),
        _row("**designed**", d.designed),
    ]
    lines += [_row("candidate", p) for p in d.points]
    lines += [
        "",
        "Per follower, the designed gains (k1, λ) and what they guarantee:",
        "",
        "| follower | k1 | λ | peak ‖u_i‖ | t_c (s) | χ̄ | Definition 1 bound | the scenario's t_c | its bound |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for i, c in enumerate(d.chosen):
        lines.append(
            f"| {i + 1} | {_fmt(c.k1)} | {_fmt(c.lam)} | {_fmt(d.designed.peak[i])} | "
            f"{_fmt(d.designed.tc[i], 3)} | {_fmt(d.designed.chi_bar[i])} | "
            f"{_fmt(d.designed.def1[i])} | {_fmt(d.given.tc[i], 3)} | {_fmt(d.given.def1[i])} |"
        )
    lines += ["", "![controller front](figures/design_controller.png)", *_gamma_lines(d)]
    lines += ["", "## Overrides", ""]
    lines += [f"- `{k} = {v}`" for k, v in d.overrides.items()]
    return atomic_write_text(folder / "design.md", "\n".join(lines) + "\n")
