"""The Dask client a study runs on: a given scheduler, else a new local cluster.

The local cluster runs single-threaded worker processes on 127.0.0.1 with the settings of
:data:`LOCAL_CLUSTER_CONFIG` and serves no HTTP (:mod:`sweep.nohttp`); the search layer
runs its points on the same client.
"""

from __future__ import annotations

import os
from typing import Any

from core.errors import UsageError

#: Dask settings of the local cluster. Each process's event loop wakes up for these
#: timers, and on two cores a wake-up takes the core from a sample: no statistical
#: profiler sampling each task's stack every 10 ms, memory polled every second, the
#: loop's responsiveness tick every second (default 20 ms), the system monitor (CPU and
#: network counters for the dashboard, which a study does not start) every 5 s. The
#: workers' environment keeps Dask's one-thread caps but not its MALLOC_TRIM_THRESHOLD_:
#: with it glibc maps and unmaps every array above 128 KiB, about 5,000 page faults and
#: 11 ms of kernel time per sample of studies/faults.toml against 10 faults without
#: (docs/studies.md, 'Cost of a sample')
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.nanny.pre-spawn-environ": {
        "OMP_NUM_THREADS": 1,
        "MKL_NUM_THREADS": 1,
        "OPENBLAS_NUM_THREADS": 1,
    },
    # no HTTP pages: every Dask node opens an HTTP server; with no routes it serves none
    "distributed.scheduler.http.routes": [],
    "distributed.worker.http.routes": [],
}


def dask_client(scheduler: str | None, workers: int | None = None) -> Any:
    """A client of ``scheduler`` (or ``$DASK_SCHEDULER``), else of a new local cluster
    with ``workers`` single-threaded worker processes (default one per core).

    Parameters
    ----------
    scheduler : str or None
        A Dask scheduler address (``tcp://host:port``); None: ``$DASK_SCHEDULER``, else a
        local cluster.
    workers : int or None
        Worker processes of the local cluster (default one per core; not used with a
        scheduler).

    Raises
    ------
    UsageError
        The scheduler does not answer: names its address and the fix.
    """
    from distributed import Client

    address = scheduler_address(scheduler)
    if address:
        try:
            return Client(address)
        except (OSError, ValueError) as exc:  # refused or timed out: name the address and the fix
            raise UsageError(
                f"Dask scheduler {address}: cannot connect ({' '.join(str(exc).split())[:200]}); "
                "start `dask scheduler` and `dask worker` there, or unset DASK_SCHEDULER"
            ) from exc
    return _local_client(workers)


def scheduler_address(scheduler: str | None) -> str | None:
    """The scheduler's address (``scheduler``, else ``$DASK_SCHEDULER``; None: a local
    cluster), checked before anything connects or is written.

    Parameters
    ----------
    scheduler : str or None
        An address given by the caller.

    Raises
    ------
    UsageError
        Not ``scheme://host:port`` with a scheme Dask knows and a port in 1..65535.
    """
    address = scheduler or os.environ.get("DASK_SCHEDULER")
    if not address:
        return None
    from distributed.comm import get_address_host_port
    from distributed.comm.addressing import parse_address
    from distributed.comm.registry import backends

    where = "scheduler" if scheduler else "DASK_SCHEDULER"
    try:
        scheme, _ = parse_address(address, strict=True)
        host, port = get_address_host_port(address)
    except (ValueError, TypeError) as exc:
        problem = " ".join(str(exc).split())[:200]
    else:
        if scheme not in backends:
            problem = f"unknown scheme {scheme!r}"
        elif not host or not 1 <= port <= 65535:
            problem = "needs a host and a port in 1..65535"
        else:
            return address
    raise UsageError(
        f"{where}={address[:200]!r} is not a Dask scheduler address ({problem}): give "
        f"tcp://HOST:PORT or tls://HOST:PORT, or unset {where} for a local cluster"
    )


def _local_client(workers: int | None) -> Any:
    """A client of a new local cluster on 127.0.0.1 that serves no HTTP.

    Dask's scheduler and workers each start an HTTP server whatever the dashboard
    settings (the scheduler on port 8787 when ``dashboard_address`` is None): here the
    scheduler's binds a free port of 127.0.0.1 instead, the servers have no routes
    (:data:`LOCAL_CLUSTER_CONFIG`), and both stop listening before the first task.

    Parameters
    ----------
    workers : int or None
        Single-threaded worker processes (default one per core).
    """
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set(LOCAL_CLUSTER_CONFIG):  # the nannies hand it to their workers
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            worker_dashboard_address=None,
            scheduler_kwargs={"dashboard": False},
        )
    from sweep.nohttp import NoHttp, stop_scheduler_http

    client = Client(cluster)
    client.run_on_scheduler(stop_scheduler_http)
    client.register_plugin(NoHttp())
    return client


def close_client(client: Any, own_cluster: bool) -> None:
    """Close ``client``, and its cluster when the run started that cluster.

    Parameters
    ----------
    client : distributed.Client
        From :func:`dask_client`.
    own_cluster : bool
        Whether the cluster is the run's own local one (:attr:`sweep.run.RunOptions.own_cluster`);
        a scheduler given by address is left running.
    """
    cluster = client.cluster if own_cluster else None
    client.close()
    if cluster is not None:
        cluster.close()
