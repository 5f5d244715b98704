"""Thin asyncio byte pumps: each moves whole frames between a socket and the sans-I/O core.

Endpoint side: WebSocket (`websockets`): one binary WebSocket message per frame; TCP:
length-prefixed frames (`framing`); TLS wraps either (`wss://`, `tls://`) through
Python's `ssl`. Client side sockets: `push_transport`. A `memory_pair` joins a client
and an endpoint in one process without sockets.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl
from collections.abc import Awaitable, Callable
from http import HTTPStatus
from typing import Protocol

import websockets
from websockets.asyncio.server import ServerConnection as WsServerConnection
from websockets.asyncio.server import serve as ws_serve
from websockets.http11 import Request, Response

from .exceptions import ConnectionClosed, MalformedFrame
from .framing import FrameReader, frame_bytes
from .origins import origin_refusal
from .url import EndpointUrl, parse_url

__all__ = [
    "MemoryTransport",
    "ServerHandle",
    "TcpTransport",
    "Transport",
    "WebSocketTransport",
    "client_ssl_context",
    "memory_pair",
    "server_ssl_context",
    "start_server",
]

log = logging.getLogger("astcom.transports")

_READ_CHUNK = 1 << 16
_WS_CLOSE_CODES = {1000: 1000, 413: 1009, 429: 1013, 503: 1001}
# How long, and how much, a closing connection reads (and drops) of what its peer still
# sends, so that the peer receives our last frames (the ERR that says why it is cut off);
# a flood beyond that is not read on.
_LINGER_S = 2.0
_LINGER_BYTES = 1 << 20


class Transport(Protocol):
    """What the Endpoint and the Client need from a connection."""

    peer: str

    async def recv(self) -> bytes | None:
        """Return the next frame, or None once the peer has closed."""

    async def send(self, frame: bytes) -> None:
        """Send one frame (waits while the peer is not reading: back-pressure)."""

    async def close(self, code: int = 1000, reason: str = "") -> None:
        """Close, telling the peer why when the transport can."""


class MemoryTransport:
    """One end of an in-process pair; the peer's inbox is bounded to model a slow reader."""

    def __init__(self, inbox: asyncio.Queue[bytes | None], outbox: asyncio.Queue[bytes | None],
                 peer: str) -> None:
        self._inbox, self._outbox = inbox, outbox
        self.peer = peer
        self.closed = False
        self.close_code = 0
        self.close_reason = ""

    async def recv(self) -> bytes | None:
        if self.closed and self._inbox.empty():
            return None
        frame = await self._inbox.get()
        if frame is None:
            self.closed = True
        return frame

    async def send(self, frame: bytes) -> None:
        if self.closed:
            raise ConnectionClosed("memory transport is closed")
        await self._outbox.put(frame)

    async def close(self, code: int = 1000, reason: str = "") -> None:
        if not self.closed:
            self.closed = True
            self.close_code, self.close_reason = code, reason
            with contextlib.suppress(asyncio.QueueFull):
                self._outbox.put_nowait(None)
            with contextlib.suppress(asyncio.QueueFull):
                self._inbox.put_nowait(None)  # wake our own pending recv


def memory_pair(maxsize: int = 64) -> tuple[MemoryTransport, MemoryTransport]:
    """Return (client end, server end) joined by two bounded queues."""
    to_server: asyncio.Queue[bytes | None] = asyncio.Queue(maxsize)
    to_client: asyncio.Queue[bytes | None] = asyncio.Queue(maxsize)
    return (MemoryTransport(to_client, to_server, "memory-server"),
            MemoryTransport(to_server, to_client, "memory-client"))


class WebSocketTransport:
    """A websockets connection carrying one binary message per frame."""

    def __init__(self, ws: websockets.asyncio.connection.Connection) -> None:
        self._ws = ws
        addr = ws.remote_address
        self.peer = f"{addr[0]}:{addr[1]}" if addr else "websocket"

    def limit_frames(self, max_bytes: int) -> None:
        """Read messages of at most `max_bytes` from now on (larger: closed with 1009)."""
        self._ws.protocol.max_message_size = max_bytes

    async def recv(self) -> bytes | None:
        try:
            message = await self._ws.recv()
        except websockets.ConnectionClosed:
            return None
        if isinstance(message, str):
            raise MalformedFrame("text WebSocket message received; ASTCom frames are binary")
        return message

    async def send(self, frame: bytes) -> None:
        try:
            await self._ws.send(frame)
        except websockets.ConnectionClosed as exc:
            raise ConnectionClosed(f"websocket closed: {exc}") from None

    async def close(self, code: int = 1000, reason: str = "") -> None:
        ws_code = _WS_CLOSE_CODES.get(code, 1008 if code else 1000)
        text = f"{code} {reason}" if reason else ""
        # The peer's close frame may sit behind messages it sent before it saw ours; they
        # are read and dropped, else the closing handshake waits for close_timeout.
        drain = asyncio.ensure_future(self._drop_incoming())
        try:
            await self._ws.close(ws_code, text.encode()[:120].decode(errors="ignore"))
        finally:
            drain.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await drain

    async def _drop_incoming(self) -> None:
        # a reader of our own may be in recv() already (ConcurrencyError): then it drains
        dropped = 0
        with contextlib.suppress(Exception):
            while dropped < _LINGER_BYTES:
                dropped += len(await self._ws.recv())


