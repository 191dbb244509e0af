"""``out/<study>/report.md`` and its figures from a study's ``results.parquet``."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from core.artifacts import atomic_write_text
from core.pyplot import pyplot
from sweep.coverage import GIVEN, coverage_lines, gains_lines

#: (column, label) of the medians in the summary table
MEDIANS = [
    ("tail_max_et", "tail max |e_ti| (max over followers)"),
    ("formation_tail_max", "formation error, tail sup (max over followers)"),
    ("observer_tail_max", "observer |ebar_eta_i|, tail sup (max over followers)"),
    ("peak_u_max", "peak |u_i| (max over followers)"),
    ("peak_u_late", "peak |u_i| after t = 1 s (max over followers)"),
    (
        "demanded_u_late",
        "peak |u_i*| after t = 1 s, the torque the slot demands (max over followers)",
    ),
    (
        "effort_over_demand",
        "peak |u_i| after t = 1 s over the peak the slot demands (max over followers)",
    ),
    ("step_peak_u", "peak |u_i| within 2 s after an operator step (max over followers)"),
    (
        "step_recovery_s",
        "slowest return of a pinned follower within 0.05 of its slot after an operator step, where defined [s]",
    ),
    (
        "step_deviation_max",
        "distance of a pinned follower from its slot after an operator step (max over the steps)",
    ),
    ("steps", "integrator steps"),
    ("wall_s", "wall time per sample [s]"),
]

#: columns whose largest value over the ok samples is reported too (a promise for every sample)
WORST = (
    "peak_u_late",
    "demanded_u_late",
    "effort_over_demand",
    "step_peak_u",
    "step_recovery_s",
    "step_deviation_max",
)


def status_counts(table: pd.DataFrame) -> dict[str, int]:
    """Number of ``ok``, ``refused`` and ``failed`` rows.

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    kind = table["status"].astype(str).str.split(":").str[0]
    return {k: int((kind == k).sum()) for k in ("ok", "refused", "failed")}


