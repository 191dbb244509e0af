"""Stop the HTTP servers Dask starts in every scheduler and worker of a local cluster.

Dask's scheduler and workers each listen on an HTTP port whatever their dashboard
settings; a study's local cluster asks for no HTTP (:func:`sweep.cluster._local_client`).
Imported only when that cluster starts (it imports :mod:`distributed`).
"""

from __future__ import annotations

from typing import Any

from distributed import WorkerPlugin


class NoHttp(WorkerPlugin):
    """Worker plugin that stops the worker's HTTP server, also in a restarted worker."""

    name = "sweep-no-http"

    def setup(self, worker: Any) -> None:
        """Stop listening (runs on the worker's event loop).

        Parameters
        ----------
        worker : distributed.Worker
            The worker the plugin is added to.
        """
        worker.http_server.stop()


def stop_scheduler_http(dask_scheduler: Any) -> None:
    """Stop the scheduler's HTTP server (``Client.run_on_scheduler``: on its event loop).

    Parameters
    ----------
    dask_scheduler : distributed.Scheduler
        The scheduler.
    """
    dask_scheduler.http_server.stop()
