"""The console's web server: one page, one WebSocket, one loop shared by every page.

Starlette (ASGI routing, static files, WebSockets) served by uvicorn. The event loop
only exchanges messages: every tick of the :class:`~console.session.Session` (the
integrator calls) and every command runs on the session's own thread
(:class:`~console.worker.Worker`), in order, so a command still falls between two
integrator calls without locks and a long call never stops the sockets. The loop task
asks for a tick at ``fps`` and hands the frame to every page's writer; while a tick is
still running, the pages get the last frame again with ``busy`` (the seconds the
integrator call has run), so a page always knows whether the server is alive. A slow
page only misses frames (each page keeps the newest), it never slows the loop.
Replies (errors, saves) are queued per page and never dropped below
:data:`MAX_REPLIES`.

**Dead-man's handle.** The driving page re-sends a non-zero command at least every
:data:`KEEPALIVE` seconds while it is held; when :data:`DEADMAN` seconds pass without
one, or the driving page closes, or another page takes over, the command goes back to
0 (through the ramps, as any change). **Saves** are limited to one at a time and one
per :data:`SAVE_INTERVAL` seconds of wall time.

Roles: the first page to send ``drive`` drives; the others watch (their commands get
an error naming the page's drive button) until the driver's page closes; every frame says
whether a page drives (``driven``), and a watcher's drive button then takes over.
Closing the driving page sets u0 back to 0; it stops nothing else.
Connections from addresses that are not loopback are refused unless the server was
started with ``allow_remote``; a page or WebSocket whose ``Host`` header is not a loopback
name at the serving port (or one of ``hosts``) is refused (DNS rebinding: another site's
name resolved to 127.0.0.1 cannot drive); a WebSocket whose ``Origin`` is not the page's
own host is refused too (another site open in the same browser cannot drive). Saves run
on one record worker thread (:class:`~console.record.Recorder`), never on the loop's.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import math
import time
from collections import deque
from collections.abc import AsyncIterator, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, PlainTextResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketState

from console.protocol import (
    DRIVER_ONLY,
    MAX_MESSAGE_BYTES,
    SCALES,
    Command,
    Limits,
    MessageError,
    parse_message,
)
from console.session import PEAK_BOUND, PEAK_FROM, Session
from console.worker import Worker

STATIC = Path(__file__).parent / "static"
#: frame rates the page may be streamed at (the issue's 20-60 Hz)
FPS_RANGE = (20.0, 60.0)
#: replies kept per page before the oldest are dropped (a flood's errors all fit)
MAX_REPLIES = 4096
#: largest WebSocket message the protocol layer reads (uvicorn ``ws_max_size``): a text of
#: MAX_MESSAGE_BYTES characters in UTF-8 (at most 4 bytes each); larger ones close with 1009
MAX_FRAME_BYTES = 4 * MAX_MESSAGE_BYTES
#: Host names every console accepts (with the serving port)
LOOPBACK_NAMES = frozenset({"127.0.0.1", "localhost", "::1"})
#: seconds between two sends of a held non-zero command by the driving page (its keepalive)
KEEPALIVE = 0.2
#: seconds without a command from the driving page after which a non-zero u0 returns to 0
DEADMAN = 0.5
#: a tick running longer than this (s) makes the pages get the last frame with ``busy``
BUSY_AFTER = 0.25
#: shortest wall time (s) between two saves (a record holds the whole log so far)
SAVE_INTERVAL = 10.0


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


def host_name(host: str) -> str:
    """A host name as a ``Host`` header's parsed name: lower case, IPv6 without brackets.

    Parameters
    ----------
    host : str
        ``example.org``, ``[::1]``, ``::1``...
    """
    return host.strip().lower().removeprefix("[").removesuffix("]")


def host_refusal(header: str | None, port: int | None, names: frozenset[str]) -> str:
    """Why a request's ``Host`` header is refused, or ``""`` when it is accepted.

    Accepted: a loopback name (:data:`LOOPBACK_NAMES`) or one of ``names``, with the
    serving port (80 when the header gives none).

    Parameters
    ----------
    header : str or None
        The request's ``Host`` header.
    port : int or None
        The port the server listens on (None: not checked).
    names : frozenset of str
        Further accepted names (:func:`host_name` form).
    """
    try:
        parts = urlsplit("//" + (header or ""))
        name, given = parts.hostname, parts.port or 80
    except ValueError:
        name, given = None, None
    if name and (name in LOOPBACK_NAMES or name in names) and port in (None, given):
        return ""
    shown = header if header is None or len(header) <= 40 else header[:37] + "..."
    return f"Host {shown!r} is not a loopback name; serve with --allow-remote <host> to accept it"


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
    hosts : iterable of str
        ``Host`` names accepted besides the loopback ones (``--allow-remote HOST``).
    title : str
        Shown on the page (the scenario's name).
    deadman : float or None
        Seconds without a command from the driving page after which a non-zero u0
        returns to 0 (:data:`DEADMAN`); None: never (scripted clients in tests).
    save_interval : float
        Shortest wall time between two saves (:data:`SAVE_INTERVAL`).
    """

    def __init__(
        self,
        session: Session,
        limits: Limits,
        fps: float = 30.0,
        allow_remote: bool = False,
        title: str = "",
        hosts: Iterable[str] = (),
        deadman: float | None = DEADMAN,
        save_interval: float = SAVE_INTERVAL,
    ) -> None:
        if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
            raise MessageError(f"--fps: {fps:g} (expected {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g})")
        self.session, self.limits, self.fps = session, limits, fps
        self.allow_remote, self.title = allow_remote, title
        self.hosts = frozenset(host_name(h) for h in hosts)
        self.deadman, self.save_interval = deadman, save_interval
        self.records = ThreadPoolExecutor(max_workers=1, thread_name_prefix="console-record")
        self.worker = Worker()
        self.pages: set[Page] = set()
        self.driver: Page | None = None
        self.frames = 0
        self.tick_seconds: deque = deque(maxlen=256)
        self.last_frame: dict[str, Any] | None = None
        self.tick_started: float | None = None  # perf_counter of the tick in progress
        self.u0_wall = 0.0  # perf_counter of the driving page's last u0 message
        self.u0_held = False  # whether the command it holds is non-zero
        self.save_wall: float | None = None  # perf_counter of the last save accepted
        self.saving = False

    # ---------------------------------------------------------------- loop
    async def run(self) -> None:
        """Tick the session at ``fps`` (on the worker) and hand each frame to every page,
        until cancelled; meanwhile :meth:`watch` keeps the pages informed."""
        period = 1.0 / self.fps
        nxt = time.perf_counter()
        watcher = asyncio.create_task(self.watch())
        try:  # a frame before the first tick (which may wait for the integrator to start)
            self.last_frame = await asyncio.wrap_future(self.worker.submit(self.session.frame))
            while True:
                t0 = self.tick_started = time.perf_counter()
                frame = await asyncio.wrap_future(self.worker.submit(self._tick))
                self.tick_started = None
                self.tick_seconds.append(time.perf_counter() - t0)
                self.frames += 1
                self.last_frame = frame
                self._broadcast(frame)
                nxt += period
                delay = nxt - time.perf_counter()
                if delay < -period:  # fell behind: do not burst to catch up
                    nxt, delay = time.perf_counter(), 0.0
                await asyncio.sleep(max(delay, 0.0))
        finally:
            watcher.cancel()

    def _tick(self) -> dict[str, Any]:
        """One tick on the worker; an exception holds the loop and the frame says why."""
        try:
            return self.session.tick()
        except Exception as exc:  # noqa: BLE001 - the loop must survive; the page says why
            self.session.loop.failure = f"{type(exc).__name__}: {exc}"
            return self.session.frame()

    async def watch(self) -> None:
        """Every frame period: the last frame again with ``busy`` while a tick runs long,
        and the dead-man's handle (:data:`DEADMAN`)."""
        period = 1.0 / self.fps
        while True:
            await asyncio.sleep(period)
            now = time.perf_counter()
            started = self.tick_started
            if started is not None and now - started > BUSY_AFTER and self.last_frame:
                self._broadcast({**self.last_frame, "busy": now - started})
            late = self.deadman is not None and now - self.u0_wall > self.deadman
            if self.driver is not None and self.u0_held and late:
                self.release(self.driver, f"no command for {self.deadman:g} s")

    def release(self, page: Page | None, why: str) -> None:
        """Set u0 back to 0 (through the ramps) and tell ``page`` why.

        Parameters
        ----------
        page : Page or None
            The page that drove (None: it has gone).
        why : str
            One line, shown by the page.
        """
        self.u0_held = False
        zero = Command("u0", values=(0.0,) * self.limits.p)
        self.worker.submit(self.session.handle, zero)
        if page is not None:
            page.push_reply({"type": "released", "reason": why})

    def _broadcast(self, frame: dict[str, Any]) -> None:
        text = json.dumps(_finite(frame), separators=(",", ":"))
        for page in self.pages:
            role = "driver" if page is self.driver else "watcher"
            driven = "true" if self.driver is not None else "false"
            page.push_frame(
                text[:-1] + f',"role":"{role}","pages":{len(self.pages)},"driven":{driven}}}'
            )

    # ---------------------------------------------------------------- pages
    def allowed(self, host: str | None) -> bool:
        """Whether a peer may connect.

        Parameters
        ----------
        host : str or None
            The peer's address.
        """
        return self.allow_remote or is_loopback(host)

    def refusal(self, conn: Request | WebSocket) -> str:
        """Why a page or socket is refused (its peer, ``Host`` or ``Origin``), or ``""``.

        Parameters
        ----------
        conn : Request or WebSocket
            The connection, before anything is served or accepted.
        """
        peer = conn.client.host if conn.client else None
        if not self.allowed(peer):
            return f"peer {peer} is not a loopback address; serve with --allow-remote to accept it"
        server = conn.scope.get("server")
        port = server[1] if server else None
        why = host_refusal(conn.headers.get("host"), port, self.hosts)
        if why or conn.scope["type"] != "websocket" or _same_origin(conn):
            return why
        origin = (conn.headers.get("origin") or "")[:40]
        return f"Origin {origin!r} is not this page's host"

    async def serve_page(self, ws: WebSocket) -> None:
        """One page's socket: accept, read and answer its messages, clean up on close.

        Parameters
        ----------
        ws : WebSocket
            The page's socket (refused, saying why, if its peer, Host or Origin is).
        """
        why = self.refusal(ws)
        if why:
            await _refuse(ws, why)
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
                self.release(None, "the driving page closed")
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
                    raise MessageError(
                        "drive: another page drives (the drive button takes over once it closes)"
                    )
                if self.driver is not page:  # a new driver starts from u0 = 0
                    self.driver = page
                    self.release(None, "a new page drives")
                page.push_reply({"type": "role", "role": "driver"})
                return
            if cmd.kind in DRIVER_ONLY and page is not self.driver:
                raise MessageError(
                    f"{cmd.kind}: this page watches (press drive to take over when no page drives)"
                )
            if cmd.kind == "save":
                self._save(page)
                return
            if cmd.kind == "u0":
                self.u0_wall, self.u0_held = time.perf_counter(), any(cmd.values)
            elif cmd.kind == "reset":
                self.u0_held = False
            done = asyncio.wrap_future(self.worker.submit(self.session.handle, cmd))
            done.add_done_callback(lambda f: self._answer(page, f, ""))
        except MessageError as exc:
            page.push_reply({"type": "error", "message": str(exc)})
        except Exception as exc:  # noqa: BLE001 - one page's message must not stop the server
            page.push_reply({"type": "error", "message": f"{type(exc).__name__}: {exc}"})

    @staticmethod
    def _answer(page: Page, done: asyncio.Future, prefix: str) -> None:
        """A command's reply (if any), or its error, to the page that sent it."""
        if done.cancelled():
            return
        exc = done.exception()
        if exc is None:
            if done.result() is not None:
                page.push_reply(done.result())
            return
        text = str(exc) if isinstance(exc, MessageError) else f"{type(exc).__name__}: {exc}"
        page.push_reply({"type": "error", "message": prefix + text})

    def _save(self, page: Page) -> None:
        """Snapshot the log on the worker; write the record on the record thread; reply when
        done. One save at a time, at most one per :attr:`save_interval` seconds."""
        now = time.perf_counter()
        if self.saving:
            raise MessageError("save: a save is being written (wait for its reply)")
        if self.save_wall is not None and now - self.save_wall < self.save_interval:
            wait = self.save_interval - (now - self.save_wall)
            raise MessageError(
                f"save: the last save was {now - self.save_wall:.1f} s ago "
                f"(at most one save every {self.save_interval:g} s; try again in {wait:.1f} s)"
            )
        self.saving, self.save_wall = True, now
        loop = asyncio.get_running_loop()

        def write() -> dict[str, Any]:
            job = self.worker.submit(self.session.save_job).result()  # the snapshot, in order
            return job()

        def done(f: asyncio.Future) -> None:
            self.saving = False
            page.push_reply(_saved(f))

        loop.run_in_executor(self.records, write).add_done_callback(done)

    async def _write(self, page: Page) -> None:
        """Send a page its replies (all, in order) and then its newest frame.

        Each send yields to the event loop first, so a connection that was lost is seen
        (the socket's disconnect arrives) before the next send, and the first failed
        send ends the writer: a dead socket is not written to again.
        """
        try:
            while True:
                await page.wake.wait()
                page.wake.clear()
                while page.replies or page.frame is not None:
                    await asyncio.sleep(0)
                    if page.ws.client_state != WebSocketState.CONNECTED:
                        return
                    if page.replies:
                        text = page.replies.popleft()
                    else:
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
            "keepalive": KEEPALIVE,
            "deadman": self.deadman,
            "peak_bound": PEAK_BOUND,
            "peak_from": PEAK_FROM,
            "scales": list(SCALES),
            "rise": loop.rise,
        }


