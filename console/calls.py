"""Calls that may not return in time: run in a child process, killed past a wall-time budget.

The native integrator is one C call that Python cannot interrupt: an attempt that needs
10⁶ steps runs for tens of seconds whatever the caller wants. :class:`ChildCalls` runs
such calls in one child process (a new interpreter: nothing of this one is copied) and
waits for the answer at most ``timeout`` seconds of wall time; past it the child is
killed (SIGKILL), a fresh one is started in the background for the next call, and
:class:`CallTimeout` is raised. Arguments and results travel pickled through a pipe.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

#: longest wall time a new child may take to start and make its first (``init``) call
START_SECONDS = 120.0


class CallTimeout(Exception):
    """A call ran past its wall-time budget; the child that ran it was killed."""


def child_main(fd: int) -> None:
    """The child's loop on the socket ``fd``: first the ``init`` call, then ``(fn, args)``
    in, ``(ok, result or error text)`` out, until the parent closes its end or dies.

    Parameters
    ----------
    fd : int
        The child's end of the socket pair (inherited).
    """
    # Ctrl-C reaches the whole group: the parent decides. A child whose parent is gone
    # exits at once, even inside a call (the native driver releases the GIL).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with, args=(os.getppid(),), daemon=True).start()
    conn = Connection(fd)
    try:
        init = conn.recv()
        try:
            if init is not None:
                init[0](*init[1])
            conn.send((True, None))
        except Exception as exc:  # noqa: BLE001 - the parent reports it
            conn.send((False, f"{type(exc).__name__}: {exc}"))
            return
        while True:
            fn, args = conn.recv()
            try:
                out = (True, fn(*args))
            except Exception as exc:  # noqa: BLE001 - the parent reports it
                out = (False, f"{type(exc).__name__}: {exc}")
            conn.send(out)
    except (EOFError, OSError):  # the parent closed its end, or is gone
        return


def _exit_with(parent: int) -> None:
    """End this process as soon as its parent is no longer ``parent``."""
    while os.getppid() == parent:
        time.sleep(0.2)
    os._exit(0)


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
        self._lock = threading.Lock()
        self._proc: Any = None
        self._conn: Any = None
        self.kills = 0  #: children killed past their budget

    def _start(self) -> None:
        """A new child (``python -c``: the caller's ``__main__`` is not run again in it)."""
        ours, theirs = socket.socketpair()
        code = f"from console.calls import child_main; child_main({theirs.fileno()})"
        proc = subprocess.Popen(
            [sys.executable, "-c", code], pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL
        )
        theirs.close()
        conn = Connection(ours.detach())
        self._proc, self._conn = proc, conn
        conn.send(self.init)
        try:
            ok, why = conn.recv() if conn.poll(START_SECONDS) else (False, "no answer")
        except (EOFError, OSError):  # killed while starting (a shutdown)
            ok, why = False, "it ended while starting"
        if not ok:
            self._proc, self._conn = None, None
            proc.kill()
            proc.wait(timeout=5)
            conn.close()
            raise RuntimeError(f"the integrator process did not start: {why}")

    def warm(self) -> None:
        """Start the child now (the first call would otherwise wait for its start-up)."""
        with self._lock:
            if self._proc is None:
                self._start()

    def warm_later(self) -> None:
        """Start the child on a thread of its own (a call made before it is up waits for it,
        outside the call's budget)."""
        threading.Thread(target=self._rewarm, daemon=True, name=f"{self.name}-start").start()

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
            if self._proc is None or self._proc.poll() is not None:
                self._start()
            conn = self._conn
            conn.send((fn, args))
            if not conn.poll(timeout):
                self._kill()
                raise CallTimeout(f"no answer within {timeout:g} s of wall time")
            try:
                ok, out = conn.recv()
            except (EOFError, OSError):
                code = self._proc.wait(timeout=5) if self._proc is not None else None
                self._kill()
                how = f"signal {-code}" if code is not None and code < 0 else f"exit {code}"
                raise RuntimeError(f"the integrator process died ({how})") from None
        if not ok:
            raise RuntimeError(out)
        return out

    def _kill(self) -> None:
        """Kill the child (the lock is held) and start the next one in the background."""
        proc, self._proc = self._proc, None
        self.kills += 1
        if proc is not None:
            proc.kill()
            proc.wait(timeout=5)
        if self._conn is not None:
            self._conn.close()
        threading.Thread(target=self._rewarm, daemon=True, name=f"{self.name}-restart").start()

    def _rewarm(self) -> None:
        with contextlib.suppress(RuntimeError):  # the next call tries again and says why
            self.warm()

    def close(self) -> None:
        """Kill the child now (at shutdown), without waiting for a call in progress: that
        call sees the child die and fails; later calls start a new one."""
        proc = self._proc
        if proc is not None:
            proc.kill()
            proc.wait(timeout=5)
