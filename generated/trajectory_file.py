"""The ``trajectory.csv`` file: its columns, the frame, writing it and reading it back.

Columns (agents and components 1-based): ``t``, the leader's ``eta0_k``, then per
follower its states and outputs (:func:`column_names`), and ``V1`` last. A run that
stopped early is written all the same, led by ``# incomplete: t = <t>: <reason>``
(:data:`INCOMPLETE_MARK`); readers skip ``#`` lines.
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
        Supplies the sizes ``N``, ``n`` and ``m``.
    """
    m, n, N = sc.m, sc.n, sc.N
    cols = ["t"] + [f"eta0_{k}" for k in range(1, m + 1)]
    for i in range(1, N + 1):
        cols += [f"p{i}_{r}" for r in range(1, n + 1)]
        cols += [f"q{i}_{r}" for r in range(1, n + 1)]
        cols += [f"eta{i}_{k}" for k in range(1, m + 1)]
        cols += [f"mu{i}_{k}" for k in range(1, m + 1)]
        cols += [f"phi{i}"]
        cols += [f"thetahat{i}_{r}" for r in range(1, n + 1)]
        cols += [f"ghat{i}"]
        cols += [f"u{i}_{r}" for r in range(1, n + 1)]
        cols += [f"b{i}_{r}" for r in range(1, n + 1)]
        cols += [f"et{i}_{r}" for r in range(1, n + 1)]
        cols += [f"eeta{i}_{k}" for k in range(1, m + 1)]
        cols += [f"chi{i}_{r}" for r in range(1, n + 1)]
        cols += [f"V2_{i}"]
    return [*cols, "V1"]


#: CSV prefix -> the closed loop's output it shows (:func:`symbolic.closed_loop.build_closed_loop`)
_OUTPUTS = {"u": "u", "b": "b", "et": "et", "eeta": "ebar", "chi": "chi", "V2": "V2", "V1": "V1"}


#: mapped outputs Functions by (id of the Function, K): the Function, its map and an
#: evaluation buffer of the map
#: how many mapped Functions are kept (one per structure and horizon in use)
_MAPS_KEPT = 24
_MAPS = MEMO.namespace("mapped-outputs", _MAPS_KEPT)  # core/memo.py
#: one evaluation at a time uses a kept buffer
_MAPS_LOCK = threading.Lock()


def _mapped(f: ca.Function, K: int) -> tuple[ca.Function, Any, Any]:
    """``f`` evaluated at K times in one call (an input ``p`` shared by all), with a buffer.

    Kept for the next run of the same Function and K (the entry holds ``f``, so its id
    is not reused while the entry lives). Call with :data:`_MAPS_LOCK` held.
    """
    key = (id(f), K)
    entry = _MAPS.get(key)
    if entry is None:
        shared = [nm == "p" for nm in f.name_in()]
        F = _expanded(f).map(K, shared, [False] * f.n_out())
        entry = _MAPS[key] = (f, F, *F.buffer())
    return entry[1:]


def _expanded(f: ca.Function) -> ca.Function:
    """An MX ``f`` (the symbolic closed loop's outputs) as SX: the same operations in the
    same order, evaluated without the MX virtual machine's per-node overhead (the same
    numbers, bit for bit: ``tests/test_trajectory_file.py``); ``f`` itself when it is not
    MX or does not expand (a call into a compiled library)."""
    if not f.is_a("MXFunction"):
        return f
    try:
        return f.expand()
    except RuntimeError:
        return f


def evaluate_outputs(built: Built, traj: Trajectory) -> dict[str, np.ndarray]:
    """All named outputs at every output time: ``name -> array (K, rows, cols)``.

    The library's outputs Function is called once for all times, with the runtime
    parameters ``built.p`` as its input ``p`` (when it has one), reading and writing
    numpy arrays directly.

    Parameters
    ----------
    built : Built
        Supplies the compiled ``outputs`` Function (``outputs_p`` and ``p``).
    traj : Trajectory
        The output times and states.
    """
    return {nm: a.transpose(0, 2, 1) for nm, a in _evaluate(built, traj).items()}


def _evaluate(built: Built, traj: Trajectory) -> dict[str, np.ndarray]:
    """:func:`evaluate_outputs` as ``name -> array (K, cols, rows)``, C-contiguous."""
    K = len(traj.t)
    f = getattr(built, "outputs_p", None)
    f = built.outputs if f is None else f
    if K == 0:
        return {nm: np.zeros((0, *f.size_out(j)[::-1])) for j, nm in enumerate(f.name_out())}
    with _MAPS_LOCK:
        return _evaluate_mapped(f, K, built, traj)