def entry_times(table: pd.DataFrame) -> np.ndarray:
    """Every finite Theorem 2 entry time of the ``ok`` rows (all followers pooled).

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    ok = table[table["status"] == "ok"]
    cols = [c for c in ok.columns if c.startswith("t2_entry:")]
    vals = ok[cols].to_numpy(float).ravel() if cols else np.array([])
    return vals[np.isfinite(vals)]


#: colour of each fault type in the scatter plots
TYPE_COLOURS = {"abrupt": "C0", "ramp": "C1", "intermittent": "C2", "bias": "C3"}


def _num(table: pd.DataFrame, col: str) -> np.ndarray:
    """Column ``col`` as floats (NaN where missing or not a number; all NaN if absent)."""
    if col not in table.columns:
        return np.full(len(table), np.nan)
    return pd.to_numeric(table[col], errors="coerce").to_numpy(float)


def fault_points(table: pd.DataFrame) -> pd.DataFrame:
    """One row per drawn fault of each ``ok`` sample (``param:faults[k].*`` columns).

    Parameters
    ----------
    table : DataFrame
        The results.

    Returns
    -------
    DataFrame
        Columns ``id``, ``fault`` (k), ``type``, ``follower``, ``onset``, ``severity`` (NaN
        for a bias), ``bias`` (the amplitude's Euclidean norm; NaN for a loss of
        effectiveness) and the sample's ``tail_max_et``.
    """
    ok = table[table["status"] == "ok"]
    ks = sorted({int(m.group(1)) for c in table.columns if (m := re.fullmatch(_FAULT_TYPE, c))})
    parts = []
    for k in ks:
        pre = f"param:faults[{k}]."
        amp = [c for c in ok.columns if c.startswith(pre + "amplitude[")]
        bias = np.sqrt(sum(_num(ok, c) ** 2 for c in amp)) if amp else np.full(len(ok), np.nan)
        part = pd.DataFrame(
            {
                "id": ok["id"].to_numpy(),
                "fault": k,
                "type": ok[pre + "type"].to_numpy(),
                "follower": _num(ok, pre + "follower"),
                "onset": _num(ok, pre + "onset"),
                "severity": _num(ok, pre + "severity"),
                "bias": bias,
                "tail_max_et": _num(ok, "tail_max_et"),
            }
        )
        parts.append(part[part["type"].notna()])
    cols = ["id", "fault", "type", "follower", "onset", "severity", "bias", "tail_max_et"]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=cols)


_FAULT_TYPE = r"param:faults\[(\d+)\]\.type"


def _scatter(ax, points: pd.DataFrame, x: str, xlabel: str) -> None:
    """Tail error against column ``x``, one colour per fault type; log scale when positive."""
    for kind, grp in points.groupby("type", sort=True):
        ok = np.isfinite(grp[x].to_numpy(float)) & np.isfinite(grp["tail_max_et"].to_numpy(float))
        if ok.any():
            ax.scatter(
                grp[x][ok], grp["tail_max_et"][ok], s=12, c=TYPE_COLOURS.get(kind), label=kind
            )
    y = points["tail_max_et"].to_numpy(float)
    if len(y) and np.all(y[np.isfinite(y)] > 0):
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("tail max |e_ti|")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)


def fault_figures(points: pd.DataFrame, figs: Path) -> list[Path]:
    """``error_vs_severity.png`` (loss of effectiveness: severity; bias: |amplitude|) and
    ``error_vs_onset.png``, coloured by fault type; none when no fault was drawn.

    Parameters
    ----------
    points : DataFrame
        From :func:`fault_points`.
    figs : Path
        The figures folder.
    """
    if not len(points):
        return []
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.4), sharey=True)
    _scatter(
        a1, points[points["type"] != "bias"], "severity", "fault severity (loss of effectiveness)"
    )
    _scatter(a2, points[points["type"] == "bias"], "bias", "bias fault |amplitude|")
    out = [_save(fig, figs / "error_vs_severity.png")]
    fig, ax = plt.subplots(figsize=(5, 3.4))
    _scatter(ax, points, "onset", "fault onset [s]")
    out.append(_save(fig, figs / "error_vs_onset.png"))
    return out


def graph_figure(table: pd.DataFrame, figs: Path) -> Path | None:
    """``error_vs_N.png``: tail error against the number of followers, coloured by the
    number of links lost (``param:graph.loss[k].*``), crosses where the tail window holds a
    topology switch (``tail_switches``); None without random graphs.

    Parameters
    ----------
    table : DataFrame
        The results.
    figs : Path
        The figures folder.
    """
    ok = table[table["status"] == "ok"]
    N, err = _num(ok, "param:graph.N"), _num(ok, "tail_max_et")
    good = np.isfinite(N) & np.isfinite(err)
    if not good.any():
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.4))
    lost = links_lost(ok)
    switched = tail_switched(ok)
    norm = plt.Normalize(0.0, max(1.0, float(lost[good].max())))
    for mask, marker, label in [
        (good & ~switched, "o", "tail window: one graph"),
        (good & switched, "x", "tail window: a link lost or back"),
    ]:
        if mask.any():
            pts = ax.scatter(
                N[mask],
                err[mask],
                s=18,
                c=lost[mask],
                cmap="viridis",
                norm=norm,
                marker=marker,
                label=label,
            )
    fig.colorbar(pts, ax=ax, label="links lost")
    if switched[good].any():
        ax.legend(fontsize=7)
    if np.all(err[good] > 0):
        ax.set_yscale("log")
    ax.set_xlabel("followers N")
    ax.set_ylabel("tail max |e_ti|")
    return _save(fig, figs / "error_vs_N.png")


def links_lost(table: pd.DataFrame) -> np.ndarray:
    """Number of links each row's sample loses (its ``param:graph.loss[k].time`` columns).

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    cols = [c for c in table.columns if re.fullmatch(r"param:graph\.loss\[\d+\]\.time", c)]
    return sum((np.isfinite(_num(table, c)) for c in cols), np.zeros(len(table))).astype(float)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return path


