"""The asyncio ASTCom client: discover, read, write, invoke and stream.

One Client is one connection. It keeps its own register of DEFINEd messages (names →
message ID), so `read(names)` defines a message once and then costs one round trip.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from .codec import Codec, CodecLimits
from .commands import (
    Bye,
    Command,
    DataFrame,
    Define,
    Invoke,
    List,
    Ping,
    Read,
    Stats,
    StreamStart,
    StreamStop,
    Undefine,
    Write,
)
from .exceptions import AstcomError, ConnectionClosed, Forbidden
from .protocol import ClientConnection, ClientState, DataReceived, Failure, Ready, Reply
from .push_transport import PushTransport, open_push_transport
from .registry import VariableInfo
from .timing import sample_offsets_us
from .transports import Transport, client_ssl_context
from .url import parse_url

__all__ = ["Client", "MessageInfo", "Stream", "StreamPacket"]

log = logging.getLogger("astcom.client")

DEFAULT_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class MessageInfo:
    """A message defined on this connection."""

    msg: int
    names: tuple[str, ...]
    types: tuple[str, ...]


@dataclass(frozen=True)
class StreamPacket:
    """A block of samples of one stream.

    `values[i, j]` is column `names[j]` at tick `ticks[i]`, time `t_us[i]` (mount time,
    integer µs). `lost` counts the samples missing just before this packet (from the
    tick and sequence gaps), `seq` is the endpoint's packet number.
    """

    msg: int
    seq: int
    first_tick: int
    first_t_us: int
    period_us: float
    period_ticks: int
    names: tuple[str, ...]
    values: np.ndarray
    lost: int = 0
    arrays: tuple[np.ndarray, ...] = field(default=(), repr=False, compare=False)
    where: Mapping[str, tuple[int, int]] = field(default_factory=dict, repr=False, compare=False)

    @property
    def n(self) -> int:
        return int(self.values.shape[0])

    @cached_property
    def t_us(self) -> np.ndarray:
        """Return the sample times, int64 µs (the exact rounding rule of the spec, §6).

        Computed once a packet (its consumers, the VSS, the recorder, the panel, ask for
        them several times); the packet is frozen, so are they."""
        t = self.first_t_us + sample_offsets_us(self.period_us, self.n)
        t.flags.writeable = False
        return t

    @property
    def ticks(self) -> np.ndarray:
        """Return the sample ticks, int64."""
        return self.first_tick + np.arange(self.n, dtype=np.int64) * self.period_ticks

    def column(self, name: str) -> np.ndarray:
        """Return the samples of one column by name, in the column's own dtype."""
        if name in self.where:
            group, j = self.where[name]
            return self.arrays[group][:, j]
        return self.values[:, self.names.index(name)]


