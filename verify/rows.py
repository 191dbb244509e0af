"""The rows of the bound-vs-actual table and the time grid they are measured on.

Columns: ``claim, agent, component, kind, bound, observed, ratio, holds, window, note``
(what a reader reads), then ``claim_id, t_start, t_end, depends`` (the same row as data:
the registry's id, the window as numbers, what the derivation depends on). ``holds`` is
empty for a row the derivation gives but that cannot be evaluated on this run (the
note says why). The ``window`` text is made from ``t_start``, ``t_end`` and never read
back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from verify import signals as S
from verify.bounds import VerifyConfig
from verify.claims import Claim, Kind

COLUMNS = [
    "claim",
    "agent",
    "component",
    "kind",
    "bound",
    "observed",
    "ratio",
    "holds",
    "window",
    "note",
    "claim_id",
    "t_start",
    "t_end",
    "depends",
]
#: the kinds, in the order the report lists them
KINDS = tuple(k.value for k in Kind)


def win(a: float, b: float) -> str:
    """A window ``[a, b] s`` as text.

    Parameters
    ----------
    a : float
        Its start (s).
    b : float
        Its end (s).
    """
    return f"[{a:g}, {b:g}] s"


@dataclass
class Rows:
    """Accumulates table rows."""

    rows: list[dict] = field(default_factory=list)

    def add(
        self,
        claim: Claim,
        kind: Kind | str,
        bound: float,
        observed: float,
        window: tuple[float, float] | None,
        note: str = "",
        *,
        agent: int | None = None,
        component: int | None = None,
        holds: bool | None = None,
        larger_is_better: bool = False,
        text: dict | None = None,
    ) -> None:
        """Append one row; ``ratio = observed / bound`` (NaN for a zero or infinite bound).

        Parameters
        ----------
        claim : Claim
            The registered claim (:mod:`verify.claims`).
        kind : Kind or str
            What a failure means for this row (the claim's kind, or weaker when a
            condition of its derivation fails on this run).
        bound : float
            The bound.
        observed : float
            The measured value.
        window : (float, float) or None
            Time window of the measurement (s).
        note : str
            Free text.
        agent : int, optional
            0-based follower (shown 1-based); None for all.
        component : int, optional
            0-based component (shown 1-based); None for none.
        holds : bool, optional
            Whether the claim holds; default ``observed <= bound`` (``>=`` with
            ``larger_is_better``).
        larger_is_better : bool
            Compare ``observed >= bound`` when ``holds`` is not given.
        text : dict, optional
            The fields of the claim's text.
        """
        kind = Kind(kind)
        if holds is None:
            holds = bool(observed >= bound) if larger_is_better else bool(observed <= bound)
        self._append(
            claim, kind, bound, observed, window, note, agent, component, bool(holds), text
        )

    def missing(
        self,
        claim: Claim,
        window: tuple[float, float] | None,
        why: str,
        *,
        agent: int | None = None,
        component: int | None = None,
        bound: float = math.nan,
        text: dict | None = None,
    ) -> None:
        """Append a row the derivation gives but this run cannot evaluate (``holds`` empty).

        Parameters
        ----------
        claim : Claim
            The registered claim.
        window : (float, float) or None
            The window it would have.
        why : str
            Why it is not evaluated (the note).
        agent, component : int, optional
            0-based follower and component.
        bound : float
            The bound when known.
        text : dict, optional
            The fields of the claim's text.
        """
        note = f"not evaluated: {why}"
        self._append(claim, Kind.INFO, bound, math.nan, window, note, agent, component, None, text)

    def _append(self, claim, kind, bound, observed, window, note, agent, component, holds, text):  # noqa: ANN001, PLR0913
        bound, observed = float(bound), float(observed)
        ratio = observed / bound if bound != 0.0 and math.isfinite(bound) else math.nan
        a, b = window if window is not None else (math.nan, math.nan)
        self.rows.append(
            {
                "claim": claim.render(**(text or {})),
                "agent": "all" if agent is None else str(agent + 1),
                "component": "" if component is None else str(component + 1),
                "kind": kind.value,
                "bound": bound,
                "observed": observed,
                "ratio": float(ratio),
                "holds": holds,
                "window": "" if window is None else win(a, b),
                "note": note,
                "claim_id": claim.id,
                "t_start": float(a),
                "t_end": float(b),
                "depends": ",".join(sorted(d.value for d in claim.depends)),
            }
        )

    def frame(self) -> pd.DataFrame:
        """The rows as a DataFrame with :data:`COLUMNS` (``holds`` nullable boolean)."""
        out = pd.DataFrame(self.rows, columns=COLUMNS)
        return out.astype({"holds": "boolean"})


@dataclass(frozen=True)
class Span:
    """The time grid of a trajectory and the windows the rows report.

    Attributes
    ----------
    t : ndarray
        Output times.
    tail : ndarray
        Boolean mask of the asymptotic window (last ``tail_fraction`` of the horizon).
    """

    t: np.ndarray
    tail: np.ndarray

    @classmethod
    def of(cls, df: S.FrameOrView, cfg: VerifyConfig) -> Span:
        """The span of a trajectory.

        Parameters
        ----------
        df : DataFrame
            The trajectory (column ``t``).
        cfg : VerifyConfig
            Its tail fraction sets the tail.
        """
        t = S.TrajectoryView.of(df).t
        return cls(t, S.tail_mask(t, cfg.tail_fraction))

    @property
    def t0(self) -> float:
        """First output time."""
        return float(self.t[0])

    @property
    def t1(self) -> float:
        """Last output time."""
        return float(self.t[-1])

    @property
    def tail_start(self) -> float:
        """First output time in the tail."""
        return float(self.t[self.tail][0])

    @property
    def full(self) -> tuple[float, float]:
        """The whole horizon."""
        return (self.t0, self.t1)

    @property
    def tail_window(self) -> tuple[float, float]:
        """The tail."""
        return (self.tail_start, self.t1)


def failed_mask(table: pd.DataFrame) -> pd.Series:
    """Rows evaluated and not holding (an empty ``holds`` is no failure).

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    """
    return table["holds"].astype("boolean").eq(False).fillna(False).astype(bool)


def held_mask(table: pd.DataFrame) -> pd.Series:
    """Rows evaluated and holding.

    Parameters
    ----------
    table : DataFrame
        The bound-vs-actual table.
    """
    return table["holds"].astype("boolean").eq(True).fillna(False).astype(bool)
