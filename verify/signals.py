"""Reading a trajectory DataFrame (the columns of ``trajectory.csv``) into arrays.

Column format (agents 1-based): ``t``, ``eta0_k``; per follower i: ``p{i}_{r}``,
``q{i}_{r}``, ``eta{i}_{k}``, ``mu{i}_{k}``, ``phi{i}``, ``thetahat{i}_{r}``,
``ghat{i}``, ``u{i}_{r}``, ``b{i}_{r}``, ``et{i}_{r}``, ``eeta{i}_{k}``,
``chi{i}_{r}``, ``V2_{i}``; and ``V1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


def block(df: Frame, prefix: str, i: int, width: int) -> np.ndarray:
    """Columns ``{prefix}{i}_{1..width}`` (i 1-based) as a (K, width) array.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    prefix : str
        Signal name, e.g. ``"p"`` or ``"et"``.
    i : int
        1-based agent number.
    width : int
        Number of components.
    """
    names = [f"{prefix}{i}_{r}" for r in range(1, width + 1)]
    missing = [c for c in names if not has(df, c)]
    if missing:
        raise VerifyError(f"trajectory: column {missing[0]!r} is missing (re-run the simulation)")
    return take(df, names)


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


def leader_output(df: Frame, C0: np.ndarray) -> np.ndarray:
    """y0 = C0 η0 along the trajectory, (K, n).

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    C0 : ndarray
        n×m leader output matrix.
    """
    m = C0.shape[1]
    eta0 = take(df, [f"eta0_{k}" for k in range(1, m + 1)])
    return eta0 @ np.asarray(C0, dtype=float).T


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


def agent_norm(df: Frame, prefix: str, i: int, width: int) -> np.ndarray:
    """Euclidean norm over components of ``{prefix}{i}_*`` at each sample.

    Parameters
    ----------
    df : DataFrame or Columns
        A trajectory in the ``trajectory.csv`` format (column ``t`` and one column per signal
        component).
    prefix : str
        Signal name, e.g. ``"et"``.
    i : int
        1-based agent number.
    width : int
        Number of components.
    """
    return np.linalg.norm(block(df, prefix, i, width), axis=1)
