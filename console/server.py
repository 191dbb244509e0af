"""The console's web server: one page, one WebSocket, one loop shared by every page.

Starlette (ASGI routing, static files, WebSockets) served by uvicorn: the page and
its socket share one asyncio thread with the loop, so a command is applied between
two integrator calls without locks (README, 'Operator console', says why this
library). The loop task ticks the :class:`~console.session.Session` at ``fps`` and
hands the frame to every page's writer; a slow page only misses frames (each page
keeps the newest), it never slows the loop. Replies (errors, saves) are queued per
page and never dropped below :data:`MAX_REPLIES`.

Roles: the first page to send ``drive`` drives; the others watch (their commands get
an error) until the driver's page closes. Closing a page stops nothing else.
Connections from addresses that are not loopback are refused unless the server was
started with ``allow_remote``; a WebSocket whose ``Origin`` is not the page's own
host is refused too (another site open in the same browser cannot drive).
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import math
import time
from collections import deque
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, PlainTextResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from console.protocol import DRIVER_ONLY, Limits, MessageError, parse_message
from console.session import Session

STATIC = Path(__file__).parent / "static"
#: frame rates the page may be streamed at (the issue's 20-60 Hz)
FPS_RANGE = (20.0, 60.0)
#: replies kept per page before the oldest are dropped (a flood's errors all fit)
MAX_REPLIES = 4096


def is_loopback(host: str | None) -> bool:
    """Whether an address is a loopback address.

    Parameters
    ----------
    host : str or None
        The address as the socket reports it (``"localhost"`` counts as loopback).
    """
    if not host:
        return False
    try:
        return ipaddress.ip_address(host.split("%")[0]).is_loopback
    except ValueError:
        return host == "localhost"


@dataclass(eq=False)
class Page:
    """One connected page: its socket, its pending replies and the newest frame."""

    ws: WebSocket
    replies: deque = field(default_factory=lambda: deque(maxlen=MAX_REPLIES))
    frame: str | None = None
    wake: asyncio.Event = field(default_factory=asyncio.Event)

    def push_reply(self, msg: dict[str, Any]) -> None:
        """Queue a reply (never dropped below :data:`MAX_REPLIES`).

        Parameters
        ----------
        msg : dict
            The JSON object to send.
        """
        self.replies.append(json.dumps(msg))
        self.wake.set()

    def push_frame(self, text: str) -> None:
        """Replace the frame waiting to be sent by the newest.

        Parameters
        ----------
        text : str
            The frame as JSON text.
        """
        self.frame = text
        self.wake.set()


class Hub:
    """The loop task and the connected pages.

    Parameters
    ----------
    session : Session
    limits : Limits
        What messages are checked against.
    fps : float
        Frames per second streamed to the pages (20-60).
    allow_remote : bool
        Accept connections from non-loopback addresses.
    title : str
        Shown on the page (the scenario's name).
    """

    def __init__(
        self,
        session: Session,
        limits: Limits,
        fps: float = 30.0,
        allow_remote: bool = False,
        title: str = "",
    ) -> None:
        if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
            raise MessageError(f"--fps: {fps:g} (expected {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g})")
        self.session, self.limits, self.fps = session, limits, fps
        self.allow_remote, self.title = allow_remote, title
        self.pages: set[Page] = set()
        self.driver: Page | None = None
        self.frames = 0
        self.tick_seconds: deque = deque(maxlen=256)

    # ---------------------------------------------------------------- loop
    async def run(self) -> None:
        """Tick the session at ``fps`` and hand each frame to every page, until cancelled."""
        period = 1.0 / self.fps
        nxt = time.perf_counter()
        while True:
            t0 = time.perf_counter()
            try:
                frame = self.session.tick()
            except Exception as exc:  # noqa: BLE001 - the loop must survive; the page says why
                self.session.loop.failure = f"{type(exc).__name__}: {exc}"
                frame = self.session.frame()
            self.tick_seconds.append(time.perf_counter() - t0)
            self.frames += 1
            self._broadcast(frame)
            nxt += period
            delay = nxt - time.perf_counter()
            if delay < -period:  # fell behind: do not burst to catch up
                nxt, delay = time.perf_counter(), 0.0
            await asyncio.sleep(max(delay, 0.0))

    def _broadcast(self, frame: dict[str, Any]) -> None:
        text = json.dumps(_finite(frame), separators=(",", ":"))
        for page in self.pages:
            role = "driver" if page is self.driver else "watcher"
            page.push_frame(text[:-1] + f',"role":"{role}","pages":{len(self.pages)}}}')

    # ---------------------------------------------------------------- pages
    def allowed(self, host: str | None) -> bool:
        """Whether a peer may connect.

        Parameters
        ----------
        host : str or None
            The peer's address.
        """
        return self.allow_remote or is_loopback(host)

    async def serve_page(self, ws: WebSocket) -> None:
        """One page's socket: accept, read and answer its messages, clean up on close.

        Parameters
        ----------
        ws : WebSocket
            The page's socket (closed with 1008 if the peer or its origin is refused).
        """
        if not self.allowed(ws.client.host if ws.client else None) or not _same_origin(ws):
            await ws.close(code=1008)
            return
        await ws.accept()
        page = Page(ws)
        self.pages.add(page)
        page.push_reply({"type": "hello", **self.describe()})
        writer = asyncio.create_task(self._write(page))
        try:
            while True:
                msg = await ws.receive()
                if msg["type"] == "websocket.disconnect":
                    break
                raw = msg.get("text")
                if raw is None:
                    raw = (msg.get("bytes") or b"").decode("utf-8", errors="replace")
                self.on_message(page, raw)
        except WebSocketDisconnect:
            pass
        finally:
            self.pages.discard(page)
            if self.driver is page:
                self.driver = None
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer

    def on_message(self, page: Page, raw: str) -> None:
        """Validate and apply one message; every refusal is an error reply, nothing raises.

        Parameters
        ----------
        page : Page
            The page that sent it (its role decides what it may do).
        raw : str
            The message text.
        """
        try:
            cmd = parse_message(raw, self.limits)
            if cmd.kind == "drive":
                if self.driver is not None and self.driver is not page:
                    raise MessageError("drive: another page drives (it must close first)")
                self.driver = page
                page.push_reply({"type": "role", "role": "driver"})
                return
            if cmd.kind in DRIVER_ONLY and page is not self.driver:
                raise MessageError(
                    f"{cmd.kind}: this page watches (send drive when no page drives)"
                )
            reply = self.session.handle(cmd)
            if reply is not None:
                page.push_reply(reply)
        except MessageError as exc:
            page.push_reply({"type": "error", "message": str(exc)})
        except Exception as exc:  # noqa: BLE001 - one page's message must not stop the server
            page.push_reply({"type": "error", "message": f"{type(exc).__name__}: {exc}"})

    async def _write(self, page: Page) -> None:
        """Send a page its replies (all, in order) and then its newest frame."""
        try:
            while True:
                await page.wake.wait()
                page.wake.clear()
                while page.replies:
                    await page.ws.send_text(page.replies.popleft())
                if page.frame is not None:
                    text, page.frame = page.frame, None
                    await page.ws.send_text(text)
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass

    def describe(self) -> dict[str, Any]:
        """What a page needs to draw the scenario (sizes, ranges, the graph)."""
        lim = self.limits
        loop = self.session.loop
        return {
            "title": self.title,
            "N": lim.N,
            "n": lim.n,
            "p": lim.p,
            "u_max": lim.u_max,
            "g_min": lim.g_min,
            "bias_max": lim.bias_max,
            "edges": sorted(lim.edges),
            "quantum": loop.quantum,
            "fps": self.fps,
            "nominal_health": loop.nominal.health.tolist(),
        }


def _same_origin(ws: WebSocket) -> bool:
    """A browser's ``Origin`` must name the host it connected to (absent: not a browser)."""
    origin = ws.headers.get("origin")
    if origin is None:
        return True
    return urlsplit(origin).netloc == ws.headers.get("host", "")


def _finite(v: Any) -> Any:
    """JSON-safe: NaN and infinities (a diverging state) become null."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_finite(x) for x in v]
    return v


def create_app(hub: Hub) -> Starlette:
    """The ASGI application: ``/`` (the page), ``/console.js``, ``/ws`` (the socket).

    Parameters
    ----------
    hub : Hub
        Runs the loop while the application is up.
    """

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        task = asyncio.create_task(hub.run())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    def guarded(name: str, media: str):
        async def endpoint(request: Request) -> Response:
            if not hub.allowed(request.client.host if request.client else None):
                return PlainTextResponse("loopback only (start with --allow-remote)", 403)
            return FileResponse(STATIC / name, media_type=media)

        return endpoint

    routes = [
        Route("/", guarded("index.html", "text/html")),
        Route("/console.js", guarded("console.js", "text/javascript")),
        WebSocketRoute("/ws", hub.serve_page),
    ]
    return Starlette(routes=routes, lifespan=lifespan)
