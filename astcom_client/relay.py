"""The Relay: one framed device link (serial/SPI/pty, or a TCP pipe) to many ASTCom clients.

The device runs one full ASTCom session per link channel (docs/astcom-protocol.md §11):
its own HELLO, nonce and AUTH, role, messages and streams. The Relay only carries
frames: a client that connects gets a free channel (OPEN), its frames go to the device on
that channel unchanged and the device's frames come back unchanged, so a client cannot
tell a relayed device from a direct one. The Relay holds no signal logic and no
password; what it adds is what a transport adds:

* a client beyond the device's channels gets ``ERR 429`` and a close;
* a client that does not read: its stream packets beyond `queue_packets` are dropped,
  oldest first (they show as a seq jump, as on a direct connection), never its replies,
  and the link to the device is never held up by it;
* link loss: no frame from the device for `link_timeout_s` (it answers a PING every
  second), a read error or the device restarting (an unasked HELLO) closes every client
  with ``["ERR", nil, {"code": 503, ...}]`` saying why; clients that arrive while the
  link is down get the same and a close. The Relay keeps calling the device.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import struct
import termios
import tty
from collections import deque
from dataclasses import dataclass

import msgpack

from .exceptions import AstcomError
from .link import (
    LinkFrame,
    LinkKind,
    LinkReader,
    encode_link_frame,
    link_hello_body,
    parse_link_hello,
)
from .transports import ServerHandle, TcpTransport, Transport, start_server
from .url import parse_url

__all__ = ["Relay", "RelayConfig"]

log = logging.getLogger("astcom.relay")
_DATA_PREFIX = b"\x99\xa4DATA"  # a DATA frame: an array of 9 starting with the str DATA


@dataclass(frozen=True)
class RelayConfig:
    """Where the device is and how the Relay serves it."""

    serial: str | None = None          # a tty/pty path
    tcp: str | None = None             # HOST:PORT of a device whose link is a TCP stream
    listen: tuple[str, ...] = ("ws://127.0.0.1:8765",)
    allowed_origins: tuple[str, ...] | None = None
    queue_packets: int = 256           # stream packets queued per client
    link_timeout_s: float = 3.0        # no frame from the device this long: the link is lost
    ping_interval_s: float = 1.0
    max_frame_bytes: int = 1 << 20     # until the device's HELLO says its own


class _Client:
    def __init__(self, chan: int, transport: Transport, queue_packets: int) -> None:
        self.chan = chan
        self.transport = transport
        self.queue: deque[bytes] = deque()
        self.queue_packets = queue_packets
        self.wake = asyncio.Event()
        self.close_code: int | None = None
        self.close_reason = ""
        self.dropped_packets = 0
        self.queued_packets = 0  # stream packets in `queue`

    def push(self, frame: bytes) -> None:
        if frame.startswith(_DATA_PREFIX):
            if self.queued_packets >= self.queue_packets:
                for i, f in enumerate(self.queue):  # the oldest packet (replies stay)
                    if f.startswith(_DATA_PREFIX):
                        del self.queue[i]
                        self.dropped_packets += 1
                        self.queued_packets -= 1
                        break
            self.queued_packets += 1
        self.queue.append(frame)
        self.wake.set()

    def pop(self) -> bytes:
        frame = self.queue.popleft()
        if frame.startswith(_DATA_PREFIX):
            self.queued_packets -= 1
        return frame

    def end(self, code: int, reason: str) -> None:
        if self.close_code is None:
            self.close_code, self.close_reason = code, reason
        self.wake.set()


def _error_frame(code: int, message: str) -> bytes:
    return msgpack.packb(["ERR", None, {"code": code, "message": message}], use_bin_type=True)


class Relay:
    """Serve one device link to many clients (see the module docstring)."""

    def __init__(self, config: RelayConfig) -> None:
        if (config.serial is None) == (config.tcp is None):
            raise ValueError("give exactly one device link: --serial DEV or --tcp HOST:PORT")
        self.config = config
        self.channels = 0                 # 0 until the device said HELLO
        self.max_frame_bytes = config.max_frame_bytes
        self.clients: dict[int, _Client] = {}
        self.closing: set[int] = set()    # channels whose CLOSE the device has not answered
        self.link_up = asyncio.Event()
        self.down_reason = "the device has not answered yet"
        self.urls: list[str] = []
        self._reader = LinkReader(1 << 24)
        self._servers: list[ServerHandle] = []
        self._tasks: list[asyncio.Task] = []
        self._write_buf = bytearray()
        self._writable = asyncio.Event()
        self._fd: int | None = None
        self._tcp_writer: asyncio.StreamWriter | None = None
        self._last_rx = 0.0
        self._tokens = itertools.count(1)
        self._hello_token = 0             # the token of our last HELLO
        self._next_chan = 0
        self.frames_to_device = 0
        self.frames_from_device = 0

    # -- the device side ---------------------------------------------------------------------
    async def _open_link(self) -> asyncio.StreamReader | None:
        if self.config.serial is not None:
            fd = os.open(self.config.serial, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            with contextlib.suppress(termios.error):
                tty.setraw(fd)
            self._fd = fd
            return None
        host, port = self.config.tcp.rsplit(":", 1)
        reader, writer = await asyncio.open_connection(host, int(port))
        self._tcp_writer = writer
        return reader

    def _send_link(self, chan: int, kind: int, body: bytes = b"") -> None:
        data = encode_link_frame(chan, kind, body)
        if self._tcp_writer is not None:
            self._tcp_writer.write(data)
            return
        self._write_buf += data
        self._flush_fd()

    def _flush_fd(self) -> None:
        loop = asyncio.get_running_loop()
        while self._write_buf and self._fd is not None:
            try:
                n = os.write(self._fd, self._write_buf)
            except BlockingIOError:
                loop.add_writer(self._fd, self._on_writable)
                return
            except OSError as exc:
                self._link_lost(f"writing to the device link failed: {exc}")
                return
            del self._write_buf[:n]
        if self._fd is not None:
            loop.remove_writer(self._fd)

    def _on_writable(self) -> None:
        self._flush_fd()

    async def _run_link(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            try:
                reader = await self._open_link()
            except OSError as exc:
                self._link_lost(f"cannot open the device link: {exc}")
                await asyncio.sleep(1.0)
                continue
            self._last_rx = loop.time()
            self._say_hello()
            pinger = asyncio.create_task(self._ping())
            try:
                if reader is not None:
                    while data := await reader.read(65536):
                        self._on_bytes(data)
                    self._link_lost("the device closed the link")
                else:
                    queue: asyncio.Queue[bytes | None] = asyncio.Queue()

                    def readable(queue: asyncio.Queue[bytes | None] = queue) -> None:
                        try:
                            data = os.read(self._fd, 65536)
                        except BlockingIOError:
                            return
                        except OSError as exc:
                            data = b""
                            log.warning("reading the device link: %s", exc)
                        queue.put_nowait(data or None)

                    loop.add_reader(self._fd, readable)
                    while (data := await queue.get()) is not None:
                        self._on_bytes(data)
                    loop.remove_reader(self._fd)
                    self._link_lost("the device link was closed (EOF)")
            finally:
                pinger.cancel()
                self._close_link()
            await asyncio.sleep(1.0)

    def _close_link(self) -> None:
        if self._fd is not None:
            loop = asyncio.get_running_loop()
            loop.remove_reader(self._fd)
            loop.remove_writer(self._fd)
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None
        if self._tcp_writer is not None:
            self._tcp_writer.close()
            self._tcp_writer = None
        self._write_buf.clear()

    async def _ping(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(self.config.ping_interval_s)
            if loop.time() - self._last_rx > self.config.link_timeout_s:
                self._link_lost(f"the device has not answered for {self.config.link_timeout_s:g} s")
                self._say_hello()
            else:
                self._send_link(0, LinkKind.PING, struct.pack("<I", next(self._tokens) & 0xFFFFFFFF))

    def _say_hello(self) -> None:
        """Ask the device to announce itself (and forget every channel)."""
        self._hello_token = next(self._tokens) & 0xFFFFFFFF or 1
        self._send_link(0, LinkKind.HELLO, link_hello_body(0, 0, self._hello_token))

    def _on_bytes(self, data: bytes) -> None:
        self._last_rx = asyncio.get_running_loop().time()
        for frame in self._reader.feed(data):
            self.frames_from_device += 1
            self._on_frame(frame)

    def _on_frame(self, frame: LinkFrame) -> None:
        if frame.kind == LinkKind.HELLO:
            try:
                _, channels, max_frame, token = parse_link_hello(frame.body)
            except ValueError:
                return
            if token not in (None, 0, self._hello_token):
                return  # the answer to an earlier HELLO of ours, overtaken by a newer one
            # the answer to our HELLO is expected; a HELLO of token 0 is the device booting
            # (a stale one may also wait in the line when the relay starts: link not up yet)
            if self.link_up.is_set() and token != self._hello_token:
                self._link_lost("the device restarted")
            self.channels, self.max_frame_bytes = channels, max_frame
            self.closing.clear()
            self.link_up.set()
            log.info("device link up: %d channels, frames up to %d bytes", channels, max_frame)
            return
        if frame.kind == LinkKind.DATA:
            client = self.clients.get(frame.chan)
            if client is not None:
                client.push(frame.body)
        elif frame.kind == LinkKind.CLOSE:
            self.closing.discard(frame.chan)
            client = self.clients.pop(frame.chan, None)
            if client is not None:
                code = struct.unpack_from("<H", frame.body)[0] if len(frame.body) >= 2 else 1000
                client.end(code, frame.body[2:].decode("utf-8", "replace"))

    def _link_lost(self, reason: str) -> None:
        if self.link_up.is_set():
            log.warning("device link lost: %s", reason)
        self.link_up.clear()
        self.down_reason = reason
        for chan, client in list(self.clients.items()):
            client.push(_error_frame(503, f"the device link is lost: {reason}"))
            client.end(503, f"the device link is lost: {reason}")
            del self.clients[chan]
        self.closing.clear()

    # -- the client side -------------------------------------------------------------------------
    def _free_channel(self) -> int | None:
        for step in range(1, self.channels + 1):
            chan = (self._next_chan + step - 1) % self.channels + 1
            if chan not in self.clients and chan not in self.closing:
                self._next_chan = chan
                return chan
        return None

    async def _serve_client(self, transport: Transport) -> None:
        if not self.link_up.is_set():
            await self._refuse(transport, 503, f"the device link is down: {self.down_reason}")
            return
        chan = self._free_channel()
        if chan is None:
            await self._refuse(transport, 429, f"too many clients: the device serves at most "
                                               f"{self.channels} connections through this relay")
            return
        client = _Client(chan, transport, self.config.queue_packets)
        self.clients[chan] = client
        self._send_link(chan, LinkKind.OPEN, transport.peer.encode()[:64])
        writer = asyncio.create_task(self._write_client(client))
        try:
            # After the end (the device closed the channel, or the frame was refused) the
            # client's frames already on their way are read and dropped until its close
            # arrives: a reader that stops would leave the WebSocket's closing handshake
            # stuck behind them (up to 1 MiB of them: beyond, a flood is not read on).
            dropped = 0
            while True:
                try:
                    frame = await transport.recv()
                except AstcomError as exc:  # a text frame, an oversized TCP frame
                    if client.close_code is None:
                        client.push(_error_frame(exc.code, exc.message))
                        client.end(exc.code, exc.message)
                    if isinstance(transport, TcpTransport):
                        break  # the TCP byte stream cannot be resynchronised
                    continue
                if frame is None:
                    break
                if client.close_code is not None:
                    dropped += len(frame)
                    if dropped > 1 << 20:  # a flood, not frames in flight: read no more
                        break
                    continue
                if len(frame) > self.max_frame_bytes:
                    message = (f"frame of {len(frame)} bytes exceeds the limit of "
                               f"{self.max_frame_bytes} bytes")
                    client.push(_error_frame(413, message))
                    client.end(413, message)
                    continue
                self._send_link(chan, LinkKind.DATA, frame)
                self.frames_to_device += 1
        finally:
            if self.clients.get(chan) is client:
                del self.clients[chan]
                self.closing.add(chan)
                self._send_link(chan, LinkKind.CLOSE)
                client.end(1000, "")
            with contextlib.suppress(Exception):
                async with asyncio.timeout(5.0):
                    await writer

    async def _write_client(self, client: _Client) -> None:
        try:
            while True:
                await client.wake.wait()
                client.wake.clear()
                while client.queue:
                    await client.transport.send(client.pop())
                if client.close_code is not None:
                    break
        except Exception:  # the client went away; its reader ends the session
            pass
        finally:
            with contextlib.suppress(Exception):
                await client.transport.close(client.close_code or 1000, client.close_reason)

    async def _refuse(self, transport: Transport, code: int, message: str) -> None:
        with contextlib.suppress(Exception):
            await transport.send(_error_frame(code, message))
            await transport.close(code, message)

    # -- running -----------------------------------------------------------------------------------
    async def start(self) -> list[str]:
        """Open the link and listen; return the bound URLs."""
        self._tasks.append(asyncio.create_task(self._run_link()))
        with contextlib.suppress(asyncio.TimeoutError):
            async with asyncio.timeout(5.0):
                await self.link_up.wait()
        for url in self.config.listen:
            handle = await start_server(parse_url(url), self._serve_client,
                                        max_frame_bytes=1 << 24,
                                        allowed_origins=self.config.allowed_origins)
            self._servers.append(handle)
            self.urls.append(handle.url)
        return self.urls

    async def close(self) -> None:
        for handle in self._servers:
            await handle.close()
        for task in self._tasks:
            task.cancel()
        for client in list(self.clients.values()):
            client.end(1001, "the relay is shutting down")
        self._close_link()
