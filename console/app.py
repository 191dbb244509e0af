"""Wiring: a scenario file -> console scenario -> gains -> per-agent engine -> session -> server.

``python -m console serve SCENARIO`` (``make console``) calls :func:`open_console` and
:func:`serve`; tests call :func:`open_console` and run the :class:`~console.server.Hub`
on a port of their own.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from console.engine import CONSOLE_RISE, LiveLoop
from console.record import Recorder
from console.scenario import BIAS_MAX, console_scenario, console_table
from console.server import MAX_FRAME_BYTES, Hub, create_app, is_loopback
from console.session import Session
from core.artifacts import OUT_ROOT
from core.errors import UsageError


@dataclass
class Console:
    """An opened console: its scenario table, loop, session and hub."""

    table: dict
    loop: LiveLoop
    session: Session
    hub: Hub
    out: Path


def open_console(
    path: str | Path,
    *,
    out_root: str | Path | None = None,
    bias_max: float = BIAS_MAX,
    fps: float = 30.0,
    allow_remote: bool = False,
    hosts: Sequence[str] = (),
    rise: float = CONSOLE_RISE,
) -> Console:
    """Build everything a console needs for the scenario file at ``path``.

    Parameters
    ----------
    path : str or Path
        A scenario file (default of ``make console``: the paper's).
    out_root : str or Path, optional
        Where gains and records go (``<out_root>/<name>-console/``; default ``out/``).
    bias_max : float
        Largest bias component the operator may add.
    fps : float
        Frames per second streamed to the pages (20-60).
    allow_remote : bool
        Accept non-loopback peers.
    hosts : sequence of str
        Host names a request may name besides the loopback ones (``--allow-remote HOST``).
    rise : float
        Rise time (s) of the shaped changes of u0 (``--rise``; > 0).

    Raises
    ------
    ToolkitError
        A bad scenario, a failed synthesis or build: one line.
    """
    from generated import api

    if not (math.isfinite(rise) and rise > 0):
        raise UsageError(f"--rise: {rise:g} (expected a rise time in seconds > 0)")
    table = console_table(path, bias_max)
    sc = console_scenario(path, table)
    root = Path(out_root or OUT_ROOT)
    gains, _ = api.ensure_gains(sc, root)
    loop = LiveLoop(sc, gains, bias_max, rise=rise)
    out = root / sc.name
    session = Session(loop, recorder=Recorder(out, table, loop))
    hub = Hub(session, loop.limits, fps=fps, allow_remote=allow_remote, hosts=hosts, title=sc.name)
    return Console(table, loop, session, hub, out)


def check_host(host: str, allow_remote: bool) -> None:
    """Refuse to bind a non-loopback address unless remote peers are allowed.

    Parameters
    ----------
    host : str
        The address to bind.
    allow_remote : bool
        ``--allow-remote`` was given.

    Raises
    ------
    UsageError
        One line naming ``--host`` and the fix.
    """
    if not is_loopback(host) and not allow_remote:
        raise UsageError(f"--host {host}: not a loopback address (add --allow-remote to serve it)")


def serve(console: Console, host: str = "127.0.0.1", port: int = 8765) -> None:
    """Serve the console until SIGINT or SIGTERM, then end the process (exit status 0).

    Parameters
    ----------
    console : Console
    host : str
        Address to bind; a non-loopback one needs ``allow_remote``.
    port : int
    """
    import uvicorn

    check_host(host, console.hub.allow_remote)
    print(f"console: http://{host}:{port}/  (Ctrl-C stops it)", flush=True)
    try:
        uvicorn.Server(uvicorn_config(create_app(console.hub), host, port)).run()
    except KeyboardInterrupt:  # Ctrl-C (uvicorn raises it again once it has stopped)
        pass
    finally:
        # the process ends here: the integrator's child is killed, and the interpreter's
        # own teardown (0.7 s unloading the compiled libraries) is skipped, so SIGINT and
        # SIGTERM stop the console within a second (nothing is left to write: records
        # are written before their reply)
        console.loop.close()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)


def uvicorn_config(app: Any, host: str, port: int) -> Any:
    """The uvicorn configuration the console is served with.

    WebSocket messages above :data:`~console.server.MAX_FRAME_BYTES` are refused by the
    protocol layer (close 1009) from the frame's header, before their payload is read.

    Parameters
    ----------
    app : ASGI application
        From :func:`~console.server.create_app`.
    host : str
        Address to bind.
    port : int
    """
    import uvicorn

    return uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level="warning",
        ws="websockets-sansio",
        ws_max_size=MAX_FRAME_BYTES,
    )