class Stream:
    """A running stream: iterate packets, or bind callbacks per packet or per sample.

    When a callback is bound, packets go to the callbacks instead of the iteration queue.
    The queue keeps `queue_packets` packets; a consumer slower than that loses the oldest
    ones, counted in the next packet's `lost`.
    """

    def __init__(self, client: Client, msg: int, reply: dict[str, Any], queue_packets: int) -> None:
        self.client = client
        self.msg = msg
        self.rate_hz = float(reply["rate_hz"])
        self.period_ticks = int(reply["period_ticks"])
        self.samples_per_packet = int(reply["samples_per_packet"])
        self.names: tuple[str, ...] = tuple(reply["columns"])
        self._groups = [np.asarray(g, dtype=np.intp) for g in reply["groups"]]
        self._identity = (len(self._groups) == 1
                          and np.array_equal(self._groups[0], np.arange(len(self.names))))
        self._where = {} if self._identity else {
            self.names[col]: (g, j) for g, cols in enumerate(self._groups) for j, col in enumerate(cols)}
        self._queue: deque[StreamPacket] = deque(maxlen=queue_packets)
        self._event = asyncio.Event()
        self._packet_callbacks: list[Callable[[StreamPacket], None]] = []
        self._sample_callbacks: list[Callable[[int, np.ndarray], None]] = []
        self._next_tick: int | None = None
        self._next_seq: int | None = None
        self._carry_lost = 0
        self.samples = 0
        self.lost = 0
        self.packets = 0
        self.lost_packets = 0
        self.skipped_samples = 0  # ticks the device never computed (not a loss)
        self.stopped = False

    def on_packet(self, callback: Callable[[StreamPacket], None]) -> None:
        """Call `callback(packet)` for every packet (on the client's reader task)."""
        self._packet_callbacks.append(callback)

    def on_sample(self, callback: Callable[[int, np.ndarray], None]) -> None:
        """Call `callback(t_us, row)` for every sample (on the client's reader task)."""
        self._sample_callbacks.append(callback)

    def _receive(self, data: DataFrame) -> None:
        if data.period_ticks != self.period_ticks:
            return  # still in flight from this message's previous rate
        values, arrays = self._assemble(data)
        lost = 0
        dropped = self._next_seq is not None and data.seq > self._next_seq
        if dropped:
            self.lost_packets += data.seq - self._next_seq
        if self._next_tick is not None and data.first_tick > self._next_tick:
            missing = (data.first_tick - self._next_tick) // max(1, data.period_ticks)
            # spec §6: a seq jump means dropped packets; seq + 1 means the device skipped ticks
            if dropped:
                lost = missing
            else:
                self.skipped_samples += missing
        self._next_tick = data.first_tick + data.n * data.period_ticks
        self._next_seq = data.seq + 1
        packet = StreamPacket(data.msg, data.seq, data.first_tick, data.first_t_us, data.period_us,
                              data.period_ticks, self.names, values, lost, arrays, self._where)
        self.lost += lost
        self.samples += packet.n
        self.packets += 1
        if self._packet_callbacks or self._sample_callbacks:
            try:
                for cb in self._packet_callbacks:
                    cb(packet)
                if self._sample_callbacks:
                    for t_us, row in zip(packet.t_us.tolist(), values, strict=True):
                        for scb in self._sample_callbacks:
                            scb(t_us, row)
            except Exception:  # a user's callback must not take the connection down
                log.exception("stream %d: a callback raised; the stream goes on", self.msg)
            return
        if len(self._queue) == self._queue.maxlen:
            dropped = self._queue.popleft()
            self._carry_lost += dropped.n
            self.lost += dropped.n
        if self._carry_lost:
            packet = StreamPacket(**{**packet.__dict__, "lost": packet.lost + self._carry_lost})
            self._carry_lost = 0
        self._queue.append(packet)
        self._event.set()

    def _assemble(self, data: DataFrame) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
        if len(data.arrays) != len(self._groups):
            raise AstcomError(f"stream {self.msg}: packet has {len(data.arrays)} arrays, layout "
                              f"{len(self._groups)}")
        arrays = tuple(np.asarray(a).reshape(data.n, len(cols))
                       for a, cols in zip(data.arrays, self._groups, strict=True))
        if self._identity:
            return arrays[0], arrays
        out = np.empty((data.n, len(self.names)), dtype=np.float64)
        for cols, arr in zip(self._groups, arrays, strict=True):
            out[:, cols] = arr
        return out, arrays

    def _end(self) -> None:
        self.stopped = True
        self._event.set()

    def __aiter__(self) -> Stream:
        return self

    async def __anext__(self) -> StreamPacket:
        while not self._queue:
            if self.stopped:
                raise StopAsyncIteration
            self._event.clear()
            await self._event.wait()
        return self._queue.popleft()

    async def get(self, timeout_s: float | None = None) -> StreamPacket:
        """Return the next packet; raise TimeoutError after `timeout_s`."""
        async with asyncio.timeout(timeout_s):
            return await self.__anext__()

    async def stop(self) -> None:
        """Stop the stream on the endpoint; iteration ends after the queued packets."""
        if not self.stopped:
            self.stopped = True
            self._event.set()
            self.client._streams.pop(self.msg, None)
            if self.client.connected:
                await self.client._request(StreamStop(self.msg))


