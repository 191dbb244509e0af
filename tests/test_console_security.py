"""The console's guards: Host names (DNS rebinding), record folders, saves off the loop,
and WebSocket messages refused by size at the protocol layer.

The server runs with :func:`console.app.uvicorn_config` (what ``python -m console serve``
uses) around :class:`console_fake.FakeLoop`.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import uvicorn
from console_fake import FakeLoop, free_port
from websockets.sync.client import connect

from console.app import uvicorn_config
from console.record import LOG_NAME, TRACE_NAME, Recorder
from console.server import MAX_FRAME_BYTES, Hub, create_app, host_refusal
from console.session import Session


def _hub(recorder=None, hosts: tuple[str, ...] = ()) -> Hub:
    loop = FakeLoop()
    return Hub(Session(loop, recorder=recorder), loop.limits, title="fake", hosts=hosts)


@contextmanager
def _serving(hub: Hub):
    """Serve ``hub`` as the console does, on a free loopback port; yields the port."""
    port = free_port()
    server = uvicorn.Server(uvicorn_config(create_app(hub), "127.0.0.1", port))
    th = threading.Thread(target=server.run, daemon=True)
    th.start()
    try:
        t0 = time.monotonic()
        while not server.started:
            assert time.monotonic() - t0 < 10 and th.is_alive(), "server did not start"
            time.sleep(0.02)
        yield port
    finally:
        server.should_exit = True
        th.join(timeout=10)


def _upgrade(port: int, host: str, origin: str | None = None) -> tuple[socket.socket, bytes]:
    """A raw WebSocket handshake naming ``host``; the socket and the server's answer."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        "GET /ws HTTP/1.1",
        f"Host: {host}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
    ]
    if origin:
        lines.append(f"Origin: {origin}")
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
    answer = b""
    while b"\r\n\r\n" not in answer:
        chunk = sock.recv(4096)
        if not chunk:
            break
        answer += chunk
    return sock, answer


def _get(port: int, host: str) -> bytes:
    """An HTTP GET of / naming ``host``; the whole answer."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(f"GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        out = b""
        while chunk := sock.recv(65536):
            out += chunk
    return out


# --------------------------------------------------------------------------- Host
def test_host_rule() -> None:
    """Loopback names at the serving port pass; other names, other ports do not."""
    for ok in ("127.0.0.1:8793", "localhost:8793", "[::1]:8793", "LOCALHOST:8793"):
        assert host_refusal(ok, 8793, frozenset()) == ""
    assert host_refusal("localhost", 80, frozenset()) == ""
    assert host_refusal("console.lan:8793", 8793, frozenset({"console.lan"})) == ""
    for bad in ("attacker.example:8793", "127.0.0.1:9999", "localhost", "[::1", "", None):
        assert host_refusal(bad, 8793, frozenset()), bad
    assert host_refusal("attacker.example:8793", 8793, frozenset()) == (
        "Host 'attacker.example:8793' is not a loopback name; "
        "serve with --allow-remote <host> to accept it"
    )


def test_dns_rebinding_host_is_refused_for_pages_and_sockets() -> None:
    """A page or socket naming attacker.example (resolved to 127.0.0.1 by its DNS) is
    refused with the one-line reason, even with a matching Origin; loopback names pass;
    a name given with --allow-remote HOST passes."""
    with _serving(_hub()) as port:
        evil = f"attacker.example:{port}"
        page = _get(port, evil)
        assert page.startswith(b"HTTP/1.1 403") and b"is not a loopback name" in page
        sock, answer = _upgrade(port, evil, f"http://{evil}")
        sock.close()
        assert answer.startswith(b"HTTP/1.1 403"), answer[:80]
        for name in ("127.0.0.1", "localhost"):
            assert _get(port, f"{name}:{port}").startswith(b"HTTP/1.1 200")
            sock, answer = _upgrade(port, f"{name}:{port}", f"http://{name}:{port}")
            sock.close()
            assert answer.startswith(b"HTTP/1.1 101"), answer[:80]
    with _serving(_hub(hosts=("console.lan",))) as port:
        assert _get(port, f"console.lan:{port}").startswith(b"HTTP/1.1 200")
        assert _get(port, f"attacker.example:{port}").startswith(b"HTTP/1.1 403")


def test_refused_socket_body_says_why() -> None:
    """The refused handshake's body is the one-line reason."""
    with _serving(_hub()) as port:
        sock, answer = _upgrade(port, f"attacker.example:{port}")
        body = answer.split(b"\r\n\r\n", 1)[1]
        while b"\n" not in body:
            chunk = sock.recv(4096)
            if not chunk:
                break
            body += chunk
        sock.close()
    assert body.decode().strip() == (
        f"Host 'attacker.example:{port}' is not a loopback name; "
        "serve with --allow-remote <host> to accept it"
    )


