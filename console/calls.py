"""Calls that may not return in time: run in a child process, killed past a wall-time budget.

The native integrator is one C call that Python cannot interrupt: an attempt that needs
10⁶ steps runs for tens of seconds whatever the caller wants. :class:`ChildCalls` runs
such calls in one child process (``spawn``: no thread of this process is copied) and
waits for the answer at most ``timeout`` seconds of wall time; past it the child is
killed (SIGKILL), a fresh one is started in the background for the next call, and
:class:`CallTimeout` is raised. Arguments and results travel pickled through a pipe.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import threading
from collections.abc import Callable
from typing import Any


#: longest wall time a new child may take to start and make its first (``init``) call
START_SECONDS = 120.0


class CallTimeout(Exception):
    """A call ran past its wall-time budget; the child that ran it was killed."""


def _serve(conn: Any, init: tuple | None) -> None:
    """The child's loop: ``(fn, args)`` in, ``(ok, result or error text)`` out, until EOF."""
    try:
        if init is not None:
            init[0](*init[1])
        conn.send((True, None))
    except Exception as exc:  # noqa: BLE001 - the parent reports it
        conn.send((False, f"{type(exc).__name__}: {exc}"))
        return
    while True:
        try:
            fn, args = conn.recv()
        except (EOFError, OSError):
            return
        try:
            out = (True, fn(*args))
        except Exception as exc:  # noqa: BLE001 - the parent reports it
            out = (False, f"{type(exc).__name__}: {exc}")
        conn.send(out)


class ChildCalls:
    """One child process that runs calls one at a time, each within a wall-time budget.

    Parameters
    ----------
    name : str
        The child's process name (``ps``).
    init : (callable, tuple), optional
        A call every new child makes first (loading a library), outside any budget.
    """

    def __init__(self, name: str = "console-integrator", init: tuple | None = None) -> None:
        self.name, self.init = name, init
        self._ctx = mp.get_context("spawn")
        self._lock = threading.Lock()
        self._proc: Any = None
        self._conn: Any = None
        self.kills = 0  #: children killed past their budget

    def _start(self) -> None:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_serve, args=(child, self.init), name=self.name, daemon=True)
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent
        ok, why = parent.recv() if parent.poll(START_SECONDS) else (False, "no answer")
        if not ok:
            self._proc, self._conn = None, None
            proc.kill()
            proc.join(timeout=5)
            parent.close()
            raise RuntimeError(f"the integrator process did not start: {why}")

    def warm(self) -> None:
        """Start the child now (the first call would otherwise wait for its start-up)."""
        with self._lock:
            if self._proc is None:
                self._start()

    def call(self, fn: Callable[..., Any], args: tuple, timeout: float) -> Any:
        """``fn(*args)`` in the child; its result, or :class:`CallTimeout` after ``timeout`` s.

        Parameters
        ----------
        fn : callable
            A module-level function (pickled by name).
        args : tuple
            Its arguments (pickled).
        timeout : float
            Wall-time budget in seconds, counted from when the call is sent.

        Raises
        ------
        CallTimeout
            The budget ran out: the child was killed (a new one starts for the next call).
        RuntimeError
            ``fn`` raised in the child (its type and text), or the child died.
        """
        with self._lock:
            if self._proc is None or not self._proc.is_alive():
                self._start()
            conn = self._conn
            conn.send((fn, args))
            if not conn.poll(timeout):
                self._kill()
                raise CallTimeout(f"no answer within {timeout:g} s of wall time")
            try:
                ok, out = conn.recv()
            except (EOFError, OSError):
                self._kill()
                raise RuntimeError("the integrator process died") from None
        if not ok:
            raise RuntimeError(out)
        return out

    def _kill(self) -> None:
        """Kill the child (the lock is held) and start the next one in the background."""
        proc, self._proc = self._proc, None
        self.kills += 1
        if proc is not None:
            proc.kill()
            proc.join(timeout=5)
        if self._conn is not None:
            self._conn.close()
        threading.Thread(target=self._rewarm, daemon=True, name=f"{self.name}-restart").start()

    def _rewarm(self) -> None:
        with contextlib.suppress(RuntimeError):  # the next call tries again and says why
            self.warm()

    def close(self) -> None:
        """Stop the child (at shutdown); later calls start a new one."""
        with self._lock:
            proc, self._proc = self._proc, None
            if self._conn is not None:
                self._conn.close()
                self._conn = None
        if proc is not None:
            proc.kill()
            proc.join(timeout=5)

