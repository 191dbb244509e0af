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
- ``ultimate_from:<i>``: the time from which it is covered at the ultimate level on its
  last interval (:func:`verify.headline.ultimate_from`: its guaranteed ultimate-level
  tracking rows reach the horizon and all hold), NaN when it is not;

and ``coverage`` (mean of ``covered:<i>``), ``followers_covered`` (how many
``last_covered:<i>``) and ``followers_ultimate`` (how many finite ``ultimate_from:<i>``).
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pandas as pd

#: the per-follower coverage columns, by prefix
PREFIXES = ("t2_rows:", "covered:", "covered_env:", "last_covered:", "ultimate_from:")


def _last_covered(cols: Any, agent: int, t1: float) -> bool:
    """A guaranteed Theorem 2 row and a guaranteed Definition 1 row among follower
    ``agent``'s rows (of :class:`verify.headline.TableColumns` ``cols``) reach ``t1``."""
    from verify import claims as CL

    ids = set(cols.claim_id[cols.rows(agent) & cols.guaranteed & cols.ending_at(t1)])
    t2 = bool(ids & {CL.T2_CHI.id, CL.T2_CHI_ENV.id})
    return t2 and bool(ids & {CL.DEF1_DERIVED.id, CL.DEF1_ENV.id})


def coverage_columns(table: pd.DataFrame) -> dict[str, Any]:
    """The sample's coverage columns (module docstring).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table (:func:`verify.table.bounds_table`).
    """
    from verify.headline import TableColumns, coverage, ultimate_from

    if not len(table) or "t_start" not in table:
        return {"coverage": math.nan, "followers_covered": 0, "followers_ultimate": 0}
    t0 = float(np.nanmin(table["t_start"].astype(float)))
    t1 = float(np.nanmax(table["t_end"].astype(float)))
    out: dict[str, Any] = {}
    covered, last, ultimate = [], 0, 0
    cols = TableColumns.of(table)  # read once: every follower's rows are masks of it
    for c in coverage(table, (t0, t1), gaps=False, columns=cols):
        ok = _last_covered(cols, c.agent, t1)
        since = ultimate_from(cols, c.agent, t1)
        out[f"t2_rows:{c.agent}"] = c.tracking
        out[f"covered:{c.agent}"] = c.covered
        out[f"covered_env:{c.agent}"] = c.covered_any
        out[f"last_covered:{c.agent}"] = ok
        out[f"ultimate_from:{c.agent}"] = since
        covered.append(c.covered)
        last += int(ok)
        ultimate += int(math.isfinite(since))
    out["coverage"] = float(np.mean(covered)) if covered else math.nan
    out["followers_covered"] = last
    out["followers_ultimate"] = ultimate
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


#: the prefix of the columns of the run with the base's own gains (``compare_gains``)
GIVEN = "given:"


def gains_summary(table: pd.DataFrame, prefix: str = "") -> dict[str, Any]:
    """What one gain set guarantees over a study's samples (the columns under ``prefix``).

    Parameters
    ----------
    table : DataFrame
        The study's results.
    prefix : str
        ``""`` for the sample's own run, :data:`GIVEN` for its run with the base's gains.

    Returns
    -------
    dict
        ``samples``, ``ok`` (runs to the end), ``held`` (ok samples whose guaranteed rows
        all hold), ``coverage_mean`` and ``coverage_min`` (the ultimate level's share of
        follower-time, over the ok samples), ``follower_samples`` and ``ultimate`` (those
        covered at the ultimate level on their last interval), ``all_ultimate`` (ok samples
        with every follower so covered), ``from_median`` and ``from_max`` (the median and
        latest time from which a covered follower-sample is covered).
    """
    status = table.get(f"{prefix}status", pd.Series([], dtype=object)).astype(str)
    ok = table[(status == "ok").to_numpy()]
    agents = sorted(
        int(m.group(1))
        for c in table.columns
        if (m := re.fullmatch(re.escape(prefix) + r"ultimate_from:(\d+)", c))
    )
    since = ok[[f"{prefix}ultimate_from:{a}" for a in agents]].astype(float).to_numpy()
    covered = np.isfinite(since)
    cov = ok[f"{prefix}coverage"].astype(float).to_numpy() if len(ok) else np.array([])
    return {
        "samples": len(table),
        "ok": len(ok),
        "held": int(ok[f"{prefix}guaranteed_held"].astype(bool).sum()) if len(ok) else 0,
        "coverage_mean": float(np.nanmean(cov)) if cov.size else math.nan,
        "coverage_min": float(np.nanmin(cov)) if cov.size else math.nan,
        "follower_samples": int(covered.size),
        "ultimate": int(covered.sum()),
        "all_ultimate": int(covered.all(axis=1).sum()) if covered.size else 0,
        "from_median": float(np.median(since[covered])) if covered.any() else math.nan,
        "from_max": float(np.max(since[covered])) if covered.any() else math.nan,
    }


def gains_lines(table: pd.DataFrame) -> list[str]:
    """Markdown: per gain set, samples ok, guaranteed rows held, coverage at the ultimate
    level (mean, lowest sample) and the follower-samples covered at the ultimate level on
    their last interval; with ``compare_gains``, the base's own gains on a second line.

    Parameters
    ----------
    table : DataFrame
        The study's results.
    """
    if not any(c.startswith("ultimate_from:") for c in table.columns):
        return []
    given = f"{GIVEN}status" in table.columns
    sets = [("designed (the base's design.json)" if given else "the study's", "")]
    if given:
        sets.append(("given (the base scenario's own)", GIVEN))
    lines = [
        "## Guarantees per gain set",
        "",
        "A follower is covered at the ultimate level on its last interval when its guaranteed "
        "Theorem 2 (provable variant) and Definition 1 (derived bound) rows of the interval "
        "after its last restart reach the horizon and every guaranteed tracking row there "
        "holds (docs/verification.md, 'Coverage'), from the time given (median and latest "
        "over the covered follower-samples: a last interval opened shortly before the "
        "horizon, e.g. by an intermittent fault, is covered from late on). Coverage: the "
        "share of follower-time inside the windows of guaranteed rows at the ultimate level.",
        "",
        "| gains | samples ok | all guaranteed rows held | coverage at the ultimate level: "
        "mean | lowest sample | follower-samples covered on their last interval | samples "
        "with every follower covered | covered from [s]: median | latest |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, prefix in sets:
        s = gains_summary(table, prefix)
        share = 100.0 * s["ultimate"] / s["follower_samples"] if s["follower_samples"] else 0.0
        lines.append(
            f"| {label} | {s['ok']} of {s['samples']} | {s['held']} of {s['ok']} | "
            f"{100 * s['coverage_mean']:.1f}% | {100 * s['coverage_min']:.1f}% | "
            f"{s['ultimate']} of {s['follower_samples']} ({share:.1f}%) | "
            f"{s['all_ultimate']} of {s['ok']} | {s['from_median']:.3g} | {s['from_max']:.4g} |"
        )
    return lines