def _evaluate_mapped(
    f: ca.Function, K: int, built: Built, traj: Trajectory
) -> dict[str, np.ndarray]:
    """:func:`_evaluate` through the kept map of ``f`` (:data:`_MAPS_LOCK` held)."""
    F, buf, call = _mapped(f, K)
    given = {"t": traj.t, "x": traj.x, "p": getattr(built, "p", None)}  # x: K x nx = nx x K
    args = []  # alive until the call
    for i, nm in enumerate(f.name_in()):
        a = np.ascontiguousarray(
            np.zeros(0) if given.get(nm) is None else given[nm], dtype=float
        ).ravel()
        if a.size != F.nnz_in(i):
            raise BuildError(
                f"closed loop outputs: input {nm!r} takes {F.nnz_in(i)} values, "
                f"the run gives {a.size} (inputs t, x and p are known)"
            )
        buf.set_arg(i, memoryview(a))
        args.append(a)
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
        Supplies the state layout and the compiled outputs.
    sc : Scenario
        Supplies the sizes ``N``, ``n`` and ``m``.
    traj : Trajectory
        The output times and states.

    Raises
    ------
    BuildError
        If the closed loop's outputs or state layout do not give these columns.
    """
    raw = _evaluate(built, traj)  # (K, cols, rows)
    named = _frame_outputs({nm: a.shape[:0:-1] for nm, a in raw.items()}, sc)
    X = np.asarray(traj.x, dtype=float)
    K, nx = len(traj.t), X.shape[1]
    # one table [t | x | each output by time, column-major], then every frame column picked
    parts = [np.asarray(traj.t, dtype=float).reshape(K, 1), X]
    start, at = {}, 1 + nx
    for nm in dict.fromkeys(nm for nm, _ in named.values()):
        start[nm] = at
        parts.append(raw[nm].reshape(K, math.prod(raw[nm].shape[1:])))
        at += parts[-1].shape[1]
    idx = _frame_index(built.closed_loop.layout.slices, nx, sc.N, named, start)
    data = np.concatenate(parts, axis=1)[:, idx]
    cols = column_names(sc)
    if data.shape[1] != len(cols):
        raise BuildError(
            f"trajectory has {data.shape[1]} columns, expected {len(cols)} (check the state layout)"
        )
    return pd.DataFrame(data, columns=cols)


def _frame_outputs(shapes: dict[str, tuple[int, ...]], sc: Scenario) -> dict[str, tuple[str, int]]:
    """The outputs the frame shows: CSV prefix -> (output name, width); shapes checked.

    ``shapes``: output name -> (rows, cols) per time.
    """

    missing = [nm for nm in _OUTPUTS.values() if nm not in shapes]
    if missing:
        raise BuildError(f"closed loop outputs lack {missing} (it has {', '.join(shapes)})")
    N, n, m = sc.N, sc.n, sc.m
    named = {}
    for key, width in (("u", n), ("b", n), ("et", n), ("eeta", m), ("chi", n), ("V2", 1)):
        nm = _OUTPUTS[key]
        if tuple(shapes[nm]) != (N, width):
            r, c = shapes[nm]
            raise BuildError(
                f"closed loop output {nm!r} is {r}x{c} per time, "
                f"expected {N}x{width} (one row per agent)"
            )
        named[key] = (nm, width)
    nm = _OUTPUTS["V1"]
    if tuple(shapes[nm]) != (1, 1):
        raise BuildError(f"closed loop output {nm!r} is not a scalar")
    named["V1"] = (nm, 1)
    return named


def _frame_index(
    sl: dict, nx: int, N: int, named: dict[str, tuple[str, int]], start: dict[str, int]
) -> list[int]:
    """Columns of ``[t | x | outputs]`` in the order of :func:`column_names`.

    Output ``nm`` (N x width per time, stored by columns) starts at ``start[nm]``: its
    entry (i, k) is ``k N + i`` further.
    """
    x_col = 1 + np.arange(nx)
    idx = [0, *np.atleast_1d(x_col[sl["eta0"]])]
    for i in range(N):
        for key in ("p", "q", "eta", "mu", "phi", "thetahat", "ghat"):
            idx += list(np.atleast_1d(x_col[sl[(key, i)]]))
        for key in ("u", "b", "et", "eeta", "chi", "V2"):
            nm, width = named[key]
            idx += [start[nm] + k * N + i for k in range(width)]
    idx.append(start[named["V1"][0]])
    return idx


def csv_text(df: pd.DataFrame) -> str:
    """Deterministic CSV: header, then every value as the shortest text that reads back exactly.

    Written by :meth:`pandas.DataFrame.to_csv` without a ``float_format``, which gives
    each float64 the same text as Python's ``repr`` (shortest round-trip form); ``nan``
    is spelled out (pandas' default is an empty field) and lines end in ``\\n`` on
    every platform.

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
        The frame (:func:`trajectory_frame`).
    traj : Trajectory
        Its ``complete``, ``t_reached`` and ``message`` mark a partial run in the file itself.
    """
    if traj.complete:
        return csv_text(df)
    why = " ".join(str(traj.message or "integrator stopped").split())
    return f"{INCOMPLETE_MARK}t = {traj.t_reached!r}: {why}\n" + csv_text(df)


def read_trajectory(data: bytes | str | Path) -> tuple[pd.DataFrame, str | None]:
    """Parse ``trajectory.csv`` (bytes, text or a path): the frame and the incomplete reason.

    Parameters
    ----------
    data : bytes, str or Path
        The file's bytes or text, or its path.

    Returns
    -------
    (DataFrame, str or None)
        The reason is the text after ``# incomplete: `` (None for a complete run).
    """
    if isinstance(data, Path):
        data = data.read_bytes()
    text = data.decode("utf-8") if isinstance(data, bytes) else data
    first = text.split("\n", 1)[0]
    reason = first[len(INCOMPLETE_MARK) :] if first.startswith(INCOMPLETE_MARK) else None
    return pd.read_csv(io.StringIO(text), comment="#"), reason


def data_rows(text: str) -> int:
    """Rows of a trajectory text: non-empty lines that are neither comments nor the header.

    Parameters
    ----------
    text : str
        The contents of a ``trajectory.csv``.
    """
    lines = [ln for ln in text.splitlines() if ln and not ln.startswith("#")]
    return max(len(lines) - 1, 0)
