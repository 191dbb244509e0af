"""The ``trajectory.csv`` file: its columns, the frame, writing it and reading it back.

A run that stopped early is written all the same, led by ``# incomplete: t = <t>: <reason>``.
"""

from __future__ import annotations

import io
import math
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
import pandas as pd

from core.errors import BuildError
from core.memo import MEMO
from core.scenario import Scenario
from generated.csource import expanded
from generated.values import Trajectory

if TYPE_CHECKING:
    from generated.built import Built

#: first line of a trajectory.csv whose run stopped early (readers skip ``#`` lines)
INCOMPLETE_MARK = "# incomplete: "


def column_names(sc: Scenario) -> list[str]:
    """The CSV columns, in order (agents and components 1-based).

    Parameters
    ----------
    sc : Scenario
    """
    m, n = sc.m, sc.n
    # per follower: states, then outputs; width 0: a scalar without a component index
    states = ("p", n), ("q", n), ("eta", m), ("mu", m), ("phi", 0), ("thetahat", n), ("ghat", 0)
    outputs = ("u", n), ("b", n), ("et", n), ("eeta", m), ("chi", n)
    cols = ["t"] + [f"eta0_{k}" for k in range(1, m + 1)]
    for i in range(1, sc.N + 1):
        for name, width in (*states, *outputs):
            cols += [f"{name}{i}_{k}" for k in range(1, width + 1)] if width else [f"{name}{i}"]
        cols.append(f"V2_{i}")
    return [*cols, "V1"]


#: CSV prefix -> the closed loop's output it shows (:func:`symbolic.closed_loop.build_closed_loop`)
_OUTPUTS = {"u": "u", "b": "b", "et": "et", "eeta": "ebar", "chi": "chi", "V2": "V2", "V1": "V1"}


#: by (id of the outputs Function, K): the Function, its map and the map's evaluation
#: buffer; one per structure and horizon in use (core/memo.py)
_MAPS = MEMO.namespace("mapped-outputs", 24)
#: one evaluation at a time uses a kept buffer
_MAPS_LOCK = threading.Lock()


def _mapped(f: ca.Function, K: int) -> tuple[ca.Function, Any, Any]:
    """``f`` evaluated at K times in one call (input ``p`` shared), with a buffer: kept (the
    entry holds ``f``, so its id is not reused while it lives). :data:`_MAPS_LOCK` held."""
    key = (id(f), K)
    entry = _MAPS.get(key)
    if entry is None:
        shared = [nm == "p" for nm in f.name_in()]
        F = expanded(f).map(K, shared, [False] * f.n_out())
        entry = _MAPS[key] = (f, F, *F.buffer())
    return entry[1:]


def evaluate_outputs(built: Built, traj: Trajectory) -> dict[str, np.ndarray]:
    """All named outputs at every output time, in one call: ``name -> array (K, rows, cols)``.

    Parameters
    ----------
    built : Built
    traj : Trajectory
    """
    return {nm: a.transpose(0, 2, 1) for nm, a in _evaluate(built, traj).items()}


def _evaluate(built: Built, traj: Trajectory) -> dict[str, np.ndarray]:
    """:func:`evaluate_outputs` as ``name -> array (K, cols, rows)``, C-contiguous."""
    K = len(traj.t)
    f = getattr(built, "outputs_p", None)
    f = built.outputs if f is None else f
    if K == 0:
        return {nm: np.zeros((0, *f.size_out(j)[::-1])) for j, nm in enumerate(f.name_out())}
    given = {"t": traj.t, "x": traj.x, "p": getattr(built, "p", None)}  # x: K x nx = nx x K
    args = [  # alive until the call
        np.ascontiguousarray(
            np.zeros(0) if given.get(nm) is None else given[nm], dtype=float
        ).ravel()
        for nm in f.name_in()
    ]
    with _MAPS_LOCK:
        F, buf, call = _mapped(f, K)
        for i, (nm, a) in enumerate(zip(f.name_in(), args, strict=True)):
            if a.size != F.nnz_in(i):
                raise BuildError(
                    f"closed loop outputs: input {nm!r} takes {F.nnz_in(i)} values, "
                    f"the run gives {a.size} (inputs t, x and p are known)"
                )
            buf.set_arg(i, memoryview(a))
        res = [np.empty(F.nnz_out(j)) for j in range(F.n_out())]
        for j, a in enumerate(res):
            buf.set_res(j, memoryview(a))
        call()
    out = {}
    for j, nm in enumerate(f.name_out()):
        r, c = f.size_out(j)
        sp = F.sparsity_out(j)
        # r x (c*K) by columns, time blocks side by side
        a = res[j] if sp.is_dense() else ca.DM(sp, res[j]).full().ravel(order="F")
        out[nm] = a.reshape(K, c, r)
    return out


