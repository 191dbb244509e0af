"""Reading a trajectory DataFrame (the columns of ``trajectory.csv``) into arrays.

Column format (agents 1-based): ``t``, ``eta0_k``; per follower i: ``p{i}_{r}``,
``q{i}_{r}``, ``eta{i}_{k}``, ``mu{i}_{k}``, ``phi{i}``, ``thetahat{i}_{r}``,
``ghat{i}``, ``u{i}_{r}``, ``b{i}_{r}``, ``et{i}_{r}``, ``eeta{i}_{k}``,
``chi{i}_{r}``, ``V2_{i}``; and ``V1``. :class:`Signal` names each per-follower block
and :class:`TrajectoryView` reads them, so consumers never spell a column name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
import pandas as pd

from verify.bounds import VerifyError


@dataclass(frozen=True)
class Columns:
    """A trajectory's columns as one float array, looked up by name.

    Selecting columns of a DataFrame by a list of names costs pandas' indexing machinery
    each time; the table reads dozens of blocks per run, so it converts the frame once
    (:meth:`of`) and slices this array instead (the same numbers).

    Attributes
    ----------
    names : tuple of str
        Column names, in the frame's order.
    position : dict
        Name -> column position.
    values : ndarray or None
        (K, columns) as float; None when some column is not numeric (then each request
        converts its own columns from :attr:`frame`).
    frame : DataFrame
        The trajectory itself.
    """

    names: tuple[str, ...]
    position: dict[str, int]
    values: np.ndarray | None
    frame: pd.DataFrame

    @classmethod
    def of(cls, df: pd.DataFrame | Columns) -> Columns:
        """The columns of ``df`` (``df`` itself when it already is :class:`Columns`).

        Parameters
        ----------
        df : DataFrame or Columns
            A trajectory in the ``trajectory.csv`` format.
        """
        if isinstance(df, Columns):
            return df
        names = tuple(str(c) for c in df.columns)
        try:
            values = df.to_numpy(dtype=float)
        except (TypeError, ValueError):  # a non-numeric column: convert per request
            values = None
        return cls(names, {c: k for k, c in enumerate(names)}, values, df)

    def __len__(self) -> int:
        return len(self.frame)

    def has(self, name: str) -> bool:
        """Whether column ``name`` exists.

        Parameters
        ----------
        name : str
            Column name.
        """
        return name in self.position

    def take(self, names: list[str]) -> np.ndarray:
        """Columns ``names`` as a (K, len(names)) float array (all must exist).

        Parameters
        ----------
        names : list of str
            Column names.
        """
        if self.values is None or len(self.position) != len(self.names):
            return self.frame[names].to_numpy(dtype=float)
        # column-major, as pandas returns a selection: the same layout for every reduction
        return np.asfortranarray(self.values[:, [self.position[c] for c in names]])

    def col(self, name: str) -> np.ndarray:
        """Column ``name`` as a (K,) float array.

        Parameters
        ----------
        name : str
            Column name.
        """
        if self.values is None or len(self.position) != len(self.names):
            return self.frame[name].to_numpy(float)
        return self.values[:, self.position[name]].copy()


Frame = pd.DataFrame | Columns


@dataclass(frozen=True)
class Dims:
    """Sizes read from the column names: N followers, n outputs, m leader states."""

    N: int
    n: int
    m: int


def dims(df: Frame) -> Dims:
    """Infer (N, n, m) from the column names.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).

    Raises
    ------
    VerifyError
        If ``t``, ``eta0_1`` or ``p1_1`` is missing.
    """
    cols = set(df.position) if isinstance(df, Columns) else set(df.columns)
    for need in ("t", "eta0_1", "p1_1"):
        if need not in cols:
            raise VerifyError(
                f"trajectory: column {need!r} is missing (expected the trajectory.csv format)"
            )
    m = _count(cols, "eta0_{}")
    n = _count(cols, "p1_{}")
    N = _count(cols, "p{}_1")
    return Dims(N=N, n=n, m=m)


def _count(cols: set[str], pattern: str) -> int:
    k = 0
    while pattern.format(k + 1) in cols:
        k += 1
    return k


def has(df: Frame, name: str) -> bool:
    """Whether column ``name`` exists.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    name : str
        Column name.
    """
    if isinstance(df, Columns):
        return df.has(name)
    return name in df.columns


def column(df: Frame, name: str) -> np.ndarray:
    """Column ``name`` as a (K,) float array.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format.
    name : str
        Column name (a missing one raises KeyError, as DataFrame indexing does).
    """
    if isinstance(df, Columns):
        return df.col(name)
    return df[name].to_numpy(float)


def take(df: Frame, names: list[str]) -> np.ndarray:
    """Columns ``names`` as a (K, len(names)) float array, column-major as pandas gives them.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format.
    names : list of str
        Column names (a missing one raises KeyError, as DataFrame indexing does).
    """
    if isinstance(df, Columns):
        return df.take(names)
    return df[names].to_numpy(dtype=float)


def tail_start(t: np.ndarray, fraction: float) -> float:
    """Where the last ``fraction`` of [t0, t_end] (the "asymptotic" window) begins, less
    a 1e-12 s allowance so that a sample at the boundary belongs to the window.

    Parameters
    ----------
    t : ndarray
        Sample times, increasing.
    fraction : float
        Fraction of the time span counted as the tail.
    """
    t0, t1 = float(t[0]), float(t[-1])
    return t1 - fraction * (t1 - t0) - 1e-12


def tail_mask(t: np.ndarray, fraction: float) -> np.ndarray:
    """Samples in the last ``fraction`` of [t0, t_end] (from :func:`tail_start` on).

    Parameters
    ----------
    t : ndarray
        Sample times, increasing.
    fraction : float
        Fraction of the time span counted as the tail.
    """
    return t >= tail_start(t, fraction)


def enter_time(t: np.ndarray, y: np.ndarray, level: float) -> float:
    """First time after which ``y <= level`` at every later sample (inf if never; t0 if always).

    Parameters
    ----------
    t, y : ndarray
        Samples.
    level : float

    Returns
    -------
    float
    """
    above = np.nonzero(np.asarray(y) > level)[0]
    if above.size == 0:
        return float(t[0])
    last = int(above[-1])
    return math.inf if last == len(t) - 1 else float(t[last + 1])


def decay_rate(t: np.ndarray, y: np.ndarray, floor: float = 1e-300) -> float:
    """Least-squares rate r of y ≈ c e^{−r t} over the given samples (NaN if < 3 usable).

    Parameters
    ----------
    t, y : ndarray
        Samples (y > 0 is used; zeros are dropped).
    floor : float
        Values at or below it are ignored.

    Returns
    -------
    float
        The fitted rate (positive = decaying).
    """
    ok = np.asarray(y) > floor
    if ok.sum() < 3:
        return math.nan
    slope = np.polyfit(np.asarray(t)[ok], np.log(np.asarray(y)[ok]), 1)[0]
    return float(-slope)


def leader_column(k: int) -> str:
    """The name of column ``k`` (1-based) of the leader's state η0.

    Parameters
    ----------
    k : int
        1-based state component.
    """
    return f"eta0_{k}"


class Signal(Enum):
    """A per-follower block of the trajectory: its column pattern and its width rule.

    The value is ``(pattern, rule)``. ``pattern`` names column r of follower i (both
    1-based; a one-column signal has no ``{r}``); ``rule`` is how many columns the block
    has: ``"n"`` (one per output), ``"m"`` (one per leader state) or ``"1"``. The
    adaptive estimate θ̂_i has one entry per output channel, so its width is n (the
    columns :func:`generated.trajectory_file.column_names` writes).
    """

    P = ("p{i}_{r}", "n")
    Q = ("q{i}_{r}", "n")
    ETA = ("eta{i}_{r}", "m")
    MU = ("mu{i}_{r}", "m")
    PHI = ("phi{i}", "1")
    THETAHAT = ("thetahat{i}_{r}", "n")
    GHAT = ("ghat{i}", "1")
    U = ("u{i}_{r}", "n")
    B = ("b{i}_{r}", "n")
    ET = ("et{i}_{r}", "n")
    EETA = ("eeta{i}_{r}", "m")
    CHI = ("chi{i}_{r}", "n")
    V2 = ("V2_{i}", "1")

    @property
    def pattern(self) -> str:
        """Column r of follower i as a format string (fields ``i`` and ``r``)."""
        return self.value[0]

    @property
    def rule(self) -> str:
        """The width rule: ``"n"``, ``"m"`` or ``"1"``."""
        return self.value[1]

    @property
    def stem(self) -> str:
        """The pattern before the follower's number (``"p"``, ``"V2_"``)."""
        return self.pattern.partition("{")[0]

    def width(self, dm: Dims) -> int:
        """Number of columns per follower for trajectory sizes ``dm``.

        Parameters
        ----------
        dm : Dims
            The trajectory's sizes.
        """
        return {"n": dm.n, "m": dm.m, "1": 1}[self.rule]

    def column(self, i: int, r: int = 1) -> str:
        """The name of column ``r`` of follower ``i`` (``r`` is ignored for one column).

        Parameters
        ----------
        i : int
            1-based follower.
        r : int
            1-based component.
        """
        return self.pattern.format(i=i, r=r)

    def columns(self, i: int, width: int) -> list[str]:
        """The names of follower ``i``'s block, ``width`` components (one for a scalar).

        Parameters
        ----------
        i : int
            1-based follower.
        width : int
            Number of components.
        """
        if self.rule == "1":
            return [self.column(i)]
        return [self.column(i, r) for r in range(1, width + 1)]

    @classmethod
    def named(cls, stem: str) -> Signal:
        """The signal whose columns start with ``stem`` (a closed-loop state's name).

        Parameters
        ----------
        stem : str
            E.g. ``"p"``, ``"thetahat"``.

        Raises
        ------
        VerifyError
            If no signal has that stem (the trajectory does not store it).
        """
        for sig in cls:
            if sig.stem == stem:
                return sig
        raise VerifyError(f"trajectory: no signal {stem!r} is stored (re-run the simulation)")


