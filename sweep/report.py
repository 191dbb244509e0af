"""``out/<study>/report.md`` and its figures from a study's ``results.parquet``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from core.artifacts import atomic_write_text

#: (column, label) of the medians in the summary table
MEDIANS = [
    ("tail_max_et", "tail max |e_ti| (max over followers)"),
    ("formation_tail_max", "formation error, tail sup (max over followers)"),
    ("observer_tail_max", "observer |ebar_eta_i|, tail sup (max over followers)"),
    ("peak_u_max", "peak |u_i| (max over followers)"),
    ("steps", "integrator steps"),
    ("wall_s", "wall time per sample [s]"),
]


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


def _histogram(values: np.ndarray, xlabel: str, path: Path) -> Path | None:
    """A histogram written to ``path`` (None when there is nothing finite to draw)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    values = values[np.isfinite(values)]
    if not len(values):
        return None
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.hist(values, bins=min(30, max(5, len(values) // 2)))
    ax.set_xlabel(xlabel)
    ax.set_ylabel("samples")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


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
        vals = pd.to_numeric(ok[col], errors="coerce").to_numpy(float)
        vals = vals[np.isfinite(vals)]
        lines.append(
            f"| median {label} | {np.median(vals):.4g} |"
            if len(vals)
            else f"| median {label} | - |"
        )
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


def failing_lines(table: pd.DataFrame, samples_dir: str) -> list[str]:
    """Samples where a guaranteed check fails, and failed/refused samples, with rerun commands.

    Parameters
    ----------
    table : DataFrame
        The results.
    samples_dir : str
        The folder of the sample scenario files, as written in the commands.
    """
    ok = table[table["status"] == "ok"]
    bad = ok[~ok["guaranteed_held"].astype(bool)]
    lines = ["## Samples where a guaranteed check fails", ""]
    if not len(bad):
        lines.append("None.")
    for r in bad.itertuples(index=False):
        lines.append(f"- id {r.id}: `make sim SCENARIO={samples_dir}/{r.name}.toml`")
    lines += ["", "## Samples not run to the end", ""]
    other = table[table["status"] != "ok"]
    if not len(other):
        lines.append("None.")
    for r in other.itertuples(index=False):
        lines.append(f"- id {r.id}: {r.status}")
    return lines


def write_report(results: Path) -> Path:
    """Write ``report.md`` and ``figures/`` next to ``results``.

    Parameters
    ----------
    results : Path
        ``out/<study>/results.parquet``; its schema metadata gives the date and the
        command of the last run that wrote rows.

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
    ok = table[table["status"] == "ok"]
    tail = pd.to_numeric(ok["tail_max_et"], errors="coerce").to_numpy(float)
    h1 = _histogram(tail, "tail max |e_ti|", figs / "tail_error.png")
    h2 = _histogram(entry_times(table), "Theorem 2 entry time [s]", figs / "theorem2_entry.png")
    lines = [
        f"# Study {folder.name}",
        "",
        f"Results of `{command}` ({date}); {len(table)} rows in `{results.name}`.",
        "",
        *summary_lines(table),
        "",
        "Theorem 2 entry time: the comparison-lemma time of the provable variant when the "
        "table has it, else Lemma 1's observed reaching time (column `t2_entry_source`).",
        "",
        "## Figures",
        "",
    ]
    for h, what in ((h1, "tail error"), (h2, "Theorem 2 entry time")):
        lines.append(f"![{what}](figures/{h.name})" if h else f"No finite {what} to draw.")
    lines += ["", *failing_lines(table, str(folder / "samples"))]
    return atomic_write_text(folder / "report.md", "\n".join(lines) + "\n")