class TcpTransport:
    """An asyncio stream carrying length-prefixed frames."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                 max_frame_bytes: int) -> None:
        self._reader, self._writer = reader, writer
        self._frames = FrameReader(max_frame_bytes)
        self._ready: list[bytes] = []
        addr = writer.get_extra_info("peername")
        self.peer = f"{addr[0]}:{addr[1]}" if addr else "tcp"

    def limit_frames(self, max_bytes: int) -> None:
        """Read frames of at most `max_bytes` from now on (larger: MalformedFrame)."""
        self._frames.max_frame_bytes = max_bytes

    async def recv(self) -> bytes | None:
        while not self._ready:
            try:
                data = await self._reader.read(_READ_CHUNK)
            except (ConnectionError, ssl.SSLError):
                return None
            if not data:
                return None
            self._ready = self._frames.feed(data)
            self._ready.reverse()
        return self._ready.pop()

    async def send(self, frame: bytes) -> None:
        if self._writer.is_closing():
            raise ConnectionClosed("tcp connection is closed")
        self._writer.write(frame_bytes(frame))
        try:
            await self._writer.drain()
        except (ConnectionError, ssl.SSLError) as exc:
            raise ConnectionClosed(f"tcp connection lost: {exc}") from None

    async def close(self, code: int = 1000, reason: str = "") -> None:
        if not self._writer.is_closing():
            # Closing with unread bytes makes the kernel reset the connection, and a reset
            # destroys what the peer has not read yet (our last replies): say we are done
            # (FIN) and drop what still comes until the peer closes too, for a while.
            with contextlib.suppress(Exception):
                if self._writer.can_write_eof():
                    self._writer.write_eof()
                    dropped = 0
                    async with asyncio.timeout(_LINGER_S):
                        while dropped < _LINGER_BYTES and (data := await self._reader.read(_READ_CHUNK)):
                            dropped += len(data)
            self._writer.close()
        with contextlib.suppress(Exception):
            async with asyncio.timeout(2.0):
                await self._writer.wait_closed()


def server_ssl_context(certfile: str, keyfile: str | None = None) -> ssl.SSLContext:
    """Return a TLS server context for `certfile`/`keyfile` (PEM)."""
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ctx.load_cert_chain(certfile, keyfile)
    return ctx


def client_ssl_context(cafile: str | None = None) -> ssl.SSLContext:
    """Return a TLS client context trusting `cafile` (or the system's authorities)."""
    return ssl.create_default_context(cafile=cafile)


class ServerHandle:
    """A listening server; `url` is the bound address (the real port when 0 was asked)."""

    def __init__(self, url: str, closer: Callable[[], Awaitable[None]]) -> None:
        self.url = url
        self._closer = closer

    async def close(self) -> None:
        await self._closer()


async def start_server(url: str | EndpointUrl, on_connection: Callable[[Transport], Awaitable[None]],
                       *, max_frame_bytes: int, ssl_context: ssl.SSLContext | None = None,
                       allowed_origins: tuple[str, ...] | None = None) -> ServerHandle:
    """Listen on `url` and run `on_connection(transport)` for every accepted connection.

    WebSocket handshakes from a browser page whose `Origin` is not allowed (see
    `origins.origin_refusal`; None: loopback pages only) get HTTP 403 and a reason.
    """
    where = parse_url(url) if isinstance(url, str) else url
    if where.secure and ssl_context is None:
        raise ValueError(f"{where.scheme}:// needs a certificate and key (certfile/keyfile)")
    ctx = ssl_context if where.secure else None
    if where.websocket:
        async def ws_handler(ws: WsServerConnection) -> None:
            await on_connection(WebSocketTransport(ws))

        def check_origin(connection: WsServerConnection, request: Request) -> Response | None:
            reason = origin_refusal(request.headers.get_all("Origin"), allowed_origins)
            if reason is None:
                return None
            log.warning("WebSocket handshake from %s: %s", connection.remote_address, reason)
            return connection.respond(HTTPStatus.FORBIDDEN, reason + "\n")

        server = await ws_serve(ws_handler, where.host, where.port, ssl=ctx,
                                max_size=max_frame_bytes, compression=None,
                                process_request=check_origin)
        port = server.sockets[0].getsockname()[1]

        async def close_ws() -> None:
            server.close()
            with contextlib.suppress(Exception):
                async with asyncio.timeout(5.0):
                    await server.wait_closed()

        bound = EndpointUrl(where.scheme, where.host, port, where.path)
        return ServerHandle(str(bound), close_ws)

    async def tcp_handler(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        transport = TcpTransport(reader, writer, max_frame_bytes)
        try:
            await on_connection(transport)
        finally:
            await transport.close()

    tcp_server = await asyncio.start_server(tcp_handler, where.host, where.port, ssl=ctx)
    port = tcp_server.sockets[0].getsockname()[1]

    async def close_tcp() -> None:
        tcp_server.close()
        with contextlib.suppress(Exception):
            async with asyncio.timeout(5.0):
                await tcp_server.wait_closed()

    return ServerHandle(str(EndpointUrl(where.scheme, where.host, port)), close_tcp)