class Client:
    """An ASTCom connection; create it with `await Client.connect(url, password=...)`."""

    def __init__(self, transport: Transport, conn: ClientConnection, *,
                 timeout_s: float = DEFAULT_TIMEOUT_S, queue_packets: int = 1024) -> None:
        self._transport = transport
        self._conn = conn
        self.timeout_s = timeout_s
        self.queue_packets = queue_packets
        self._pending: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self._ready: asyncio.Future[Ready] = asyncio.get_running_loop().create_future()
        self._messages: dict[tuple[str, ...], MessageInfo] = {}
        self._streams: dict[int, Stream] = {}
        self._reader: asyncio.Task[None] | None = None
        self._closed_error: AstcomError | None = None
        self._last_error: AstcomError | None = None
        self.hello: dict[str, Any] = {}

    # -- opening and closing ------------------------------------------------------------------
    @classmethod
    async def connect(cls, url: str, *, password: str | None = None, role: str | None = None,
                      name: str = "astcom-client", cafile: str | None = None,
                      ssl_context: ssl.SSLContext | None = None,
                      timeout_s: float = DEFAULT_TIMEOUT_S, max_frame_bytes: int = 1 << 24,
                      queue_packets: int = 1024) -> Client:
        """Connect to `url`, say HELLO and authenticate; raise ConnectionError or AstcomError.

        `role` ("observer"/"operator") asks for at most that role; by default the endpoint
        grants the highest role whose password matches.
        """
        where = parse_url(url)
        if where.secure and ssl_context is None:
            ssl_context = client_ssl_context(cafile)
        transport = await open_push_transport(where, max_frame_bytes=max_frame_bytes,
                                              ssl_context=ssl_context, timeout_s=timeout_s)
        return await cls.open(transport, password=password, role=role, name=name,
                              timeout_s=timeout_s, max_frame_bytes=max_frame_bytes,
                              queue_packets=queue_packets)

    @classmethod
    async def open(cls, transport: Transport, *, password: str | None = None,
                   role: str | None = None, name: str = "astcom-client",
                   timeout_s: float = DEFAULT_TIMEOUT_S, max_frame_bytes: int = 1 << 24,
                   queue_packets: int = 1024) -> Client:
        """Run the handshake over an already open transport (e.g. `Endpoint.connect_in_memory()`)."""
        codec = Codec(CodecLimits(max_frame_bytes=max_frame_bytes, max_array_len=10_000_000,
                                  max_str_bytes=max_frame_bytes))
        conn = ClientConnection(codec, password=password, role=role, client_name=name)
        client = cls(transport, conn, timeout_s=timeout_s, queue_packets=queue_packets)
        if isinstance(transport, PushTransport):
            transport.start(client._on_frame, client._on_closed)
        else:
            client._reader = asyncio.get_running_loop().create_task(client._read_loop())
        conn.start()
        try:
            # An endpoint that refuses (429, 503) says why and closes at once: its reason may
            # already be here, before our HELLO (then sending it fails). Its reason, not the
            # closed socket.
            if client._ready.done() and client._ready.exception() is not None:
                raise client._ready.exception()
            await client._flush()
            async with asyncio.timeout(timeout_s):
                ready = await asyncio.shield(client._ready)
        except ConnectionClosed as exc:
            await client._abort()
            refusal = client._ready.exception() if client._ready.done() else None
            if isinstance(refusal, AstcomError) and refusal is not exc:
                raise refusal from None
            raise
        except BaseException:
            await client._abort()
            raise
        client.hello = ready.hello
        if role == "operator" and ready.role.label != "operator":
            await client.close()
            raise Forbidden("the password grants the observer role, not operator")
        return client

    async def __aenter__(self) -> Client:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    @property
    def connected(self) -> bool:
        return self._conn.state is ClientState.READY and self._closed_error is None

    @property
    def role(self) -> str:
        """Return the granted role: "observer" or "operator"."""
        return self._conn.role.label

    async def close(self) -> None:
        """Say BYE (when still connected) and close."""
        if self.connected:
            with contextlib.suppress(AstcomError, TimeoutError, asyncio.TimeoutError):
                async with asyncio.timeout(2.0):
                    await self._request(Bye())
        await self._abort()

    async def _abort(self) -> None:
        with contextlib.suppress(Exception):
            await self._transport.close()
        if self._reader is not None and not self._reader.done():
            self._reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._reader
        self._fail_all(self._closed_error or ConnectionClosed("the client closed the connection"))

    # -- requests --------------------------------------------------------------------------------
    async def list(self, prefix: str = "") -> list[VariableInfo]:
        """Return every variable and function whose name starts with `prefix`."""
        result = await self._request(List(prefix))
        fields = ("name", "type", "kind", "access", "unit", "doc")
        return [VariableInfo(**{k: str(e.get(k, "")) for k in fields},
                             min=_bound(e.get("min")), max=_bound(e.get("max")))
                for e in result["entries"]]

    async def define(self, names: Sequence[str]) -> MessageInfo:
        """Define (or reuse) the message made of `names` and return it."""
        key = tuple(names)
        info = self._messages.get(key)
        if info is None:
            result = await self._request(Define(list(key)))
            info = MessageInfo(int(result["msg"]), key, tuple(result["types"]))
            self._messages[key] = info
        return info

    async def undefine(self, names: Sequence[str] | MessageInfo) -> None:
        """Release a message defined on this connection."""
        info = names if isinstance(names, MessageInfo) else self._messages.get(tuple(names))
        if info is None:
            return
        self._messages.pop(info.names, None)
        stream = self._streams.pop(info.msg, None)
        if stream is not None:
            stream._end()
        await self._request(Undefine(info.msg))

    async def read(self, names: Sequence[str] | str) -> dict[str, Any]:
        """Return {name: value} of `names`, all taken at one tick."""
        values, _, _ = await self.read_at(names)
        return values

    async def read_at(self, names: Sequence[str] | str) -> tuple[dict[str, Any], int, int]:
        """Return ({name: value}, tick, t_us) of `names`, all taken at that tick."""
        key = (names,) if isinstance(names, str) else tuple(names)
        info = await self.define(key)
        result = await self._request(Read(info.msg))
        return dict(zip(info.names, result["values"], strict=True)), result["tick"], result["t_us"]

    async def write(self, values: Mapping[str, Any]) -> int:
        """Write all `values` at once (applied between two ticks); return the tick before."""
        info = await self.define(list(values))
        result = await self._request(Write(info.msg, [_plain(v) for v in values.values()]))
        return int(result["tick"])

    async def invoke(self, name: str, *args: Any) -> Any:
        """Call device function `name` with `args` and return its value."""
        result = await self._request(Invoke(name, [_plain(a) for a in args]))
        return result.get("value")

    async def stream(self, names: Sequence[str] | str, rate_hz: float, *,
                     queue_packets: int | None = None) -> Stream:
        """Start streaming `names` at `rate_hz` (rounded to the loop rate / k) and return it."""
        key = (names,) if isinstance(names, str) else tuple(names)
        info = await self.define(key)
        old = self._streams.pop(info.msg, None)
        if old is not None:
            old._end()
        result = await self._request(StreamStart(info.msg, float(rate_hz)))
        stream = Stream(self, info.msg, result, queue_packets or self.queue_packets)
        self._streams[info.msg] = stream
        return stream

    async def ping(self) -> dict[str, Any]:
        """Return the endpoint's clocks (PING).

        `t_us`: the endpoint host's wall clock (UTC) when it answered, a TimestampUs;
        `tick`: the last tick the device computed (-1 before the first); `tick_t_us`: the
        mount time of that tick, int µs (None before the first tick).
        """
        return await self._request(Ping())

    async def stats(self) -> dict[str, Any]:
        """Return the endpoint's statistics (STATS)."""
        return await self._request(Stats())

    async def _request(self, command: Command) -> dict[str, Any]:
        if self._closed_error is not None:
            raise ConnectionClosed(f"the connection is closed: {self._closed_error}")
        seq = self._conn.send(command)
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._pending[seq] = future
        try:
            await self._flush()
            async with asyncio.timeout(self.timeout_s):  # no extra task, unlike wait_for
                return await future
        finally:
            self._pending.pop(seq, None)

    async def _flush(self) -> None:
        try:
            while (frame := self._conn.next_frame()) is not None:
                await self._transport.send(frame)
        except (ConnectionError, AstcomError) as exc:
            error = ConnectionClosed(f"connection lost while sending: {exc}")
            self._fail_all(error)
            raise error from None

    # -- reader ----------------------------------------------------------------------------------
    async def _read_loop(self) -> None:
        error: AstcomError = ConnectionClosed("the endpoint closed the connection")
        try:
            while True:
                data = await self._transport.recv()
                if data is None:
                    break
                for event in self._conn.receive_frame(data):
                    self._dispatch(event)
                if self._conn.has_output:
                    await self._flush()
        except AstcomError as exc:
            error = exc
        except (ConnectionError, OSError) as exc:
            error = ConnectionClosed(f"connection lost: {exc}")
        finally:
            if self._closed_error is None:
                self._closed_error = self._last_error or error
            self._fail_all(self._closed_error)

    def _on_frame(self, data: bytes) -> None:
        """Handle one frame pushed by a PushTransport (runs inside data_received)."""
        for event in self._conn.receive_frame(data):
            self._dispatch(event)
        while (frame := self._conn.next_frame()) is not None:
            self._transport.write(frame)  # type: ignore[attr-defined]  # handshake replies

    def _on_closed(self, reason: AstcomError) -> None:
        if self._closed_error is None:
            self._closed_error = self._last_error or reason
        self._fail_all(self._closed_error)

    def _dispatch(self, event: Any) -> None:
        if isinstance(event, DataReceived):
            stream = self._streams.get(event.data.msg)
            if stream is not None:
                stream._receive(event.data)
        elif isinstance(event, Reply):
            future = self._pending.get(event.seq)
            if future is not None and not future.done():
                future.set_result(event.result)
        elif isinstance(event, Failure):
            future = self._pending.get(event.seq) if event.seq is not None else None
            if future is not None and not future.done():
                future.set_exception(event.error)
            elif not self._ready.done():
                self._ready.set_exception(event.error)
            else:
                self._last_error = event.error  # the endpoint's reason for closing
        elif isinstance(event, Ready) and not self._ready.done():
            self._ready.set_result(event)

    def _fail_all(self, error: AstcomError) -> None:
        if self._closed_error is None:
            self._closed_error = error
        if not self._ready.done():
            self._ready.set_exception(error)
            self._ready.exception()  # mark retrieved
        for future in self._pending.values():
            if not future.done():
                future.set_exception(error)
                # its waiter raises it; a request whose own send failed (`_flush` raises
                # the error itself) never awaits its future: no "never retrieved" at exit
                future.exception()
        for stream in self._streams.values():
            stream._end()


def _plain(value: Any) -> Any:
    """Return `value` ready for the codec (tuples and numpy scalars are fine as they are)."""
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, Iterable) and not isinstance(value, str | bytes | dict | np.ndarray | list):
        return list(value)
    return value


def _bound(value: Any) -> float | None:
    """A LIST entry's min/max: a number, or absent (nil)."""
    return None if value is None or isinstance(value, bool) else float(value)
