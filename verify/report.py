"""The report: ``out/<name>/report.md`` and ``out/<name>/bounds.csv`` (atomic writes)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from core.artifacts import atomic_write_text
from core.scenario import Scenario
from verify import claims as CL
from verify.bounds import VerifyConfig, theorem1_floor, theorem1_rates, theorem2_constants
from verify.effort import PEAK_U, PEAK_U_LATE
from verify.lyapunov import InequalityCheck
from verify.rows import KINDS, failed_mask, held_mask
from verify.table import (
    FIG13_LEVEL_FACTOR,
    SATURATION_NOTE,
    STARTUP,
    SWITCHING_NOTE,
    failures,
    to_markdown,
)
from verify.theorem2_check import theorem2_guaranteed


@dataclass
class Verification:
    """Everything the report shows.

    Attributes
    ----------
    scenario : Scenario
    table : DataFrame
        The bound-vs-actual table.
    gains : Gains or None
    theorem1 : list of InequalityCheck
        [supported rate, printed rate] (empty when the closed loop was not available).
    theorem2 : list of InequalityCheck
        One per follower.
    ablation_summary : str
        Plain statement on Fig. 13.
    figures : list of Path
    notes : list of str
        Anything skipped or approximated.
    meta : dict
        Simulation metadata (method, stats) when known.
    config : VerifyConfig
    numbers : list of verify.headline.Worst
        The headline's three numbers (:func:`verify.headline.run_numbers`; empty when the
        trajectory was not at hand).
    """

    scenario: Scenario
    table: pd.DataFrame
    gains: object | None = None
    theorem1: list[InequalityCheck] = field(default_factory=list)
    theorem2: list[InequalityCheck] = field(default_factory=list)
    ablation_summary: str = ""
    figures: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    meta: dict = field(default_factory=dict)
    config: VerifyConfig = field(default_factory=VerifyConfig)
    numbers: list = field(default_factory=list)

    def headline(self, strict: bool = False) -> list[str]:
        """The verdict, one line per follower and the three numbers (:mod:`verify.headline`).

        Parameters
        ----------
        strict : bool
            Also count the paper's own claims.
        """
        from verify.headline import headline_lines

        return headline_lines(self.table, self.numbers, strict)

    def failed(self, strict: bool = False) -> pd.DataFrame:
        """Rows that fail ``check`` (guaranteed; plus the paper's claims when strict).

        Parameters
        ----------
        strict : bool
            Also count the paper's own claims (kind ``paper``).
        """
        return failures(self.table, strict)


def ablation_statement(table: pd.DataFrame) -> str:
    """One plain sentence on whether the ablation (42) converges more slowly (Fig. 13).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    """
    cid = table["claim_id"]
    rows = table[(cid == CL.FIG13_VERDICT.id) & (table["kind"] == "paper")]
    if rows.empty:
        return "No ablation run: Fig. 13 was not reproduced."
    ft, ab = rows["bound"].to_numpy(float), rows["observed"].to_numpy(float)
    slower = int(np.sum(ab > ft))
    same = int(np.sum(np.isclose(ab, ft)))
    tr = table[cid == CL.FIG13_TAIL.id]["ratio"].to_numpy(float)
    fixed = table[cid.isin([CL.FIG13_VERDICT.id, CL.FIG13_FIXED.id]) & (table["kind"] != "paper")]
    rates = table[cid == CL.FIG13_RATE.id]
    txt = (
        f"Fig. 13 (eq. (42) ablation u_i = Psi_i vs the fault-tolerant u_i = ghat_i Psi_i): "
        f"the ablation's |e_ti| enters {FIG13_LEVEL_FACTOR:g} x the larger tail sup of both runs "
        f"later for {slower} of {len(rows)} followers (same time for {same}); FTC times "
        f"{_fmt_list(ft)} s, ablation times {_fmt_list(ab)} s; tail-sup ratio ablation/FTC "
        f"{_fmt_list(tr)}. "
    )
    if not fixed.empty:
        fslow = int(np.sum(fixed["observed"].to_numpy(float) > fixed["bound"].to_numpy(float)))
        txt += (
            f"At the fixed level 1e-2, close to the tails (it can time the noise floor), "
            f"the ablation is later for {fslow} of {len(fixed)}. "
        )
    if not rates.empty:
        txt += (
            f"Fitted decay rates of |e_ti| (1/s) up to the earlier entering time: FTC "
            f"{_fmt_list(rates['bound'].to_numpy(float))}, ablation "
            f"{_fmt_list(rates['observed'].to_numpy(float))}. "
        )
    if slower == len(rows):
        txt += "The ablation converges more slowly, as the paper's Fig. 13 shows."
    elif slower == 0:
        txt += "The ablation does NOT converge more slowly here: the paper's Fig. 13 is not reproduced."
    else:
        txt += "The ablation is slower only for some followers: Fig. 13 is only partly reproduced."
    return txt


def _fmt_list(a: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in a) + "]"


def paper_t2_sentence(rows: pd.DataFrame) -> str:
    """The findings' sentence on Theorem 2's printed bounds (31), from exactly ``rows``.

    Rows with a positive bound give the largest observed/bound; rows with bound 0 (d_i = 0)
    are asymptotic claims, counted apart with how many of them hold as a decay.

    Parameters
    ----------
    rows : DataFrame
        The ``paper`` rows of (31).
    """
    pos, zero = rows[rows["bound"] > 0], rows[rows["bound"] == 0]
    parts = []
    if len(pos):
        bad = int(failed_mask(pos).sum())
        verdict = (
            "they hold here although they do not follow as printed (docs/fidelity.md, D3)"
            if not bad
            else f"{bad} of {len(pos)} are violated"
        )
        parts.append(
            f"observed/bound at most {pos['ratio'].max():.3g} on the tail over the "
            f"{len(pos)} rows with a positive bound; {verdict}"
        )
    if len(zero):
        parts.append(
            f"{len(zero)} rows have bound 0 (d_i = 0): asymptotic claims, of which "
            f"{int(held_mask(zero).sum())} decay on the tail"
        )
    return "- Theorem 2's printed bounds (31): " + "; ".join(parts) + "."


def findings(v: Verification) -> list[str]:
    """A few plain sentences with the headline numbers.

    Parameters
    ----------
    v : Verification
        The verification results.
    """
    tb = v.table
    out = ["Findings:", ""]
    if v.theorem2:
        n_ok = sum(c.ok for c in v.theorem2)
        out.append(
            f"- Consistency (not evidence for Theorem 2): eq. (38) with exact dV2/dt holds at "
            f"every output time for {n_ok} of {len(v.theorem2)} followers."
        )
    prov = tb[(tb["kind"] == "guaranteed") & tb["claim_id"].isin([CL.T2_CHI.id, CL.T2_E.id])]
    if not prov.empty:
        out.append(
            f"- Theorem 2, provable variant (every term of the derivation included): "
            f"{int(held_mask(prov).sum())} of {len(prov)} rows hold, observed/bound at most "
            f"{prov['ratio'].max():.3g}."
        )
    paper_t2 = tb[
        (tb["kind"] == "paper") & tb["claim_id"].isin([CL.T2_CHI_PAPER.id, CL.T2_E_PAPER.id])
    ]
    if not paper_t2.empty:
        out.append(paper_t2_sentence(paper_t2))
    for chk, label in zip(v.theorem1, ("supported", "printed", "floor"), strict=False):
        what = "+ c_phi (phi floor, supported rate)" if label == "floor" else f"({label} rate)"
        out.append(
            f"- dV1/dt <= -delta~ V1 {what} holds at {100 * chk.fraction:.1f}% of output times."
        )
    ebar = tb[tb["claim_id"] == CL.T1_TAIL.id]
    if not ebar.empty:
        out.append(
            f"- Observer error on the tail: max |ebar_eta_i| = {ebar['observed'].max():.3g}."
        )
    lem = tb[tb["claim_id"] == CL.LEMMA1_PAPER.id]
    if not lem.empty:
        out.append(
            f"- Lemma 1: V2 enters its level after {lem['observed'].min():.3g}–"
            f"{lem['observed'].max():.3g} s; the printed t_f bounds are "
            f"{lem['bound'].min():.3g}–{lem['bound'].max():.3g} s."
        )
    out.append("")
    return out


def effort_section(table: pd.DataFrame) -> list[str]:
    """Markdown lines: peak |u_i| and its time per follower, over the run and after start-up.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table (its ``peak |u_i|`` rows).
    """
    rows = table[table["claim_id"].isin([PEAK_U.id, PEAK_U_LATE.id])]
    if rows.empty:
        return []
    L = [
        "",
        "## Control effort",
        "",
        f"Peak Euclidean norm of the logged torque u_i, over the run and after t = {STARTUP:g} s "
        "(the start-up peak, driven by the initial errors, dominates the first).",
        "",
        "| follower | window | peak norm of u_i | at |",
        "|---|---|---|---|",
    ]
    for r in rows.itertuples(index=False):
        at = r.note.split(";")[0].removeprefix("at ")
        L.append(f"| {r.agent} | {r.window} | {r.observed:.4g} | {at} |")
    return L


#: figures shown inline in the report (the others are linked)
SHOWN_FIGURES = (
    "fig03-10_formation_overview",
    "fig11_estimation_errors_log",
    "fig12_tracking_errors_log",
    "fig13_ablation",
    "lyapunov_V1",
    "lyapunov_V2",
)


def render_markdown(v: Verification, *, strict: bool = False) -> str:
    """The report as Markdown text.

    Parameters
    ----------
    v : Verification
        The verification results.
    strict : bool
        Whether the paper's own claims count as failures.
    """
    L = header_section(v)
    L += summary_section(v, strict)
    L += theorem1_section(v)
    L += theorem2_section(v)
    L += effort_section(v.table)
    L += ["", "## Ablation (Fig. 13)", "", v.ablation_summary or ablation_statement(v.table), ""]
    L += figures_section(v.figures)
    if v.notes:
        L += ["## Notes", ""] + [f"- {n}" for n in v.notes] + [""]
    L += [
        "## Bound vs actual",
        "",
        f"Tail window: last {100 * v.config.tail_fraction:g}% of the horizon. "
        "ratio = observed/bound.",
        "",
        to_markdown(v.table),
        "",
    ]
    return "\n".join(L)


def header_section(v: Verification) -> list[str]:
    """Title, scenario, simulation metadata and options (report lines).

    Parameters
    ----------
    v : Verification
        The verification results.
    """
    sc = v.scenario
    L: list[str] = [f"# Verification report: `{sc.name}`", ""]
    L += [f"Scenario `{sc.path}` (sha256 `{sc.sha256[:12]}`): {sc.description}", ""]
    if v.meta:
        keys = ("method", "complete", "t_reached", "wall_seconds", "steps")
        info = ", ".join(f"{k} = {v.meta[k]}" for k in keys if k in v.meta)
        if info:
            L += [f"Simulation: {info}.", ""]
    o = sc.options
    return L + [
        f"Options: sign = {o.sign} (width {o.sign_width:g}), ghat law = {o.ghat_law}, "
        f"feedforward = {o.feedforward}, derivatives = {o.derivatives}, ablation = {o.ablation}, "
        f"phi_min = {sc.observer.phi_min:g}.",
        "",
    ]


def summary_section(v: Verification, strict: bool) -> list[str]:
    """Row counts per kind, the verdict, the findings and the paper's claims that fail.

    Parameters
    ----------
    v : Verification
        The verification results.
    strict : bool
        Whether the paper's own claims count as failures.
    """
    tb = v.table
    L = ["## Summary", ""]
    for kind in KINDS:
        sub = tb[tb["kind"] == kind]
        if sub.empty:
            continue
        bad, good = int(failed_mask(sub).sum()), int(held_mask(sub).sum())
        rest = len(sub) - bad - good
        L.append(
            f"- **{kind}**: {len(sub)} rows, {good} hold, {bad} do not"
            + (f", {rest} not evaluated (the note says why)." if rest else ".")
        )
    fg, fp = v.failed(False), tb[(tb["kind"] == "paper") & failed_mask(tb)]
    head = v.headline(strict)
    verdict = head[0].split(":", 1)[0] if fg.empty and (not strict or fp.empty) else "FAIL"
    L += [
        "",
        "Coverage and the headline numbers (computed from the rows below):",
        "",
        "```",
        *head,
        "```",
        "",
        f"Verdict ({'strict' if strict else 'default'}): **{verdict}**. `guaranteed` rows follow "
        "from the theory for this reconstruction (a failure is a bug); `consistency` rows cannot "
        "fail for a correct implementation, so they are no evidence for a theorem (a failure is "
        "a bug); `paper` rows are the paper's claims as printed, which do not all follow "
        "(docs/fidelity.md, deviations); `info` rows are measurements.",
        "",
    ]
    L += saturation_statement(tb)
    L += switching_statement(v.scenario, tb)
    L += findings(v)
    if not fp.empty:
        L.append("The paper's claims that do not hold on these numbers:")
        L.append("")
        for r in fp.itertuples(index=False):
            L.append(
                f"- {r.claim}, follower {r.agent}{' comp. ' + r.component if r.component else ''}:"
                f" bound {r.bound:.4g}, observed {r.observed:.4g} ({r.window})"
            )
        L.append("")
    return L


def saturation_statement(table: pd.DataFrame) -> list[str]:
    """One sentence when actuator saturation invalidated rows of the table (else nothing).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table (rows marked by :func:`verify.table.mark_saturation`).
    """
    notes = table.loc[table["note"].str.startswith(SATURATION_NOTE), "note"]
    if notes.empty:
        return []
    where = notes.iloc[0].split(";")[0].removeprefix(SATURATION_NOTE).strip()
    return [
        f"Actuator saturation (controller.u_max) was active on {where}: the {len(notes)} rows "
        "derived from the unsaturated control law (29) (Theorem 2, eq. (38), Lemmas 1-2, "
        "Definition 1) are shown as `info` with the note 'invalidated', neither passed nor "
        "failed.",
        "",
    ]


def switching_statement(sc: Scenario, table: pd.DataFrame) -> list[str]:
    """Which topology held when, and which rows it invalidated (nothing without switches).

    Parameters
    ----------
    sc : Scenario
        Its ``graph.switches``.
    table : DataFrame
        The bound-vs-actual table (rows marked by :func:`verify.table.mark_switching`).
    """
    if not sc.graph.switches:
        return []
    tops = sc.graph.topologies()
    ends = [f"{tp.t_start:g}" for tp in tops[1:]] + [f"{sc.integration.horizon:g}"]
    held = [f"the base graph on [0, {ends[0]}) s"]
    for k, tp in enumerate(tops[1:]):
        links = ", ".join(
            f"{s.link} = {s.weight:g}" for s in sc.graph.switches if s.time == tp.t_start
        )
        held.append(f"from {tp.t_start:g} s to {ends[k + 1]} s {links}")
    n = int(table["note"].str.startswith(SWITCHING_NOTE).sum())
    T = sc.graph.link_fade
    fade = (
        f" (each change fading in over {T:g} s, `graph.link_fade`)" if T > 0 else " (raw switching)"
    )
    return [
        "The graph switches (`[[graph.switches]]`, outside the paper's theorems)"
        + fade
        + ": "
        + "; ".join(held)
        + f". The {n} rows built on V1 of the base graph (Theorem 1's dV1/dt and decay rate, "
        "the derived Definition 1 bound), Lemma 1's reaching time from V2(0) and the paper's "
        "rows whose window holds a switch (they measure its transient) are shown as "
        "`info` with the note 'invalidated by switching topology'; Theorem 2's provable rows "
        f"restart their comparison lemma after the last switch ({tops[-1].t_start:g} s).",
        "",
    ]


def theorem1_section(v: Verification) -> list[str]:
    """Theorem 1: the rates, the exact dV1/dt checks and what the phi floor changes.

    Parameters
    ----------
    v : Verification
        The verification results.
    """
    sc = v.scenario
    L = ["## Theorem 1 (distributed observer)", ""]
    if v.gains is not None:
        r1 = theorem1_rates(sc, v.gains)
        L += [
            f"Rates: supported delta~ = min(delta1 - delta1_hat, alpha1~, delta2 - delta2_hat) = "
            f"{r1.supported:.4g}; printed delta~ = min(delta1, alpha1~, delta2) = {r1.printed:.4g}.",
            "",
        ]
    for chk, label in zip(v.theorem1, ("supported", "printed"), strict=False):
        L.append(
            f"- dV1/dt <= -delta~ V1 with the {label} rate: holds at {100 * chk.fraction:.2f}% of "
            f"output times; worst lhs - rhs = {chk.worst:.4g} at t = {chk.t_worst:.4g} s. "
            "dV1/dt is exact (AD of V1 along the vector field)."
        )
    if sc.observer.phi_min > 0:
        L += _phi_floor_lines(v)
    L.append("")
    return L


def _phi_floor_lines(v: Verification) -> list[str]:
    """What the phi floor does to Theorem 1, with c_phi when the gains are known."""
    sc = v.scenario
    L = [
        "",
        f"The phi floor (phi_min = {sc.observer.phi_min:g}) keeps the oracle derivatives "
        "finite but leaves the term 2 lambda2 sum l_ii z_i phi_i / alpha1bar_i of V1 "
        "bounded away from zero: the observer is only ultimately bounded and "
        "dV1/dt <= -delta~ V1 cannot hold once V1 reaches that level (see the rows above).",
    ]
    if v.gains is not None:
        fl = theorem1_floor(sc, v.gains)
        L += [
            "",
            f"With the floor the proof gives dV1/dt <= -delta~ V1 + c_phi, c_phi = 2 lambda2 "
            f"phi_min sum l_ii z_i (alpha1_i + alpha1bar_i)/alpha1bar_i = {fl.c_phi:.4g} "
            f"(delta~ = {fl.rate:.4g}, limsup V1 <= c_phi/delta~ = {fl.c_phi / fl.rate:.4g}; "
            "docs/verification.md). It is the guaranteed Theorem 1 row.",
        ]
    return L


def theorem2_section(v: Verification) -> list[str]:
    """Theorem 2: the eq. (38) consistency checks and the constants table.

    Parameters
    ----------
    v : Verification
        The verification results.
    """
    sc, cfg = v.scenario, v.config
    guaranteed, why = theorem2_guaranteed(sc)
    L = ["## Theorem 2 (fault-tolerant controller)", ""]
    L += [
        f"Implementation consistency: pointwise inequality (38) with exact dV2/dt by AD; {why}."
        + ("" if guaranteed else " It is therefore reported, not required.")
        + " With the shipped adaptive laws dV2/dt minus the right side of (38) equals "
        "chi'f - d'|chi| - k2|thetahat|^2/2 (plus the projection's term <= 0), which is <= 0 "
        "whenever |f_r| <= d_r: this checks the simulated closed loop against its derivation, "
        "it is not evidence for Theorem 2 (the provable-variant rows are).",
        "",
    ]
    for chk in v.theorem2:
        L.append(f"- {chk.where()}; worst lhs - rhs = {chk.worst:.4g}.")
    L += [
        "",
        "Constants (lambda_min/max(M) over all joint angles, Lemma 1 delta = "
        f"{cfg.lemma1_delta:g}):",
        "",
        "| follower | lambda_min(M) | lambda_max(M) | Omega_v2 | chi_v2 | chi_bar (paper) "
        "| ghat law | ghat term | layer term | chi_bar (provable) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i in range(sc.N):
        c = theorem2_constants(sc, i, cfg)
        prov = f"{c.chi_bar_var:.4g}" if c.provable else f"does not follow: {c.why_not}"
        L.append(
            f"| {i + 1} | {c.lam_min_M:.4g} | {c.lam_max_M:.4g} | {c.Omega:.4g} | {c.chi_v:.4g} | "
            f"{c.chi_bar:.4g} | {c.variant} | {c.ghat_term:.4g} | {c.layer_term:.4g} | {prov} |"
        )
    return L


def figures_section(figures: list[Path]) -> list[str]:
    """The :data:`SHOWN_FIGURES` inline and links to every PNG and GIF (none without figures).

    Parameters
    ----------
    figures : list of Path
        The figure files written.
    """
    if not figures:
        return []
    L = ["## Figures", ""]
    for p in figures:
        if p.suffix == ".png" and p.stem in SHOWN_FIGURES:
            L += [f"![{p.stem}](figures/{p.name})", ""]
    L.append("All files (PNG and PDF):")
    L.append("")
    for p in figures:
        if p.suffix in (".png", ".gif"):
            L.append(f"- [{p.name}](figures/{p.name})")
    L.append("")
    return L


def write_report(v: Verification, folder: Path, *, strict: bool = False) -> tuple[Path, Path]:
    """Write ``bounds.csv`` and ``report.md`` into ``folder`` atomically.

    Parameters
    ----------
    v : Verification
        The verification results.
    folder : Path
        Output folder (created).
    strict : bool
        Whether the paper's own claims count as failures.

    Returns
    -------
    (report path, bounds path)
    """
    folder.mkdir(parents=True, exist_ok=True)
    bpath = atomic_write_text(folder / "bounds.csv", v.table.to_csv(index=False))
    rpath = atomic_write_text(folder / "report.md", render_markdown(v, strict=strict))
    return rpath, bpath


def console_table(table: pd.DataFrame) -> str:
    """Compact plain-text table for the terminal.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    """
    cols = ["claim", "agent", "component", "kind", "bound", "observed", "ratio", "holds"]
    t = table[cols].copy()
    t["claim"] = t["claim"].str.slice(0, 60)
    with pd.option_context("display.max_rows", None, "display.width", 200):
        return t.to_string(
            index=False,
            formatters={
                c: (lambda x: "nan" if isinstance(x, float) and math.isnan(x) else f"{x:.4g}")
                for c in ("bound", "observed", "ratio")
            },
        )
