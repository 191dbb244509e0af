"""``out/<name>/report.md`` of a search and its plot (docs/search.md, 'Report').

A falsified guaranteed row comes first, as a defect of the code or of the bound's
derivation, with its minimised reproduction; then the robustness of the search against
the baseline (``figures/robustness.png``: the least robustness found so far against the
evaluation index, per arm), the least robust run and its minimised version.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from core.artifacts import atomic_write_text
from core.provenance import provenance_line
from search.evaluate import UNSCORED
from search.minimise import MINIMISED, STATE, WORST, least_robust
from search.spec import SearchFile
from sweep.run import read_results

FIGURE = "figures/robustness.png"


def best_so_far(table: pd.DataFrame, arm: str) -> pd.Series:
    """The running minimum of robustness over the arm's evaluations (by index; a row
    that is not ``ok`` leaves it unchanged).

    Parameters
    ----------
    table : DataFrame
        results.parquet.
    arm : str
        ``search`` or ``baseline``.
    """
    rows = table[table["arm"] == arm].sort_values("eval")
    rob = rows["robustness"].astype(float).where(rows["status"] == "ok")
    return pd.Series(rob.fillna(math.inf).cummin().to_numpy(), index=rows["eval"].to_numpy())


def plot(table: pd.DataFrame, path: Path) -> Path:
    """Least robustness so far against evaluations, search and baseline.

    Parameters
    ----------
    table : DataFrame
        results.parquet.
    path : Path
        The PNG written.
    """
    from core.pyplot import pyplot

    plt = pyplot()

    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    drawn = False
    for arm, style in (("search", "-"), ("baseline", "--")):
        s = best_so_far(table, arm)
        s = s[np.isfinite(s.to_numpy())]  # before the arm's first scored run: nothing to draw
        if len(s):
            ax.step(s.index + 1, s.to_numpy(), style, where="post", label=arm)
            drawn = True
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("evaluations")
    ax.set_ylabel("least robustness so far")
    if drawn:
        ax.set_xscale("log")
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no scored run", ha="center", transform=ax.transAxes)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_report(search: SearchFile, results: Path) -> Path:
    """Write report.md and the figure next to ``results``.

    Parameters
    ----------
    search : SearchFile
        The search.
    results : Path
        results.parquet.
    """
    folder = results.parent
    table = read_results(results)
    table = table[table["arm"].notna()] if "arm" in table.columns else table
    plot(table, folder / FIGURE)
    worst = least_robust(table)
    state = json.loads((folder / STATE).read_text()) if (folder / STATE).is_file() else None
    lines = [f"# Search {search.name}", "", provenance_line(), ""]
    lines += _defect(search, worst, state, folder)
    lines += _summary(search, table)
    lines += _unscored(table)
    lines += ["", f"![least robustness so far]({FIGURE})", ""]
    lines += _worst(search, worst, state, folder)
    return atomic_write_text(folder / "report.md", "\n".join(lines) + "\n")


def _defect(search: SearchFile, worst, state, folder: Path) -> list[str]:
    """The falsified guaranteed row, first."""
    guaranteed = [r.name for r in search.requirements if r.guaranteed]
    if worst is None or not guaranteed:
        return []
    falsified = [n for n in guaranteed if float(worst[f"rob:{n}"]) < 0]
    if not falsified:
        return []
    n = falsified[0]
    out = [
        "## DEFECT: a guaranteed row is falsified",
        "",
        f"The run `{worst['name']}` violates the guaranteed row "
        f"**{worst[f'worst_row:{n}']}** (requirement `{n}`, scaled robustness "
        f"{float(worst[f'rob:{n}']):.4g}). A guaranteed row is a theorem's bound: its "
        "failure is a defect of the code or of the bound's derivation, not of the scenario.",
        "",
    ]
    if state is not None and state["requirement"] == n:
        out += _reproduction(folder, state)
    return out


def _reproduction(folder: Path, state: dict) -> list[str]:
    kept = ", ".join(f"`{k}` = {state['values'][k]!r}" for k in state["changed"]) or "none"
    dropped = ", ".join(f"`{g}`" for g in state["dropped"]) or "none"
    return [
        f"Minimised reproduction (`{folder / MINIMISED}`, robustness "
        f"{state['robustness']:.4g} after {state['steps']} evaluations): values that "
        f"differ from the base: {kept}; groups reverted to the base: {dropped}.",
        "",
        f"    make verify SCENARIO={folder / MINIMISED}",
        "",
    ]


def _summary(search: SearchFile, table: pd.DataFrame) -> list[str]:
    s = search.settings
    out = [
        "## Search against uniform random search",
        "",
        f"Budget {s.budget} CMA-ES evaluations and {s.baseline} uniform random ones in the "
        "same run. Robustness is the least over the requirements, each divided by its scale;"
        " negative is violated.",
        "",
        "| arm | evaluations | ok | least robustness | violating runs |",
        "|---|---|---|---|---|",
    ]
    for arm in ("search", "baseline", "minimise"):
        rows = table[table["arm"] == arm] if len(table) else table
        ok = rows[rows["status"] == "ok"]
        rob = ok["robustness"].astype(float)
        least = f"{rob.min():.4g}" if len(rob) else "-"
        out.append(f"| {arm} | {len(rows)} | {len(ok)} | {least} | {int((rob < 0).sum())} |")
    out += [
        "",
        "| requirement | formula | least (search) | least (baseline) |",
        "|---|---|---|---|",
    ]
    for r in search.requirements:
        col = f"rob:{r.name}"
        vals = []
        for arm in ("search", "baseline"):
            ok = table[(table["arm"] == arm) & (table["status"] == "ok")] if len(table) else table
            vals.append(f"{ok[col].astype(float).min():.4g}" if len(ok) and col in ok else "-")
        what = "every guaranteed row: observed <= bound" if r.guaranteed else f"`{r.formula}`"
        out.append(f"| {r.name} | {what} | {vals[0]} | {vals[1]} |")
    return out


def _unscored(table: pd.DataFrame) -> list[str]:
    """The runs a requirement could not score (``unscored: ...``, search.evaluate.unscored)."""
    if not len(table) or "status" not in table.columns:
        return []
    status = table["status"].astype(str)
    counts = status[status.str.startswith(f"{UNSCORED}:")].value_counts()
    if not len(counts):
        return []
    out = [
        "",
        "## Runs a requirement cannot score",
        "",
        "Their robustness is infinite or not a number, which ranks nothing: they are not "
        "told to CMA-ES and never the least robust run. Give every window a start within "
        "the horizon, and guaranteed-rows requirements claims with guaranteed rows.",
        "",
        "| runs | why |",
        "|---|---|",
    ]
    out += [f"| {n} | {why.removeprefix(UNSCORED + ': ')} |" for why, n in counts.items()]
    return out


def _worst(search: SearchFile, worst, state, folder: Path) -> list[str]:
    if worst is None:
        return ["No evaluation finished."]
    out = [
        "## Least robust run",
        "",
        f"`{worst['name']}` ({worst['arm']}, evaluation {int(worst['eval'])}), robustness "
        f"{float(worst['robustness']):.4g}:",
        "",
        *(f"- `{r.name}`: {float(worst[f'rob:{r.name}']):.4g}" for r in search.requirements),
        "",
        f"    make sim SCENARIO={folder / WORST} && make verify SCENARIO={folder / WORST}",
        "",
    ]
    if state is not None:
        out += [f"### Minimised (requirement `{state['requirement']}`)", ""]
        out += _reproduction(folder, state)
    elif float(worst["robustness"]) >= 0:
        out += ["No run violates a requirement: nothing to minimise.", ""]
    return out
