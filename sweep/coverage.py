"""What a study's samples guarantee: per-sample coverage columns and the report's coverage lines.

Per sample and follower i (1-based), from the bounds table's rows
(:func:`verify.headline.coverage`, the numbers the headline prints):

- ``t2_rows:<i>``: the follower's guaranteed tracking rows (Theorem 2's provable bound,
  Definition 1's derived bound);
- ``covered:<i>``: the share of the horizon their windows cover;
- ``covered_env:<i>``: the same with the transient envelopes (each interval's bound from
  its start, :data:`verify.claims.ENVELOPE`);
- ``last_covered:<i>``: whether its last interval (after its last restart: health switch,
  operator step, neighbourhood switch) has a guaranteed Theorem 2 row and a guaranteed
  Definition 1 row (at the ultimate level or the envelope), both reaching the horizon;

and ``coverage`` (mean of ``covered:<i>``) and ``followers_covered`` (how many
``last_covered:<i>``).
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pandas as pd

#: the per-follower coverage columns, by prefix
PREFIXES = ("t2_rows:", "covered:", "covered_env:", "last_covered:")


def _last_covered(rows: pd.DataFrame, t1: float) -> bool:
    """A guaranteed Theorem 2 row and a guaranteed Definition 1 row among one follower's
    ``rows`` reach ``t1``."""
    from verify import claims as CL

    rows = rows[
        (rows["kind"] == CL.Kind.GUARANTEED.value)
        & (np.abs(rows["t_end"].astype(float) - t1) <= 1e-9 * max(1.0, abs(t1)))
    ]
    ids = set(rows["claim_id"])
    t2 = bool(ids & {CL.T2_CHI.id, CL.T2_CHI_ENV.id})
    return t2 and bool(ids & {CL.DEF1_DERIVED.id, CL.DEF1_ENV.id})


def coverage_columns(table: pd.DataFrame) -> dict[str, Any]:
    """The sample's coverage columns (module docstring).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table (:func:`verify.table.bounds_table`).
    """
    from verify.headline import by_agent, coverage

    if not len(table) or "t_start" not in table:
        return {"coverage": math.nan, "followers_covered": 0}
    t0 = float(np.nanmin(table["t_start"].astype(float)))
    t1 = float(np.nanmax(table["t_end"].astype(float)))
    out: dict[str, Any] = {}
    covered, last = [], 0
    groups = by_agent(table)
    for c in coverage(table, (t0, t1)):
        ok = _last_covered(groups[str(c.agent)], t1)
        out[f"t2_rows:{c.agent}"] = c.tracking
        out[f"covered:{c.agent}"] = c.covered
        out[f"covered_env:{c.agent}"] = c.covered_any
        out[f"last_covered:{c.agent}"] = ok
        covered.append(c.covered)
        last += int(ok)
    out["coverage"] = float(np.mean(covered)) if covered else math.nan
    out["followers_covered"] = last
    return out


def _followers(table: pd.DataFrame) -> list[int]:
    return sorted(
        int(m.group(1)) for c in table.columns if (m := re.fullmatch(r"last_covered:(\d+)", c))
    )


def coverage_lines(table: pd.DataFrame, points: pd.DataFrame) -> list[str]:
    """Markdown: follower-samples covered on their last interval, overall and by fault type.

    Parameters
    ----------
    table : DataFrame
        The study's results.
    points : DataFrame
        :func:`sweep.report.fault_points` (the fault type of each sample).
    """
    ok = table[table["status"] == "ok"]
    agents = _followers(ok)
    if not len(ok) or not agents:
        return []
    last = ok[[f"last_covered:{a}" for a in agents]].astype(bool).to_numpy()
    cov = ok[[f"covered:{a}" for a in agents]].astype(float).to_numpy()
    env_cols = [f"covered_env:{a}" for a in agents]
    env = ok[env_cols].astype(float).to_numpy() if all(c in ok for c in env_cols) else cov
    held = ok["guaranteed_held"].astype(bool).to_numpy()
    lines = [
        "Coverage: a follower-sample is covered when its last interval (after its last health "
        "switch, operator step or neighbourhood switch) has guaranteed Theorem 2 and "
        "Definition 1 rows (at the ultimate level, or the envelope from the interval's start); "
        "the fractions of the horizon are those inside the windows of its guaranteed rows at "
        "the ultimate level, and with the envelopes.",
        "",
        "| samples | all guaranteed rows held | follower-samples covered | mean fraction of "
        "the horizon at the ultimate level | with the envelopes |",
        "|---|---|---|---|---|",
        _line("all", held, last, cov, env),
    ]
    if len(points):
        kind = points.drop_duplicates("id").set_index("id")["type"]
        types = ok["id"].map(kind)
        for t in sorted(types.dropna().unique()):
            sel = (types == t).to_numpy()
            lines.append(_line(str(t), held[sel], last[sel], cov[sel], env[sel]))
    return lines


def _line(label: str, held: np.ndarray, last: np.ndarray, cov: np.ndarray, env: np.ndarray) -> str:
    n = last.size
    share = 100.0 * last.sum() / n if n else math.nan
    return (
        f"| {label} ({len(held)}) | {int(held.sum())} of {len(held)} | {int(last.sum())} of "
        f"{n} ({share:.1f}%) | {100 * float(np.nanmean(cov)):.1f}% | "
        f"{100 * float(np.nanmean(env)):.1f}% |"
    )