@dataclass(frozen=True)
class TrajectoryView:
    """A trajectory's named blocks, read by :class:`Signal` and 1-based follower.

    Built once per trajectory (:meth:`of`). Every accessor selects through
    :meth:`Columns.take` or :meth:`Columns.col`, so its arrays are those the column
    helpers give (the same numbers in the same column-major layout). A missing column
    raises the one-line :class:`VerifyError` naming it.

    Attributes
    ----------
    columns : Columns
        The trajectory's columns.
    """

    columns: Columns
    _memo: dict[str, Dims] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def of(cls, df: Frame | TrajectoryView) -> TrajectoryView:
        """The view of ``df`` (``df`` itself when it already is one).

        Parameters
        ----------
        df : DataFrame, Columns or TrajectoryView
            A trajectory in the ``trajectory.csv`` format.
        """
        if isinstance(df, TrajectoryView):
            return df
        return cls(Columns.of(df))

    def __len__(self) -> int:
        return len(self.columns)

    @property
    def t(self) -> np.ndarray:
        """Output times, (K,)."""
        return self._col("t")

    @property
    def dims(self) -> Dims:
        """N, n and m read from the column names (:func:`dims`; its errors)."""
        if "dims" not in self._memo:
            self._memo["dims"] = dims(self.columns)
        return self._memo["dims"]

    def leader(self, width: int | None = None) -> np.ndarray:
        """The leader's state η0, (K, width).

        Parameters
        ----------
        width : int, optional
            Number of states (default m of :attr:`dims`).
        """
        m = self.dims.m if width is None else width
        return self._take([leader_column(k) for k in range(1, m + 1)])

    def leader_output(self, C0: np.ndarray) -> np.ndarray:
        """y0 = C0 η0 along the trajectory, (K, n).

        Parameters
        ----------
        C0 : ndarray
            n×m leader output matrix.
        """
        eta0 = self.leader(C0.shape[1])
        return eta0 @ np.asarray(C0, dtype=float).T

    def block(self, sig: Signal, i: int, width: int | None = None) -> np.ndarray:
        """Follower ``i``'s block of ``sig``, (K, width).

        Parameters
        ----------
        sig : Signal
            The block.
        i : int
            1-based follower.
        width : int, optional
            Number of components (default the signal's width rule on :attr:`dims`).
        """
        if width is None:
            width = 1 if sig.rule == "1" else sig.width(self.dims)
        return self._take(sig.columns(i, width))

    def norm(self, sig: Signal, i: int, width: int | None = None) -> np.ndarray:
        """Euclidean norm over the components of follower ``i``'s ``sig`` per sample, (K,).

        Parameters
        ----------
        sig : Signal
            The block.
        i : int
            1-based follower.
        width : int, optional
            As :meth:`block`.
        """
        return np.linalg.norm(self.block(sig, i, width), axis=1)

    def scalar(self, sig: Signal, i: int) -> np.ndarray:
        """Follower ``i``'s one-column signal ``sig``, (K,).

        Parameters
        ----------
        sig : Signal
            A signal of width rule ``"1"``.
        i : int
            1-based follower.
        """
        return self._col(_scalar(sig).column(i))

    def scalars(self, sig: Signal, count: int | None = None) -> np.ndarray:
        """The one-column signal ``sig`` of followers 1..count side by side, (K, count).

        Parameters
        ----------
        sig : Signal
            A signal of width rule ``"1"``.
        count : int, optional
            Number of followers (default N of :attr:`dims`).
        """
        N = self.dims.N if count is None else count
        return self._take([_scalar(sig).column(i) for i in range(1, N + 1)])

    def has(self, sig: Signal, i: int) -> bool:
        """Whether the trajectory logs follower ``i``'s ``sig`` (its first column).

        Parameters
        ----------
        sig : Signal
            The block.
        i : int
            1-based follower.
        """
        return self.columns.has(sig.column(i))

    def V1(self) -> np.ndarray:
        """The observer's Lyapunov function V1, (K,)."""
        return self._col("V1")

    def has_V1(self) -> bool:
        """Whether the trajectory logs V1."""
        return self.columns.has("V1")

    def _col(self, name: str) -> np.ndarray:
        self._need([name])
        return self.columns.col(name)

    def _take(self, names: list[str]) -> np.ndarray:
        self._need(names)
        return self.columns.take(names)

    def _need(self, names: list[str]) -> None:
        missing = [c for c in names if not self.columns.has(c)]
        if missing:
            raise VerifyError(
                f"trajectory: column {missing[0]!r} is missing (re-run the simulation)"
            )


