"""The session's own thread: every integrator call and command runs here, in order.

The server's event loop only exchanges messages: it hands each tick and each validated
command to :class:`Worker` and awaits the answer, so an integrator call that takes
seconds never stops the pages' sockets, the frames sent meanwhile or a signal. One
thread runs them all in the order they were submitted, so a command still falls
between two integrator calls without locks. The thread is a daemon: a process that is
told to stop does not wait for a call in progress.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any


class Worker:
    """One daemon thread running submitted calls one at a time, in order.

    Parameters
    ----------
    name : str
        The thread's name.
    """

    def __init__(self, name: str = "console-loop") -> None:
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.thread.start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        """Run ``fn(*args)`` after every call submitted before; its future.

        Parameters
        ----------
        fn : callable
        *args
            Its arguments.
        """
        fut: Future = Future()
        self._jobs.put((fut, fn, args))
        return fut

    def stop(self) -> None:
        """Let the thread end after the calls already submitted (it does not wait)."""
        self._jobs.put(None)

    def _run(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            fut, fn, args = job
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                fut.set_result(fn(*args))
            except BaseException as exc:  # noqa: BLE001 - the submitter reports it
                fut.set_exception(exc)
