"""Client transport that hands each received frame to a callback, as soon as it arrives.

An `asyncio.Protocol` feeds the bytes to websockets' sans-I/O `ClientProtocol` (for ws://
and wss://) or to the TCP `FrameReader` (tcp://, tls://) and calls the Client's frame
callback directly from `data_received`. Compared with a task awaiting `recv()`, a reply
reaches the waiting request one event-loop turn earlier, which is most of a round trip's
overhead on loopback.
"""

from __future__ import annotations

import asyncio
import contextlib
import ssl
from collections.abc import Callable

from websockets.client import ClientProtocol
from websockets.frames import Opcode
from websockets.http11 import Response
from websockets.protocol import State
from websockets.uri import parse_uri

from .exceptions import AstcomError, ConnectionClosed, LimitExceeded
from .framing import FrameReader, frame_bytes
from .url import EndpointUrl

__all__ = ["PushTransport", "open_push_transport"]

FrameCallback = Callable[[bytes], None]
ClosedCallback = Callable[[AstcomError], None]


class _Pump(asyncio.Protocol):
    def __init__(self, owner: PushTransport) -> None:
        self.owner = owner

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.owner._transport = transport

    def data_received(self, data: bytes) -> None:
        self.owner._data(data)

    def eof_received(self) -> bool:
        self.owner._lost(None)
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.owner._lost(exc)

    def pause_writing(self) -> None:
        self.owner._writable.clear()

    def resume_writing(self) -> None:
        self.owner._writable.set()


class PushTransport:
    """A connection whose received frames are pushed to `start(on_frame, on_closed)`."""

    def __init__(self, where: EndpointUrl, max_frame_bytes: int) -> None:
        self.peer = f"{where.host}:{where.port}"
        self._ws = (ClientProtocol(parse_uri(str(where)), max_size=max_frame_bytes)
                    if where.websocket else None)
        self._frames = FrameReader(max_frame_bytes)
        self._parts: list[bytes] = []
        self._transport: asyncio.Transport | None = None
        self._writable = asyncio.Event()
        self._writable.set()
        self._handshake: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        if self._ws is None:
            self._handshake.set_result(None)  # TCP has no handshake of its own
        self._on_frame: FrameCallback | None = None
        self._on_closed: ClosedCallback | None = None
        self._early: list[bytes] = []
        self._closed: AstcomError | None = None

    def start(self, on_frame: FrameCallback, on_closed: ClosedCallback) -> None:
        """Deliver every frame to `on_frame`; call `on_closed(reason)` once at the end."""
        self._on_frame, self._on_closed = on_frame, on_closed
        early, self._early = self._early, []
        for frame in early:
            on_frame(frame)
        if self._closed is not None:
            on_closed(self._closed)

    # -- receiving --------------------------------------------------------------------------
    def _data(self, data: bytes) -> None:
        try:
            if self._ws is None:
                for frame in self._frames.feed(data):
                    self._deliver(frame)
                return
            self._ws.receive_data(data)
            for event in self._ws.events_received():
                if isinstance(event, Response):
                    self._handshake_done()
                elif event.opcode in (Opcode.BINARY, Opcode.TEXT, Opcode.CONT):
                    self._parts.append(event.data)
                    if event.fin:
                        frame = b"".join(self._parts) if len(self._parts) > 1 else self._parts[0]
                        self._parts = []
                        self._deliver(frame)
                elif event.opcode is Opcode.CLOSE and self._ws.close_reason:
                    self._closed = self._closed or ConnectionClosed(
                        f"the endpoint closed the connection: {self._ws.close_reason}")
            self._flush_ws()
        except LimitExceeded as exc:
            self._fail(exc)
        except AstcomError as exc:  # raised by the Client's frame callback
            self._fail(exc)

    def _handshake_done(self) -> None:
        assert self._ws is not None
        if self._handshake.done():
            return
        if self._ws.handshake_exc is not None:
            self._handshake.set_exception(ConnectionClosed(
                f"WebSocket handshake refused: {self._ws.handshake_exc}"))
        else:
            self._handshake.set_result(None)

    def _deliver(self, frame: bytes) -> None:
        if self._on_frame is None:
            self._early.append(frame)
        else:
            self._on_frame(frame)

    def _fail(self, exc: AstcomError) -> None:
        self._closed = self._closed or exc
        if self._transport is not None:
            self._transport.close()

    def _lost(self, exc: Exception | None) -> None:
        if self._ws is not None:
            with contextlib.suppress(Exception):
                self._ws.receive_eof()
        reason = self._closed or ConnectionClosed(
            f"connection lost: {exc}" if exc else "the endpoint closed the connection")
        self._closed = reason
        self._writable.set()
        if not self._handshake.done():
            self._handshake.set_exception(reason)
            self._handshake.exception()  # the opener may already have given up waiting
        if self._on_closed is not None:
            callback, self._on_closed = self._on_closed, None
            callback(reason)

    # -- sending ------------------------------------------------------------------------------
    def _flush_ws(self) -> None:
        assert self._ws is not None and self._transport is not None
        for chunk in self._ws.data_to_send():
            if chunk:
                self._transport.write(chunk)
            elif self._transport.can_write_eof():
                self._transport.write_eof()

    def write(self, frame: bytes) -> None:
        """Queue one frame for sending now (see `drain` for back-pressure)."""
        if self._transport is None or self._transport.is_closing() or self._closed is not None:
            raise ConnectionClosed(f"the connection is closed{': ' + str(self._closed) if self._closed else ''}")
        if self._ws is None:
            self._transport.write(frame_bytes(frame))
        else:
            if self._ws.state is not State.OPEN:
                raise ConnectionClosed("the WebSocket is closing")
            self._ws.send_binary(frame)
            self._flush_ws()

    async def drain(self) -> None:
        """Wait while the kernel's send buffer is full."""
        await self._writable.wait()

    async def send(self, frame: bytes) -> None:
        self.write(frame)
        await self.drain()

    async def recv(self) -> bytes | None:  # the Transport protocol; unused in push mode
        raise NotImplementedError("PushTransport pushes frames to start(on_frame, ...)")

    async def close(self, code: int = 1000, reason: str = "") -> None:
        if self._transport is None or self._transport.is_closing():
            return
        if self._ws is not None and self._ws.state is State.OPEN:
            with contextlib.suppress(Exception):
                self._ws.send_close(1000)
                self._flush_ws()
        self._transport.close()


async def open_push_transport(where: EndpointUrl, *, max_frame_bytes: int,
                              ssl_context: ssl.SSLContext | None, timeout_s: float) -> PushTransport:
    """Connect to `where` and finish the WebSocket handshake; raise ConnectionClosed."""
    transport = PushTransport(where, max_frame_bytes)
    loop = asyncio.get_running_loop()
    try:
        async with asyncio.timeout(timeout_s):
            await loop.create_connection(lambda: _Pump(transport), where.host, where.port,
                                         ssl=ssl_context,
                                         server_hostname=where.host if ssl_context else None)
            if transport._ws is not None:
                transport._ws.send_request(transport._ws.connect())
                transport._flush_ws()
                await transport._handshake
    except (OSError, TimeoutError) as exc:
        await transport.close()
        raise ConnectionClosed(f"cannot connect to {where}: {exc or type(exc).__name__}") from None
    except ConnectionClosed:
        await transport.close()
        raise
    return transport