def _scalar(sig: Signal) -> Signal:
    """``sig``, which must be a one-column signal."""
    if sig.rule != "1":
        raise ValueError(f"Signal.{sig.name} has {sig.rule} columns per follower: use block()")
    return sig


def block(df: Frame, prefix: str, i: int, width: int) -> np.ndarray:
    """Columns ``{prefix}{i}_{1..width}`` (i 1-based) as a (K, width) array.

    :meth:`TrajectoryView.block` of the signal named ``prefix``; the packages read the view.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format.
    prefix : str
        Signal name, e.g. ``"p"`` or ``"et"``.
    i : int
        1-based agent number.
    width : int
        Number of components.
    """
    return TrajectoryView.of(df).block(Signal.named(prefix), i, width)


def agent_norm(df: Frame, prefix: str, i: int, width: int) -> np.ndarray:
    """Euclidean norm over components of ``{prefix}{i}_*`` at each sample.

    :meth:`TrajectoryView.norm` of the signal named ``prefix``; the packages read the view.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format.
    prefix : str
        Signal name, e.g. ``"et"``.
    i : int
        1-based agent number.
    width : int
        Number of components.
    """
    return TrajectoryView.of(df).norm(Signal.named(prefix), i, width)


#: what the readers of a trajectory accept: a frame, its columns or its view
FrameOrView = Frame | TrajectoryView
