"""Hostile peers on loopback, and a `vs server` in a process of its own to aim them at.

The peers speak WebSocket by hand on a plain socket (RFC 6455: an HTTP upgrade, then
masked frames), so that they can do what no polite client library does: write
thousands of requests and never read a byte of the answers, or open and close
connections as fast as the kernel allows.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import forkserver

OPERATOR, OBSERVER = "hostile-op-secret", "hostile-obs-secret"
VEGA_NIGHT = "2024-05-18T21:00:00Z"  # Vega high above the default site (Poznań)


def host_port(url: str) -> tuple[str, int]:
    parts = urlsplit(url)
    return parts.hostname or "127.0.0.1", int(parts.port or 0)


def ws_frame(text: str | bytes, *, opcode: int = 1, mask: bytes = b"\x12\x34\x56\x78") -> bytes:
    """One masked client frame (RFC 6455 §5.2) carrying `text`."""
    payload = text.encode() if isinstance(text, str) else text
    n = len(payload)
    head = bytes([0x80 | opcode])
    if n < 126:
        head += bytes([0x80 | n])
    elif n < 1 << 16:
        head += bytes([0x80 | 126]) + struct.pack("!H", n)
    else:
        head += bytes([0x80 | 127]) + struct.pack("!Q", n)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return head + mask + masked


def ws_open(url: str, *, timeout_s: float = 10.0, source: str | None = None
            ) -> tuple[socket.socket, bytes]:
    """Open a socket and complete the WebSocket upgrade; return the socket (blocking) and
    the bytes that came after the server's handshake (the start of its first frame)."""
    host, port = host_port(url)
    sock = socket.create_connection((host, port), timeout=timeout_s,
                                    source_address=(source, 0) if source else None)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                  "Sec-WebSocket-Version: 13\r\n\r\n").encode())
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = sock.recv(4096)
        if not chunk:
            raise ConnectionError(f"{url} closed during the handshake")
        head += chunk
    status = head.split(b"\r\n", 1)[0]
    if b" 101 " not in status:
        raise ConnectionError(f"{url} refused the upgrade: {status!r}")
    return sock, head.split(b"\r\n\r\n", 1)[1]