def _histogram(values: np.ndarray, xlabel: str, path: Path) -> Path | None:
    """A histogram written to ``path`` (None when there is nothing finite to draw)."""
    plt = pyplot()
    values = values[np.isfinite(values)]
    if not len(values):
        return None
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.hist(values, bins=min(30, max(5, len(values) // 2)))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("samples")
    return _save(fig, path)


def summary_lines(table: pd.DataFrame) -> list[str]:
    """The counts and medians as a Markdown table.

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    c = status_counts(table)
    ok = table[table["status"] == "ok"]
    lines = ["| quantity | value |", "|---|---|", f"| samples | {len(table)} |"]
    lines += [f"| {k} | {v} |" for k, v in c.items()]
    for col, label in [(c, lab.replace("|", "\\|")) for c, lab in MEDIANS]:
        vals = _num(ok, col)
        vals = vals[np.isfinite(vals)]
        lines.append(
            f"| median {label} | {np.median(vals):.4g} |"
            if len(vals)
            else f"| median {label} | - |"
        )
    for col, label in [(c, lab.replace("|", "\\|")) for c, lab in MEDIANS if c in WORST]:
        vals = _num(ok, col)
        vals = vals[~np.isnan(vals)]  # inf stays: a follower that never came back
        if len(vals):
            lines.append(f"| largest {label} | {np.max(vals):.4g} |")
    lines += step_lines(ok)
    lines += link_lines(ok)
    lines += given_link_lines(table)
    lines += kernel_lines(table)
    lines += tail_split_lines(ok)
    t2 = entry_times(table)
    lines.append(
        f"| median Theorem 2 entry time [s] | {np.median(t2):.4g} |"
        if len(t2)
        else "| median Theorem 2 entry time [s] | - |"
    )
    held = ok["guaranteed_held"].astype(bool)
    lines.append(f"| ok samples whose guaranteed rows all hold | {int(held.sum())} of {len(ok)} |")
    cons = ok["consistency_held"].astype(bool)
    n_cons = int(pd.to_numeric(ok["n_consistency"], errors="coerce").fillna(0).sum())
    lines.append(
        f"| ok samples whose consistency rows all hold | {int(cons.sum())} of {len(ok)} "
        f"({n_cons} consistency rows in all) |"
    )
    return lines


def step_lines(ok: pd.DataFrame) -> list[str]:
    """How many (operator step, pinned follower) pairs of the ``ok`` rows came back to
    their slot in time, and how many were late or undefined (:mod:`verify.operator_steps`);
    no line when no row has a step.

    Parameters
    ----------
    ok : DataFrame
        The ``ok`` rows.
    """
    from verify.operator_steps import RECOVERY_LEVEL, RECOVERY_LIMIT

    pairs = np.nansum(_num(ok, "step_pairs"))
    if not pairs > 0:
        return []
    late = int(np.nansum(_num(ok, "step_pairs_late")))
    undefined = int(np.nansum(_num(ok, "step_pairs_undefined")))
    back, within = int(pairs) - late - undefined, f"{RECOVERY_LIMIT:g} s"
    return [
        f"| (operator step, pinned follower) pairs back within {RECOVERY_LEVEL:g} of the slot "
        f"within {within} | {back} of {int(pairs)} ({late} late; {undefined} undefined: still "
        f"out when the next step or the horizon came within {within}) |"
    ]


def kernel_lines(table: pd.DataFrame) -> list[str]:
    """Samples run on the per-agent engine (method ``native``): the kernel libraries they
    ran and which samples compiled them, the cyclic graphs, and Theorem 1 shown with the
    paper's z on every topology (``[graph.losses] theorem1 = "measured"``); no line
    without them.

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    if "compiled" not in table.columns:
        return []
    ran = table[table["compiled"].notna()]
    libs = sorted({str(k)[:12] for k in ran["library"].dropna()})
    compiled = [int(i) for i in ran["id"][ran["compiled"].astype(bool)]]
    cyclic = int(ran["cyclic"].astype(bool).sum())
    lines = [
        f"| kernel libraries (per-agent engine) | {len(libs)} ({', '.join(libs)}); compiled "
        f"for sample(s) {', '.join(map(str, compiled)) or 'none (all from the cache)'} |",
        f"| cyclic graphs among the ok samples | {cyclic} of {len(ran)} |",
    ]
    if "theorem1" in table.columns:
        shown = ran["theorem1"].dropna()
        lines.append(
            f"| Theorem 1 shown on every topology with the paper's z | "
            f"{int(shown.astype(bool).sum())} of {len(shown)} |"
        )
    return lines


def link_lines(ok: pd.DataFrame) -> list[str]:
    """After each graph switch: the (switch, follower) pairs back within the level in time
    (:mod:`verify.link_recovery`), and the peak |u_i| after 1 s against the same sample
    with its switches made no-ops (``[graph.losses] baseline``); no line without switches.

    Parameters
    ----------
    ok : DataFrame
        The ``ok`` rows.
    """
    from verify.operator_steps import RECOVERY_LEVEL, RECOVERY_LIMIT

    pairs = np.nansum(_num(ok, "switch_pairs"))
    if not pairs > 0:
        return []
    late = int(np.nansum(_num(ok, "switch_pairs_late")))
    undefined = int(np.nansum(_num(ok, "switch_pairs_undefined")))
    before = int(np.nansum(_num(ok, "switch_pairs_out_before")))
    slowest = _num(ok, "switch_recovery_s")
    slowest = slowest[~np.isnan(slowest)]
    back, within = int(pairs) - late - undefined, f"{RECOVERY_LIMIT:g} s"
    lines = [
        f"| (graph switch, follower) pairs back within {RECOVERY_LEVEL:g} of the slot within "
        f"{within} | {back} of {int(pairs)} ({late} late; {undefined} undefined: still out "
        f"when the next switch or the horizon came within {within}; {before} already out "
        "before the switch) |",
        f"| slowest return after a switch, where defined [s] | "
        f"{np.max(slowest) if len(slowest) else float('nan'):.4g} |",
    ]
    if "switch_pairs_late_nolosses" in ok.columns:
        late0 = int(np.nansum(_num(ok, "switch_pairs_late_nolosses")))
        undef0 = int(np.nansum(_num(ok, "switch_pairs_undefined_nolosses")))
        lines.append(
            f"| the same pairs in the same samples without losses (switches made no-ops) | "
            f"{int(pairs) - late0 - undef0} of {int(pairs)} back ({late0} late; {undef0} "
            "undefined) |"
        )
    lines += out_lines(ok, int(pairs))
    late_u, base_u = _num(ok, "peak_u_late"), _num(ok, "peak_u_late_nolosses")
    both = np.isfinite(late_u) & np.isfinite(base_u) & (base_u > 0)
    if both.any():
        r = late_u[both] / base_u[both]
        lines.append(
            f"| peak \\|u_i\\| after t = 1 s over the same sample without losses | median "
            f"{np.median(r):.4g}, largest {np.max(r):.4g} (sample {_worst_id(ok, both, r)}); "
            f"{int((r <= 2.0).sum())} of {len(r)} within 2x |"
        )
    return lines


def out_lines(ok: pd.DataFrame, pairs: int) -> list[str]:
    """What keeps the (switch, follower) pairs out that are not back in time
    (:func:`verify.link_recovery.switch_summary`), with and without the losses, and how many
    are out by the sample's N; none for results without the columns.

    Parameters
    ----------
    ok : DataFrame
        The ``ok`` rows.
    pairs : int
        The pairs in all.
    """
    from verify.operator_steps import RECOVERY_LIMIT

    if "switch_out_within" not in ok.columns:
        return []
    out = int(np.nansum(_num(ok, "switch_pairs_late") + _num(ok, "switch_pairs_undefined")))
    n = {k: int(np.nansum(_num(ok, f"switch_out_{k}"))) for k in ("within", "own", "observer")}
    big = {
        k: np.nanmax(_num(ok, f"switch_out_{k}_max"), initial=-np.inf)
        for k in ("worst", "observer", "controller")
    }
    lim = f"{RECOVERY_LIMIT:g} s"
    lines = [
        f"| of the {out} pairs not back in time | {n['within']} within the level for the whole "
        f"{lim} after the switch (above it only later); {n['own']} whose follower's own links "
        f"switched; {n['observer']} with the observer's part ‖C0η_i + b_i − s_i‖ above the "
        f"controller's ‖e_ti‖ at their largest deviation after {lim}: at most "
        f"{big['worst']:.4g} (observer's part up to {big['observer']:.4g}, controller's up "
        f"to {big['controller']:.4g}) |"
    ]
    if "switch_out_within_nolosses" in ok.columns:
        out0 = int(
            np.nansum(
                _num(ok, "switch_pairs_late_nolosses") + _num(ok, "switch_pairs_undefined_nolosses")
            )
        )
        w0 = int(np.nansum(_num(ok, "switch_out_within_nolosses")))
        o0 = int(np.nansum(_num(ok, "switch_out_observer_nolosses")))
        lines.append(
            f"| of the {out0} pairs not back without losses | {w0} within the level for the "
            f"whole {lim}; {o0} with the observer's part above the controller's |"
        )
    if "param:graph.N" in ok.columns:
        N = _num(ok, "param:graph.N")
        per = _num(ok, "switch_pairs_late") + _num(ok, "switch_pairs_undefined")
        lo = int(np.nanmin(N))
        cells = []
        for a in range(lo, int(np.nanmax(N)) + 1, 5):
            m = (N >= a) & (N < a + 5)
            b = min(a + 4, int(np.nanmax(N)))
            cells.append(
                f"N = {a}{f'–{b}' if b > a else ''}: "
                f"{int(np.nansum(per[m]))} of {int(np.nansum(_num(ok, 'switch_pairs')[m]))}"
            )
        lines.append(f"| pairs not back in time by N (of {pairs}) | {'; '.join(cells)} |")
    return lines


def given_link_lines(table: pd.DataFrame) -> list[str]:
    """:func:`link_lines` of the samples' runs with the base scenario's own gains
    (``compare_gains``: the ``given:`` columns of the rows whose ``given:status`` is ok),
    each quantity marked so; none without them.

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    if f"{GIVEN}status" not in table.columns:
        return []
    ran = table[table[f"{GIVEN}status"] == "ok"]
    names = {c: c.removeprefix(GIVEN) for c in ran.columns if c.startswith(GIVEN)}
    params = [c for c in ran.columns if c.startswith("param:")]
    given = ran[["id", *params, *names]].rename(columns=names)
    mark = "| with the base scenario's own gains: "
    return [mark + line.removeprefix("| ") for line in link_lines(given)]


def _worst_id(ok: pd.DataFrame, mask: np.ndarray, ratio: np.ndarray) -> str:
    """The id of the row with the largest ratio."""
    return str(ok["id"].to_numpy()[mask][int(np.argmax(ratio))])


def tail_switched(table: pd.DataFrame) -> np.ndarray:
    """Rows whose tail window holds a topology switch (``tail_switches`` > 0); none for
    rows written before the column existed.

    Parameters
    ----------
    table : DataFrame
        The results.
    """
    return _num(table, "tail_switches") > 0  # NaN (missing) compares False


def tail_split_lines(ok: pd.DataFrame) -> list[str]:
    """The median tail error of the samples whose tail window saw one fixed graph, and of
    those with a link lost or recovered inside it (no lines when no sample switches there).

    Parameters
    ----------
    ok : DataFrame
        The ``ok`` rows.
    """
    switched = tail_switched(ok)
    if not switched.any():
        return []
    err = _num(ok, "tail_max_et")
    lines = []
    for mask, what in [(~switched, "one fixed graph"), (switched, "a topology switch")]:
        vals = err[mask & np.isfinite(err)]
        med = f"{np.median(vals):.4g}" if len(vals) else "-"
        lines.append(
            f"| median tail max \\|e_ti\\|, tail window with {what} ({int(mask.sum())} samples)"
            f" | {med} |"
        )
    return lines


def fault_type_lines(points: pd.DataFrame) -> list[str]:
    """Per fault type: how many faults of the ``ok`` samples, and their samples' median tail error.

    Parameters
    ----------
    points : DataFrame
        From :func:`fault_points`.
    """
    if not len(points):
        return []
    lines = ["| fault type | faults | median tail max \\|e_ti\\| |", "|---|---|---|"]
    for kind, grp in points.groupby("type", sort=True):
        err = grp["tail_max_et"].to_numpy(float)
        err = err[np.isfinite(err)]
        med = f"{np.median(err):.4g}" if len(err) else "-"
        lines.append(f"| {kind} | {len(grp)} | {med} |")
    return lines


def rerun_command(study: str, sample_id: int, name: str, folder: Path) -> str:
    """The command that writes one sample's scenario file and simulates it.

    Parameters
    ----------
    study : str
        The study file, as the run named it.
    sample_id : int
        The sample's id.
    name : str
        The sample's scenario name.
    folder : Path
        The study's output folder; the file goes to its ``samples/``.
    """
    samples = folder / "samples"
    return (
        f"python -m sweep samples {study} --ids {sample_id} --write-scenarios {samples} && "
        f"make sim SCENARIO={samples}/{name}.toml"
    )


def failing_lines(table: pd.DataFrame, study: str, folder: Path) -> list[str]:
    """Samples where a guaranteed check fails (which, and the rerun command), and the
    failed/refused samples with their reasons.

    Parameters
    ----------
    table : DataFrame
        The results.
    study : str
        The study file (for the rerun commands).
    folder : Path
        The study's output folder.
    """
    ok = table[table["status"] == "ok"]
    bad = ok[~ok["guaranteed_held"].astype(bool)]
    lines = ["## Samples where a guaranteed check fails", ""]
    if not len(bad):
        lines.append("None.")
    for r in bad.itertuples(index=False):
        which = getattr(r, "guaranteed_failed", "") or "?"
        lines.append(f"- id {r.id} ({which}): `{rerun_command(study, r.id, r.name, folder)}`")
    lines += ["", "## Samples not run to the end", ""]
    other = table[table["status"] != "ok"]
    if not len(other):
        lines.append("None.")
    for r in other.itertuples(index=False):
        lines.append(f"- id {r.id}: {r.status}" + stop_text(r._asdict()))
    return lines


def stop_text(r: dict) -> str:
    """Where CVODE stood when a sample's run stopped early, against the largest state of
    the output rows before and the last topology switch (:func:`sweep.measures.stop_columns`);
    empty for a row without them.

    Parameters
    ----------
    r : dict
        A results row.
    """
    t_stop = pd.to_numeric(r.get("t_stop"), errors="coerce")
    if t_stop is None or not np.isfinite(t_stop):
        return ""
    switch = pd.to_numeric(r.get("switch_before_stop"), errors="coerce")
    last = (
        "no topology switch before"
        if switch is None or not np.isfinite(switch)
        else f"{(t_stop - switch) * 1e3:.3g} ms after the last topology switch"
    )
    before = f"at most {float(r.get('rows_abs')):.3g} in the output rows before; {last})"
    if f"the largest state is {r.get('stop_state')} = " in str(r.get("status", "")):
        return f" ({before}"  # the error's message named CVODE's last state already
    return (
        f" (stopped at t = {t_stop:.7g} s, the largest state there {r.get('stop_state')} = "
        f"{float(r.get('stop_abs')):.3g} in magnitude, {before}"
    )


def write_report(results: Path, retried: int | None = None) -> Path:
    """Write ``report.md`` and ``figures/`` next to ``results``.

    Parameters
    ----------
    results : Path
        ``out/<study>/results.parquet``; its schema metadata gives the date, the
        command and the study file of the last run that wrote rows.
    retried : int, optional
        Samples recorded as ``failed`` that this run ran again (default: the number in
        the schema metadata, that of the last run that wrote rows).

    Returns
    -------
    Path
        The report.
    """
    import pyarrow.parquet as pq

    info = {k.decode(): v.decode() for k, v in (pq.read_schema(results).metadata or {}).items()}
    command, date = info.get("command", "?"), info.get("date", "?")
    table = pd.read_parquet(results)
    folder = results.parent
    figs = folder / "figures"
    figs.mkdir(exist_ok=True)
    points = fault_points(table)
    lines = [
        f"# Study {folder.name}",
        "",
        f"Results of `{command}` ({date}; commit {info.get('commit', '?')}, "
        f"{info.get('machine', '?')}); {len(table)} rows in `{results.name}`.",
        "",
        _retried_line(info.get("retried", "0") if retried is None else retried),
        "",
        *summary_lines(table),
        "",
        "Theorem 2 entry time: the comparison-lemma time of the provable variant when the "
        "table has it, else Lemma 1's observed reaching time (column `t2_entry_source`).",
        "",
        *fault_type_lines(points),
        "",
        *coverage_lines(table, points),
        "",
        *gains_lines(table),
        "",
        "## Figures",
        "",
        *_figure_lines(table, points, figs),
        "",
        *failing_lines(table, info.get("study", "STUDY"), folder),
    ]
    return atomic_write_text(folder / "report.md", "\n".join(lines) + "\n")


def _retried_line(retried: int | str) -> str:
    """How many samples recorded as ``failed`` this run ran again."""
    return f"Retried in this run: {retried} samples that had failed (refused samples are final)."


def _figure_lines(table: pd.DataFrame, points: pd.DataFrame, figs: Path) -> list[str]:
    """Draw every figure the results allow; one Markdown line each."""
    ok = table[table["status"] == "ok"]
    h1 = _histogram(_num(ok, "tail_max_et"), "tail max |e_ti|", figs / "tail_error.png")
    h2 = _histogram(entry_times(table), "Theorem 2 entry time [s]", figs / "theorem2_entry.png")
    lines = []
    for h, what in ((h1, "tail error"), (h2, "Theorem 2 entry time")):
        lines.append(f"![{what}](figures/{h.name})" if h else f"No finite {what} to draw.")
    for path in fault_figures(points, figs):
        lines.append(f"![{path.stem.replace('_', ' ')}](figures/{path.name})")
    g = graph_figure(table, figs)
    if g is not None:
        lines.append(f"![tail error against N](figures/{g.name})")
    return lines