def trajectory_frame(built: Built, sc: Scenario, traj: Trajectory) -> pd.DataFrame:
    """The trajectory as a DataFrame with exactly the columns of :func:`column_names`.

    Parameters
    ----------
    built : Built
    sc : Scenario
    traj : Trajectory

    Raises
    ------
    BuildError
        If the closed loop's outputs or state layout do not give these columns.
    """
    raw = _evaluate(built, traj)  # (K, cols, rows)
    missing = [nm for nm in _OUTPUTS.values() if nm not in raw]
    if missing:
        raise BuildError(f"closed loop outputs lack {missing} (it has {', '.join(raw)})")
    N = sc.N
    widths = {"u": sc.n, "b": sc.n, "et": sc.n, "eeta": sc.m, "chi": sc.n, "V2": 1}
    for key, width in widths.items():
        nm = _OUTPUTS[key]
        c, r = raw[nm].shape[1:]
        if (r, c) != (N, width):
            raise BuildError(
                f"closed loop output {nm!r} is {r}x{c} per time, "
                f"expected {N}x{width} (one row per agent)"
            )
    if raw["V1"].shape[1:] != (1, 1):
        raise BuildError("closed loop output 'V1' is not a scalar")
    X = np.asarray(traj.x, dtype=float)
    K, nx = len(traj.t), X.shape[1]
    # one table [t | x | each output by time, column-major], then every frame column picked:
    # output entry (i, k) (N x width per time, by columns) is k N + i after its start
    parts = [np.asarray(traj.t, dtype=float).reshape(K, 1), X]
    start, at = {}, 1 + nx
    for key, nm in _OUTPUTS.items():
        start[key] = at
        parts.append(raw[nm].reshape(K, math.prod(raw[nm].shape[1:])))
        at += parts[-1].shape[1]
    sl, x_col = built.closed_loop.layout.slices, 1 + np.arange(nx)
    idx = [0, *np.atleast_1d(x_col[sl["eta0"]])]
    for i in range(N):
        for key in ("p", "q", "eta", "mu", "phi", "thetahat", "ghat"):
            idx += list(np.atleast_1d(x_col[sl[(key, i)]]))
        for key, width in widths.items():
            idx += [start[key] + k * N + i for k in range(width)]
    idx.append(start["V1"])
    data = np.concatenate(parts, axis=1)[:, idx]
    cols = column_names(sc)
    if data.shape[1] != len(cols):
        raise BuildError(
            f"trajectory has {data.shape[1]} columns, expected {len(cols)} (check the state layout)"
        )
    return pd.DataFrame(data, columns=cols)


def csv_text(df: pd.DataFrame) -> str:
    """Deterministic CSV: header, then every value as the shortest text that reads back exactly.

    Without a ``float_format`` pandas writes each float64 as Python's ``repr`` does;
    ``nan`` spelled out (pandas' default is an empty field), ``\\n`` on every platform.

    Parameters
    ----------
    df : pandas.DataFrame
        All columns numeric (written as float64); the index is not written.
    """
    return df.astype(float).to_csv(index=False, lineterminator="\n", na_rep="nan")


def trajectory_text(df: pd.DataFrame, traj: Trajectory) -> str:
    """The ``trajectory.csv`` text: :func:`csv_text`, led by ``# incomplete: <reason>`` if partial.

    Parameters
    ----------
    df : pandas.DataFrame
    traj : Trajectory
    """
    if traj.complete:
        return csv_text(df)
    why = " ".join(str(traj.message or "integrator stopped").split())
    return f"{INCOMPLETE_MARK}t = {traj.t_reached!r}: {why}\n" + csv_text(df)


def read_trajectory(data: bytes | str | Path) -> tuple[pd.DataFrame, str | None]:
    """Parse ``trajectory.csv``: the frame and the text after ``# incomplete: `` (None if complete).

    Parameters
    ----------
    data : bytes, str or Path
        The file's bytes or text, or its path.
    """
    if isinstance(data, Path):
        data = data.read_bytes()
    text = data.decode("utf-8") if isinstance(data, bytes) else data
    first = text.split("\n", 1)[0]
    reason = first[len(INCOMPLETE_MARK) :] if first.startswith(INCOMPLETE_MARK) else None
    return pd.read_csv(io.StringIO(text), comment="#"), reason


def data_rows(text: str) -> int:
    """Rows of a ``trajectory.csv`` text: non-empty lines, not comments, not the header.

    Parameters
    ----------
    text : str
    """
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    return max(len(lines) - 1, 0)