class FrameReader:
    """Read whole server frames (unmasked) from a blocking socket."""

    def __init__(self, sock: socket.socket, buf: bytes = b"") -> None:
        self.sock = sock
        self.buf = buf

    def _need(self, n: int) -> None:
        while len(self.buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk

    def frame(self) -> tuple[int, bytes]:
        self._need(2)
        opcode, n = self.buf[0] & 0x0F, self.buf[1] & 0x7F
        at = 2
        if n == 126:
            self._need(4)
            n, at = struct.unpack("!H", self.buf[2:4])[0], 4
        elif n == 127:
            self._need(10)
            n, at = struct.unpack("!Q", self.buf[2:10])[0], 10
        self._need(at + n)
        payload, self.buf = self.buf[at:at + n], self.buf[at + n:]
        return opcode, payload

    def json(self) -> dict[str, Any]:
        """The next text frame as JSON (raises ConnectionError at a close frame)."""
        while True:
            opcode, payload = self.frame()
            if opcode == 8:
                code = struct.unpack("!H", payload[:2])[0] if len(payload) >= 2 else 1005
                raise ConnectionError(f"closed by the server: {code} {payload[2:].decode()}")
            if opcode == 1:
                return json.loads(payload)


@dataclass
class Flood:
    """What a flood of requests never read came to."""

    sent: int  # requests written into the socket before it stopped taking more
    wanted: int
    closed: bool = False  # the server closed the connection (e.g. not authenticated in time)


def flood_never_read(url: str, count: int, *, give_up_s: float = 5.0,
                     text: str | bytes = '{"id": 1, "cmd": "ping"}', opcode: int = 1,
                     first: bytes = b"") -> tuple[socket.socket, Flood]:
    """Write `count` requests on a fresh connection without ever reading; stop when the
    socket has taken nothing for `give_up_s` (the server stopped reading it). Returns
    the socket, still open, and how many whole requests went out. `first`: a frame to
    send before the flood (an ASTCom HELLO)."""
    sock, _ = ws_open(url)
    if first:
        sock.sendall(first)
    return sock, flood_socket(sock, count, give_up_s=give_up_s, text=text, opcode=opcode)


def flood_socket(sock: socket.socket, count: int, *, give_up_s: float = 5.0,
                 text: str | bytes = '{"id": 1, "cmd": "ping"}', opcode: int = 1) -> Flood:
    """Write `count` requests on an open connection (authenticated or not) without reading,
    until the socket has taken nothing for `give_up_s`; how many whole requests went out."""
    frame = ws_frame(text, opcode=opcode)
    data = frame * count
    sock.setblocking(False)
    sent, idle_since, closed = 0, time.monotonic(), False
    while sent < len(data):
        try:
            n = sock.send(data[sent:sent + 65536])
        except BlockingIOError:
            if time.monotonic() - idle_since > give_up_s:
                break
            time.sleep(0.01)
            continue
        except (ConnectionResetError, BrokenPipeError):
            closed = True
            break
        sent += n
        idle_since = time.monotonic()
    return Flood(sent // len(frame), count, closed)


@dataclass
class ServerProcess:
    """A `vs server --emulator` in its own process; its stderr goes to a file."""

    url: str
    emulator_url: str
    line: str
    proc: subprocess.Popen
    stderr_path: Path
    out: str = ""

    @property
    def stderr(self) -> str:
        return self.stderr_path.read_text(errors="replace")


@contextlib.contextmanager
def vs_server(tmp: Path, *args: str, passwords: bool = True) -> Iterator[ServerProcess]:
    """Run `vs server --emulator ARGS` with the operator/observer passwords (free ports for
    it and its emulator's endpoint: the default 8741 may be taken by another run on the
    machine), until the block ends; then SIGTERM it as Ctrl-C would."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        url = f"ws://127.0.0.1:{s.getsockname()[1]}"
    secrets = ["--operator-password", OPERATOR, "--observer-password", OBSERVER] \
        if passwords else []
    err_path = tmp / f"vss-stderr-{url.rsplit(':', 1)[1]}.txt"
    env = {k: v for k, v in os.environ.items() if k not in ("ASTCOM_PASSWORD",)}
    with err_path.open("w") as err:
        proc = forkserver.popen(
            [sys.executable, "-c", "from virtualstar.cli.main import main; main()", "server",
             "--emulator", "--endpoint-port", "0", *secrets, *args, "--listen", url],
            stdout=subprocess.PIPE, stderr=err, text=True,
            env={**env, "PYTHONUNBUFFERED": "1"})
    try:
        line = proc.stdout.readline() if proc.stdout else ""
        found = re.search(r"other clients: (ws://[0-9.:]+)", line)
        assert url in line and found, (line, err_path.read_text())
        if passwords and proc.stdout:  # the line that says what guards the emulator
            line += proc.stdout.readline()
        server = ServerProcess(url, found.group(1), line, proc, err_path)
        yield server
    finally:
        proc.send_signal(signal.SIGTERM)
        with contextlib.suppress(subprocess.TimeoutExpired):
            server_out, _ = proc.communicate(timeout=30)
            if "server" in locals():
                server.out = server_out
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@dataclass
class Session:
    """A polite authenticated client on a raw socket (one request at a time)."""

    sock: socket.socket
    reader: FrameReader
    role: str = ""
    next_id: int = 1
    events: list[dict[str, Any]] = field(default_factory=list)

    def request(self, cmd: str, params: dict[str, Any] | None = None, *,
                raw: str | None = None) -> dict[str, Any]:
        """Send one request (or a raw frame) and return its reply (skipping events)."""
        rid = self.next_id
        self.next_id += 1
        text = raw if raw is not None else json.dumps(
            {"id": rid, "cmd": cmd, "params": params or {}})
        self.sock.sendall(ws_frame(text))
        while True:
            doc = self.reader.json()
            if "event" in doc:
                self.events.append(doc)
                del self.events[:-100]
                continue
            if raw is not None or doc.get("id") == rid:
                return doc

    def next_reply(self, within_s: float) -> dict[str, Any] | None:
        """The next answer (events skipped) if one comes within `within_s`, else None; a
        frame half read when the time runs out stays buffered for the next call."""
        deadline = time.monotonic() + within_s
        try:
            while (left_s := deadline - time.monotonic()) > 0:
                self.sock.settimeout(left_s)
                doc = self.reader.json()
                if "event" not in doc:
                    return doc
                self.events.append(doc)
                del self.events[:-100]
        except TimeoutError:
            pass
        finally:
            self.sock.settimeout(None)
        return None

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.sendall(ws_frame(struct.pack("!H", 1000), opcode=8))
        self.sock.close()


def stranger(url: str, *, timeout_s: float = 30.0) -> Session:
    """Connect and read the hello, without authenticating (no password check, so nothing
    the server's throttle counts): such a peer may send `ping` and `auth` only."""
    sock, rest = ws_open(url, timeout_s=timeout_s)
    session = Session(sock, FrameReader(sock, rest))
    session.events.append(session.reader.json())  # the hello
    return session


def login(url: str, password: str | None, *, timeout_s: float = 30.0) -> Session:
    """Connect and authenticate with `password` (challenge–response, as docs/vss-api.md says)."""
    import hashlib
    import hmac

    sock, rest = ws_open(url, timeout_s=timeout_s)
    reader = FrameReader(sock, rest)
    hello = reader.json()
    session = Session(sock, reader)
    auth = hello["data"]["auth"]
    if not auth["required"]:
        session.role = auth["role"]
        return session
    nonce = bytes.fromhex(auth["nonce"])
    mine = os.urandom(16)
    mac = hmac.new((password or "").encode(), b"ASTCom-1 client\x00" + nonce + mine,
                   hashlib.sha256).digest()
    reply = session.request("auth", {"client_nonce": mine.hex(), "mac": mac.hex()})
    if reply.get("ok"):
        session.role = reply["result"]["role"]
    else:
        session.role = ""
        session.events.append(reply)
    return session