def _saved(done: Future) -> dict[str, Any]:
    """A finished save's reply: ``saved``, or the error that stopped it."""
    exc = done.exception()
    if exc is None:
        return done.result()
    text = str(exc) if isinstance(exc, MessageError) else f"{type(exc).__name__}: {exc}"
    return {"type": "error", "message": f"save: {text}"}


async def _refuse(ws: WebSocket, why: str) -> None:
    """Refuse a socket before accepting it: HTTP 403 with ``why`` where the server can
    send one (uvicorn's ``websocket.http.response``), else close 1008 with ``why``."""
    if "websocket.http.response" in ws.scope.get("extensions", {}):
        await ws.send_denial_response(PlainTextResponse(why + "\n", 403))
    else:
        await ws.close(code=1008, reason=why.encode("utf-8")[:123].decode("utf-8", "ignore"))


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
            hub.worker.stop()

    def guarded(name: str, media: str):
        async def endpoint(request: Request) -> Response:
            why = hub.refusal(request)
            if why:
                return PlainTextResponse(why + "\n", 403)
            return FileResponse(STATIC / name, media_type=media)

        return endpoint

    routes = [
        Route("/", guarded("index.html", "text/html")),
        Route("/console.js", guarded("console.js", "text/javascript")),
        WebSocketRoute("/ws", hub.serve_page),
    ]
    return Starlette(routes=routes, lifespan=lifespan)
