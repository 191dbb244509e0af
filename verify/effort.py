"""Peak control effort: ‖u_i‖ over the run and after the start-up (``info`` rows).

A check as docs/ARCHITECTURE.md's recipe adds one: its claims registered here
(:func:`verify.claims.register`), its rows with :func:`verify.checks.register_check`.
"""

from __future__ import annotations

import math

import numpy as np

from verify import claims as CL
from verify import signals as S
from verify.checks import CheckInput, register_check
from verify.rows import Rows

#: peak |u_i| is also reported after this start-up time (s): the t = 0 peak dominates
STARTUP = 1.0

PEAK_U = CL.register("effort.peak", "peak |u_i|", CL.Kind.INFO)
PEAK_U_LATE = CL.register("effort.peak_late", "peak |u_i| after t = {startup:g} s", CL.Kind.INFO)


def effort_rows(R: Rows, df: S.FrameOrView, N: int, n: int) -> None:
    """Peak ‖u_i‖ (Euclidean, logged torques) over the run and after :data:`STARTUP` (info).

    Parameters
    ----------
    R : Rows
        Rows to append to.
    df : DataFrame, Columns or TrajectoryView
        The trajectory; followers without ``u`` columns end the rows.
    N, n : int
        Number of followers and of outputs.
    """
    view = S.TrajectoryView.of(df)
    t = view.t
    for i in range(N):
        if not view.has(S.Signal.U, i + 1):
            return
        un = view.norm(S.Signal.U, i + 1, n)
        for label, mask in (
            ("", np.ones_like(t, bool)),
            (f" after t = {STARTUP:g} s", t >= STARTUP),
        ):
            if not mask.any():
                continue
            k = int(np.flatnonzero(mask)[np.argmax(un[mask])])
            R.add(
                PEAK_U_LATE if label else PEAK_U,
                CL.Kind.INFO,
                math.inf,  # a measurement: no bound
                float(un[k]),
                (float(t[mask][0]), float(t[-1])),
                f"at t = {t[k]:.4g} s; Euclidean norm of the logged u_i",
                agent=i,
                holds=True,
                text={"startup": STARTUP},
            )


@register_check
def effort_check(R: Rows, inp: CheckInput) -> None:
    """The effort rows of a bound table (:func:`effort_rows` on its trajectory).

    Parameters
    ----------
    R : Rows
        Rows to append to.
    inp : CheckInput
        The table's inputs.
    """
    dm = inp.view.dims
    effort_rows(R, inp.view, dm.N, dm.n)
