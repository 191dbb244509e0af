"""A synthetic trajectory in the ``trajectory.csv`` format (tests and figure development).

Analytic signals with known answers: the leader of the paper (η0 = (2 − 2cos t, 2 sin t)),
observer errors ē_ηi = c_i e^{−a t}, tracking errors e_ti = c_i e^{−βt}, so decay rates,
entering times and suprema are known in closed form.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from verify.signals import Signal, leader_column


def synthetic_trajectory(
    N: int = 5,
    horizon: float = 20.0,
    step: float = 0.01,
    obs_rate: float = 1.0,
    track_rate: float = 2.0,
    Lambda: float = 40.0,
    C0: np.ndarray | None = None,
    b0: np.ndarray | None = None,
) -> pd.DataFrame:
    """Build a DataFrame with every ``trajectory.csv`` column, n = m = 2.

    Parameters
    ----------
    N : int
        Followers.
    horizon, step : float
        Time grid.
    obs_rate : float
        ‖ē_ηi‖ = ‖c_i‖ e^{−obs_rate t}.
    track_rate : float
        e_ti = c_i e^{−track_rate t}.
    Lambda : float
        λ_ir used for χ = ė + λe.
    C0 : ndarray, optional
        Defaults to the paper's [[1, 1], [2, 2]].
    b0 : ndarray, optional
        (N, 2) formation offsets; default the paper's reading.

    Returns
    -------
    DataFrame
    """
    C0 = np.array([[1.0, 1.0], [2.0, 2.0]]) if C0 is None else np.asarray(C0, float)
    if b0 is None:
        b0 = np.array([[4, 0], [1, 4], [-3, 2], [2, -4], [-3, -2]], float)[:N]
    t = np.arange(0.0, horizon + step / 2, step)
    cols: dict[str, np.ndarray] = {"t": t}
    eta0 = np.stack([2 - 2 * np.cos(t), 2 * np.sin(t)], axis=1)
    for k in range(2):
        cols[leader_column(k + 1)] = eta0[:, k]
    V1 = np.zeros_like(t)
    tau = np.pi / 2 - t  # the paper's formation angle for this leader
    R = np.stack([[np.cos(tau), -np.sin(tau)], [np.sin(tau), np.cos(tau)]])  # 2×2×K
    for i in range(N):
        c = np.array([1.0 + 0.2 * i, -0.5 + 0.1 * i])
        ebar = c[None, :] * np.exp(-obs_rate * t)[:, None]
        eta = eta0 + ebar
        b = np.einsum("abk,b->ka", R, b0[i])
        ce = np.array([5.0 + i, -3.0 + 0.5 * i])
        et = ce[None, :] * np.exp(-track_rate * t)[:, None]
        etd = -track_rate * et
        chi = etd + Lambda * et
        p = eta @ C0.T + b + et
        q = np.gradient(p, t, axis=0)
        blocks = {
            Signal.P: p,
            Signal.Q: q,
            Signal.ETA: eta,
            Signal.MU: np.zeros_like(eta),
            Signal.THETAHAT: np.repeat((1.0 - np.exp(-t))[:, None], 2, axis=1),
            Signal.U: -20 * chi,
            Signal.B: b,
            Signal.ET: et,
            Signal.EETA: ebar,
            Signal.CHI: chi,
        }
        for r in range(2):
            for sig, x in blocks.items():
                cols[sig.column(i + 1, r + 1)] = x[:, r]
        cols[Signal.PHI.column(i + 1)] = np.exp(-2 * t)
        cols[Signal.GHAT.column(i + 1)] = 1.0 + 0.05 * (1 - np.exp(-t))
        cols[Signal.V2.column(i + 1)] = 0.5 * 8.0 * np.sum(chi**2, axis=1) + 1.0
        V1 += np.sum(ebar**2, axis=1)
    cols["V1"] = V1
    return pd.DataFrame(cols)