# --------------------------------------------------------------------------- size
def test_oversized_frame_closes_1009_from_its_header() -> None:
    """A frame whose header announces 1 MiB is answered by close 1009 before any of its
    payload is sent: the server never buffers it (today's 16 MiB default waited for it)."""
    assert MAX_FRAME_BYTES < 1 << 20
    with _serving(_hub()) as port:
        sock, answer = _upgrade(port, f"127.0.0.1:{port}")
        assert answer.startswith(b"HTTP/1.1 101")
        sock.sendall(bytes([0x81, 0x80 | 127]) + struct.pack("!Q", 1 << 20) + os.urandom(4))
        code = _close_code(sock)
        sock.close()
    assert code == 1009


def _close_code(sock: socket.socket) -> int | None:
    """Read frames for up to 3 s until the server's close frame; its code (None: none)."""
    buf = b""
    sock.settimeout(3)
    end = time.monotonic() + 3
    try:
        while True:
            while len(buf) < 2:
                buf += _recv(sock, end)
            n = buf[1] & 0x7F
            head = 2 + {126: 2, 127: 8}.get(n, 0)
            while len(buf) < head:
                buf += _recv(sock, end)
            if n >= 126:
                n = int.from_bytes(buf[2:head], "big")
            while len(buf) < head + n:
                buf += _recv(sock, end)
            if buf[0] & 0x0F == 0x8:
                return struct.unpack("!H", buf[head : head + 2])[0]
            buf = buf[head + n :]
    except (TimeoutError, ConnectionError):
        return None


def _recv(sock: socket.socket, end: float) -> bytes:
    if time.monotonic() > end:
        raise TimeoutError("no close frame within 3 s")
    chunk = sock.recv(65536)
    if not chunk:
        raise ConnectionError("closed")
    return chunk


def test_message_between_the_limits_gets_an_error() -> None:
    """A message above MAX_MESSAGE_BYTES but within the frame limit is answered, not closed."""
    with _serving(_hub()) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        ws.send("x" * 5000)
        while (m := json.loads(ws.recv(timeout=2)))["type"] != "error":
            pass
        assert "bytes" in m["message"]


# --------------------------------------------------------------------------- records
def test_two_quick_saves_write_two_folders(tmp_path: Path) -> None:
    """Two saves in the same second: two folders, each with its whole record."""
    loop = FakeLoop()
    session = Session(loop, recorder=Recorder(tmp_path, _table(), loop))
    session.tick()
    time.sleep(0.05)
    session.tick()
    a = session.handle(_save_cmd())
    b = session.handle(_save_cmd())
    assert a["folder"] != b["folder"]
    for rec in (a, b):
        folder = Path(rec["folder"])
        assert (folder / TRACE_NAME).exists()
        rows = (folder / LOG_NAME).read_text().splitlines()
        assert len(rows) == 1 + rec["rows"] and rows[0].startswith("t,")
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == sorted(
        Path(r["folder"]).name for r in (a, b)
    )


def test_later_saves_append_only_new_rows(tmp_path: Path, monkeypatch) -> None:
    """The second save formats only the rows logged since the first; both logs are whole."""
    import console.record as record

    formatted: list[int] = []
    real = record._csv_rows
    monkeypatch.setattr(record, "_csv_rows", lambda t, x: formatted.append(len(t)) or real(t, x))
    loop = FakeLoop()
    session = Session(loop, recorder=Recorder(tmp_path, _table(), loop))
    for _ in range(3):
        time.sleep(0.03)
        session.tick()
    first = session.handle(_save_cmd())
    for _ in range(3):
        time.sleep(0.03)
        session.tick()
    second = session.handle(_save_cmd())
    assert formatted == [first["rows"], second["rows"] - first["rows"]]
    a = (Path(first["folder"]) / LOG_NAME).read_text()
    b = (Path(second["folder"]) / LOG_NAME).read_text()
    assert b.startswith(a) and len(b.splitlines()) == 1 + second["rows"]


def test_save_runs_off_the_loop_and_frames_go_on() -> None:
    """The record is written on a worker thread: while it is held, frames keep coming."""
    go, seen = threading.Event(), {}

    def recorder(snap) -> dict:
        seen["thread"] = threading.current_thread()
        go.wait(timeout=5)
        return {"folder": "x", "rows": snap.rows}

    hub = _hub(recorder)
    with _serving(hub) as port, connect(f"ws://127.0.0.1:{port}/ws") as ws:
        ws.send(json.dumps({"type": "drive"}))
        ws.send(json.dumps({"type": "save"}))
        t_frames = []
        while len(t_frames) < 5:  # on the old code the loop was blocked: recv timed out
            m = json.loads(ws.recv(timeout=2))
            if m["type"] == "state":
                t_frames.append(m["t"])
        assert "thread" in seen and not go.is_set()
        go.set()
        while (m := json.loads(ws.recv(timeout=5)))["type"] != "saved":
            assert m["type"] in ("state", "hello", "role"), m
    assert seen["thread"].name.startswith("console-record")
    assert seen["thread"] is not threading.main_thread() and t_frames[-1] > t_frames[0]


def _save_cmd():
    from console.protocol import Command

    return Command("save")


def _table() -> dict:
    """A console table with the fields a record's replay needs (not loaded back: FakeLoop)."""
    return {"name": "fake", "leader": {"u0": ["0"]}, "graph": {}, "followers": [{}, {}, {}]}
