"""A stand-in loop for the console's server tests, and a server run in a thread.

``FakeLoop`` has the console's bookkeeping (:class:`console.engine.LoopBase`) but
integrates a small numpy model instead of the compiled closed loop: a double-integrator
leader η̇0 = (η0_2, u0), y0 = (η0_1, 0) (with two inputs one double integrator per axis,
y0 = (η0_1, η0_3)), and followers ṗ_i = k g_i (y0 + b_i0 − p_i) +
bias_i (the neighbours' links scale k). Its solution for a held u0 is known in closed
form, which the tests use as truth.
"""

from __future__ import annotations

import socket
import threading
import time
from contextlib import contextmanager

import numpy as np
import uvicorn

from console.engine import Advance, LoopBase, Settings, desired_formation
from console.protocol import Limits
from console.server import DEADMAN, SAVE_INTERVAL, Hub, create_app
from console.session import Session

B0 = np.array([[4.0, 0.0], [0.0, 4.0], [-4.0, 0.0]])
GAIN = 3.0


class FakeLoop(LoopBase):
    """Three followers following a double-integrator leader; optional failure time.

    ``fail_at``: an attempt (numbered below ``fail_attempts``; default: every attempt)
    whose step from a to b has a <= fail_at < b stops at a.
    """

    def __init__(
        self,
        fail_at: float | None = None,
        quantum: float = 0.01,
        fail_attempts: int = 10**9,
        rise: float = 1.0,
        p: int = 1,
    ) -> None:
        N = len(B0)
        limits = Limits(
            N=N,
            n=2,
            p=p,
            u_max=2.0 / np.sqrt(p),
            g_min=0.5,
            bias_max=10.0,
            edges=frozenset({(1, 0), (2, 1), (3, 1), (3, 2)}),
        )
        self.p = p
        nominal = Settings(
            u0=np.zeros(p),
            health=np.ones(N),
            bias=np.zeros((N, 2)),
            weights={(0, -1): 1.0, (1, 0): 1.0, (2, 0): 1.0, (2, 1): 1.0},
        )
        x0 = np.concatenate([np.zeros(2 * p), (B0 + 1.0).ravel()])
        self.fail_at, self.fail_attempts = fail_at, fail_attempts
        self.attempts: list[tuple[float, int]] = []  # (start, attempt) of every call
        super().__init__(limits, quantum, nominal, x0, rise=rise)

    def leader_output(self, x: np.ndarray) -> np.ndarray:
        """y0: (η0_1, 0) for one input, (η0_1, η0_3) for two (a double integrator per axis)."""
        return np.array([x[0], x[2] if self.p > 1 else 0.0])

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        st = self.settings
        y0 = self.leader_output(x)
        P = x[2 * self.p :].reshape(-1, 2)
        dP = GAIN * st.health[:, None] * (y0 + B0 - P) + st.bias
        u = self.u0_at(t)
        lead = np.ravel([[x[2 * k + 1], u[k]] for k in range(self.p)])
        return np.concatenate([lead, dP.ravel()])

    def integrate(
        self, x0: np.ndarray, t_out: np.ndarray, breaks: list[float], attempt: int = 0
    ) -> Advance:
        self.attempts.append((float(t_out[0]), attempt))
        xs, x, steps = [x0.copy()], x0.copy(), 0
        for a, b in zip(t_out[:-1], t_out[1:], strict=True):
            fails = self.fail_at is not None and a <= self.fail_at < b
            if fails and attempt < self.fail_attempts:
                return Advance(t_out[: len(xs)], np.array(xs), f"fake failure at t = {a:g}", steps)
            hs = (b - a) / 4
            for k in range(4):  # RK4
                t = a + k * hs
                k1 = self.rhs(t, x)
                k2 = self.rhs(t + hs / 2, x + hs / 2 * k1)
                k3 = self.rhs(t + hs / 2, x + hs / 2 * k2)
                k4 = self.rhs(t + hs, x + hs * k3)
                x = x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
                steps += 1
            xs.append(x.copy())
        return Advance(t_out, np.array(xs), "", steps)

    def signals(self, x: np.ndarray) -> dict:
        y0 = self.leader_output(x)
        P = x[2 * self.p :].reshape(-1, 2)
        slots = desired_formation(y0, np.array([x[1], x[3] if self.p > 1 else 0.0]), B0)
        return {
            "y0": y0.tolist(),
            "p": P.tolist(),
            "slots": slots.tolist(),
            "et": np.linalg.norm(P - y0 - B0, axis=1).tolist(),
            "est": [0.0] * len(B0),
            "ghat": [1.0] * len(B0),
            "unorm": np.linalg.norm(GAIN * (y0 + B0 - P), axis=1).tolist(),
        }


def free_port() -> int:
    """A free TCP port on 127.0.0.1 (bound and released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def running(hub: Hub, host: str = "127.0.0.1"):
    """Serve ``hub`` on a free loopback port in a thread; yields the port; always stops."""
    port = free_port()
    cfg = uvicorn.Config(
        create_app(hub), host=host, port=port, log_level="warning", ws="websockets-sansio"
    )
    server = uvicorn.Server(cfg)
    th = threading.Thread(target=server.run, daemon=True)
    th.start()
    try:
        t0 = time.monotonic()
        while not server.started:
            if time.monotonic() - t0 > 10 or not th.is_alive():
                raise RuntimeError("console server did not start")
            time.sleep(0.02)
        yield port
    finally:
        server.should_exit = True
        th.join(timeout=10)


def fake_hub(
    fail_at: float | None = None,
    fps: float = 30.0,
    p: int = 1,
    recorder=None,
    deadman: float | None = DEADMAN,
    save_interval: float = SAVE_INTERVAL,
) -> Hub:
    """A hub around a :class:`FakeLoop` (``p`` inputs; an optional recorder for saves).

    ``deadman=None`` for a scripted client that holds a command without keepalives."""
    loop = FakeLoop(fail_at, p=p)
    session = Session(loop, recorder=recorder)
    return Hub(
        session, loop.limits, fps=fps, title="fake", deadman=deadman, save_interval=save_interval
    )
