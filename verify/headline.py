"""The headline of a verification: per follower what is guaranteed and what is not, and the
three numbers a user looks at first.

Everything here is computed from the bound-vs-actual table (and the trajectory for the
three numbers), so the headline, the report and the study's rows say the same thing:

- per follower: guaranteed rows held / total, the share of the horizon its guaranteed
  tracking rows (Theorem 2's provable bound and Definition 1's derived bound,
  :data:`verify.claims.TRACKING`) cover, and every interval they do not cover with why;
- for the run: the coverage over followers, the worst formation deviation
  ‖p_i − h_i y0 − b_i‖ and the worst tracking error ‖e_ti‖ on the tail window (after the
  transient), and the peak ‖u_i‖ after t = 1 s, each with its follower and time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from verify import claims as CL
from verify import signals as S
from verify.intervals import covered_fraction
from verify.rows import failed_mask, held_mask


@dataclass(frozen=True)
class FollowerCoverage:
    """What the table guarantees for one follower.

    Attributes
    ----------
    agent : int
        1-based follower.
    held, total : int
        Guaranteed rows that hold, and all guaranteed rows (evaluated ones).
    tracking : int
        Guaranteed tracking rows (:data:`verify.claims.TRACKING`).
    covered : float
        Share of the horizon inside the windows of its guaranteed tracking rows.
    envelope : int
        Guaranteed envelope rows (:data:`verify.claims.ENVELOPE`: the transient of each
        interval, bounded from its start).
    covered_any : float
        Share of the horizon inside the windows of its guaranteed tracking or envelope rows.
    gaps : tuple of str
        ``"[a, b] s: why"`` for each interval no guaranteed tracking row covers.
    """

    agent: int
    held: int
    total: int
    tracking: int
    covered: float
    envelope: int = 0
    covered_any: float = 0.0
    gaps: tuple[str, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class TableColumns:
    """The bound-vs-actual table's columns the coverage reads, as numpy arrays read once
    (a follower's rows are a boolean mask, not a filtered DataFrame: a study's sample
    asks for every follower's rows several times).

    Attributes
    ----------
    agent : ndarray of str
        ``agent`` as text (``"1"``, ...), as :func:`by_agent` keys it.
    guaranteed, tracking, envelope : ndarray of bool
        The row is of kind ``guaranteed``; its claim is in :data:`verify.claims.TRACKING`;
        in :data:`verify.claims.ENVELOPE`.
    claim_id : ndarray of str
    t_start, t_end : ndarray of float
    held : ndarray of bool
        :func:`verify.rows.held_mask`.
    """

    agent: np.ndarray
    guaranteed: np.ndarray
    tracking: np.ndarray
    envelope: np.ndarray
    claim_id: np.ndarray
    t_start: np.ndarray
    t_end: np.ndarray
    held: np.ndarray

    @classmethod
    def of(cls, table: pd.DataFrame) -> TableColumns:
        """The columns of ``table``.

        Parameters
        ----------
        table : DataFrame
            The bound-vs-actual table.
        """
        claim = table["claim_id"].to_numpy(dtype=object)
        return cls(
            agent=table["agent"].astype(str).to_numpy(dtype=object),
            guaranteed=(table["kind"] == CL.Kind.GUARANTEED.value).to_numpy(dtype=bool),
            tracking=np.array([c in CL.TRACKING for c in claim], dtype=bool),
            envelope=np.array([c in CL.ENVELOPE for c in claim], dtype=bool),
            claim_id=claim,
            t_start=table["t_start"].astype(float).to_numpy(),
            t_end=table["t_end"].astype(float).to_numpy(),
            held=held_mask(table).to_numpy(dtype=bool),
        )

    def agents(self) -> list[int]:
        """The followers with rows (1-based), in order."""
        return sorted(int(a) for a in dict.fromkeys(self.agent) if a.isdigit())

    def rows(self, agent: int) -> np.ndarray:
        """Follower ``agent``'s rows (1-based), a boolean mask.

        Parameters
        ----------
        agent : int
        """
        return self.agent == str(agent)

    def windows(self, mask: np.ndarray) -> list[tuple[float, float]]:
        """The finite windows of the rows of ``mask``, in the table's order.

        Parameters
        ----------
        mask : ndarray of bool
        """
        return [
            (float(x), float(y))
            for x, y in zip(self.t_start[mask], self.t_end[mask], strict=True)
            if math.isfinite(x) and math.isfinite(y)
        ]

    def ending_at(self, t1: float) -> np.ndarray:
        """The rows whose window ends at ``t1`` (to 1e-9 of max(1, |t1|)).

        Parameters
        ----------
        t1 : float
        """
        return np.abs(self.t_end - t1) <= 1e-9 * max(1.0, abs(t1))


def by_agent(table: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The table's rows per follower (``agent`` as text: ``"1"``, ...), split once.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    """
    key = table["agent"].astype(str)
    return {str(a): rows for a, rows in table.groupby(key, sort=False)}


def _fraction(wins: list[tuple[float, float]], t0: float, t1: float) -> float:
    """Share of [t0, t1] inside the windows."""
    if t1 <= t0:
        return 0.0
    return covered_fraction([(x - t0, y - t0) for x, y in wins], t1 - t0)


def _step(table: pd.DataFrame) -> float:
    """The output step, from the table's windows (0 when unknown)."""
    d = np.diff(np.unique(np.concatenate([table["t_start"], table["t_end"]]).astype(float)))
    d = d[np.isfinite(d) & (d > 1e-12)]
    return float(d.min()) if d.size else 0.0


def _gaps(
    rows: pd.DataFrame, covered: list[tuple[float, float]], t0: float, t1: float, step: float
) -> list[str]:
    """Uncovered parts of [t0, t1], each with the reason of a row stated on it (one output
    step between two windows is the grid at a restart, not a gap)."""
    out, at = [], t0
    pieces = sorted(covered)
    chi: list | None = None  # the Theorem 2 rows, read once when a gap needs them
    for a, b in [*pieces, (t1, t1)]:
        if a > at + 1.5 * step + 1e-9 or (at == t0 and a > at + 1e-9):
            if chi is None:
                chi = list(rows[rows["claim_id"] == CL.T2_CHI.id].itertuples(index=False))
            out.append(f"[{at:.4g}, {a:.4g}] s: {_why(chi, at, a)}")
        at = max(at, b)
    return out


def _why(chi: list, a: float, b: float) -> str:
    """Why no guaranteed tracking row covers [a, b]: the note of a Theorem 2 row (of the
    follower's ``chi`` rows) stated there that is not guaranteed, else the transient before
    the comparison-lemma time."""
    if not chi:
        return "no provable variant for this ghat law (options.ghat_law)"
    for r in chi:
        if r.kind == CL.Kind.GUARANTEED.value or not (r.t_start <= b and r.t_end >= a):
            continue
        note = str(r.note)
        for cut in ("not evaluated: ", "not guaranteed: ", "invalidated"):
            if cut in note:
                return note.split(cut, 1)[1] if cut != "invalidated" else note
        return f"{r.kind} row: {note}"
    return "transient: before the comparison-lemma time"


def coverage(
    table: pd.DataFrame,
    horizon: tuple[float, float],
    gaps: bool = True,
    columns: TableColumns | None = None,
) -> list[FollowerCoverage]:
    """Per follower, what the guaranteed rows cover (module docstring).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    horizon : (float, float)
        First and last output time.
    gaps : bool
        Also say why each uncovered interval is (default); False leaves
        :attr:`FollowerCoverage.gaps` empty.
    columns : TableColumns, optional
        ``TableColumns.of(table)``, when the caller has it.
    """
    t0, t1 = horizon
    cols = TableColumns.of(table) if columns is None else columns
    groups = by_agent(table) if gaps else {}
    step = _step(table) if gaps else 0.0
    out = []
    for a in cols.agents():
        g = cols.rows(a) & cols.guaranteed
        track, env = g & cols.tracking, g & cols.envelope
        wins, wenv = cols.windows(track), cols.windows(env)
        out.append(
            FollowerCoverage(
                agent=a,
                held=int((cols.held & g).sum()),
                total=int(g.sum()),
                tracking=int(track.sum()),
                covered=_fraction(wins, t0, t1),
                envelope=int(env.sum()),
                covered_any=_fraction(wins + wenv, t0, t1),
                gaps=tuple(_gaps(groups[str(a)], wins, t0, t1, step)) if gaps else (),
            )
        )
    return out


#: the ultimate-level rows a follower's last interval must have (both: its tracking error
#: through ‖χ_i‖ and its formation deviation)
ULTIMATE_NEEDED = (CL.T2_CHI.id, CL.DEF1_DERIVED.id)


def ultimate_from(table: pd.DataFrame | TableColumns, agent: int, t1: float) -> float:
    """The time from which follower ``agent`` is covered at the ultimate level on its last
    interval, up to the horizon ``t1``; NaN when it is not (docs/verification.md,
    'Coverage').

    The last interval's rows are those whose window ends at ``t1`` (every earlier
    interval's window ends before the next restart). It is covered when its guaranteed
    ultimate-level tracking rows (:data:`verify.claims.TRACKING`) include Theorem 2's
    provable ‖χ_i‖ ≤ χ̄_i and Definition 1's derived bound, and every one of them was
    evaluated and holds; the time is the latest start of their windows (the first output
    time after the comparison-lemma time t_c).

    Parameters
    ----------
    table : DataFrame or TableColumns
        The bound-vs-actual table (or its :class:`TableColumns`).
    agent : int
        1-based follower.
    t1 : float
        The last output time.
    """
    c = table if isinstance(table, TableColumns) else TableColumns.of(table)
    last = c.rows(agent) & c.guaranteed & c.tracking & c.ending_at(t1)
    if not set(ULTIMATE_NEEDED) <= set(c.claim_id[last]) or not c.held[last].all():
        return math.nan
    start = c.t_start[last]
    start = start[~np.isnan(start)]  # pandas' max skips NaN
    return float(start.max()) if start.size else math.nan


@dataclass(frozen=True)
class Worst:
    """A largest value with where and when it occurs."""

    what: str
    value: float
    agent: int
    t: float
    window: tuple[float, float]

    def text(self) -> str:
        """``'worst tracking error |e_ti| on [10, 20] s: 0.0041 (follower 2, t = 10 s)'``."""
        a, b = self.window
        if not math.isfinite(self.value):
            return f"{self.what} on [{a:.4g}, {b:.4g}] s: not available"
        return (
            f"{self.what} on [{a:.4g}, {b:.4g}] s: {self.value:.4g} "
            f"(follower {self.agent}, t = {self.t:.4g} s)"
        )


def _worst(what: str, t: np.ndarray, mask: np.ndarray, per_agent: list[np.ndarray]) -> Worst:
    best = Worst(what, math.nan, 0, math.nan, (float(t[mask][0]), float(t[-1])))
    for i, x in enumerate(per_agent):
        x = np.where(mask & np.isfinite(x), x, -np.inf)
        k = int(np.argmax(x))
        if np.isfinite(x[k]) and not (x[k] <= best.value):
            best = Worst(what, float(x[k]), i + 1, float(t[k]), best.window)
    return best


def run_numbers(
    scenario, df: S.FrameOrView, h: np.ndarray, tail_fraction: float, startup: float
) -> list[Worst]:  # noqa: ANN001
    """The three numbers: worst formation deviation and tracking error on the tail, peak ‖u_i‖
    after ``startup``.

    Parameters
    ----------
    scenario : Scenario
        Its leader's C0.
    df : DataFrame
        The trajectory.
    h : ndarray
        The gauge h_i.
    tail_fraction : float
        The tail window (after the transient).
    startup : float
        Peak effort is taken from this time on (s).
    """
    view = S.TrajectoryView.of(df)
    dm = view.dims
    t = view.t
    tail = S.tail_mask(t, tail_fraction)
    y0 = view.leader_output(scenario.leader.C0)
    dev, et, un = [], [], []
    for i in range(dm.N):
        p, b = view.block(S.Signal.P, i + 1), view.block(S.Signal.B, i + 1)
        dev.append(np.linalg.norm(p - h[i] * y0 - b, axis=1))
        et.append(view.norm(S.Signal.ET, i + 1))
        un.append(
            view.norm(S.Signal.U, i + 1) if view.has(S.Signal.U, i + 1) else np.full(len(t), np.nan)
        )
    late = t >= startup
    effort = f"peak |u_i| after t = {startup:g} s"
    if not late.any():  # a horizon shorter than the start-up: the whole run, said so
        late = np.ones_like(t, bool)
        effort = f"peak |u_i| over the run (horizon shorter than {startup:g} s)"
    return [
        _worst("worst formation deviation |p_i - h_i y0 - b_i|", t, tail, dev),
        _worst("worst tracking error |e_ti|", t, tail, et),
        _worst(effort, t, late, un),
    ]


def verdict(table: pd.DataFrame, cov: list[FollowerCoverage], strict: bool = False) -> str:
    """One line: PASS only with a guaranteed tracking row for every follower, else says what
    is missing; FAIL with the number of failed rows.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    cov : list of FollowerCoverage
        :func:`coverage` of the table.
    strict : bool
        Also count the paper's claims.
    """
    kinds = [*CL.BUG_KINDS, CL.Kind.PAPER.value] if strict else list(CL.BUG_KINDS)
    bad = int((table["kind"].isin(kinds) & failed_mask(table)).sum())
    g = table[table["kind"] == CL.Kind.GUARANTEED.value]
    held, total = int(held_mask(g).sum()), len(g)
    if bad:
        return f"FAIL: {bad} check(s) failed ({held} of {total} guaranteed rows hold)"
    bare = [c.agent for c in cov if c.tracking == 0]
    mean = float(np.mean([c.covered for c in cov])) if cov else 0.0
    env = float(np.mean([c.covered_any for c in cov])) if cov else 0.0
    cover = (
        f"covering {100 * mean:.0f}% of follower-time at the ultimate level, "
        f"{100 * env:.0f}% with the transient envelopes"
    )
    if bare:
        who = ", ".join(map(str, bare))
        return (
            f"PASS WITH GAPS: all {total} guaranteed rows hold, but follower(s) {who} have no "
            f"guaranteed tracking row; {cover}"
        )
    return (
        f"PASS: all {total} guaranteed rows hold; every follower has guaranteed tracking "
        f"rows, {cover}"
    )


def headline_lines(table: pd.DataFrame, numbers: list[Worst], strict: bool = False) -> list[str]:
    """The verdict, one line per follower, and the three numbers.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    numbers : list of Worst
        :func:`run_numbers`.
    strict : bool
        Also count the paper's claims.
    """
    t0 = float(np.nanmin(table["t_start"])) if len(table) else 0.0
    t1 = float(np.nanmax(table["t_end"])) if len(table) else 0.0
    cov = coverage(table, (t0, t1))
    lines = [verdict(table, cov, strict)]
    for c in cov:
        line = (
            f"  follower {c.agent}: {c.held} of {c.total} guaranteed rows hold; tracking rows "
            f"at the ultimate level ({c.tracking}) cover {100 * c.covered:.0f}% of "
            f"[{t0:g}, {t1:g}] s, with the transient envelopes ({c.envelope}) "
            f"{100 * c.covered_any:.0f}%"
        )
        if c.gaps:
            line += "; level not covered: " + "; ".join(c.gaps)
        lines.append(line)
    lines += [f"  {w.text()}" for w in numbers]
    return lines
