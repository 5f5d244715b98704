"""What an Endpoint does with checked requests, without I/O: the message register,
command execution against a Collection, and stream sampling in `publish`.

Everything here runs on the device loop's thread between two blocks of ticks, which is
what makes a WRITE land between two ticks and a READ see one consistent tick.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .auth import Role
from .codec import Codec, TimestampUs
from .commands import (
    Command,
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
    data_frame,
)
from .exceptions import (
    DeviceError,
    InvalidValue,
    LimitExceeded,
    NotWritable,
    TooMany,
    UnknownMessage,
)
from .protocol import ServerConnection
from .registry import Collection, Function, Variable
from .timing import round_half_up

__all__ = ["MAX_PERIOD_TICKS", "EndpointService", "PendingInvoke", "ServiceLimits"]

# The slowest stream: one sample every 2^32 ticks (5 days at 10 kHz). It keeps period_ticks,
# and every tick a stream names, far below 2^53 (spec §2.4, §6).
MAX_PERIOD_TICKS = 2**32


@dataclass(frozen=True)
class ServiceLimits:
    """Per-endpoint limits on the register and on streams."""

    max_messages: int = 4096
    max_names_per_message: int = 1024
    max_streams_per_client: int = 64
    max_array_len: int = 100_000
    flush_interval_s: float = 0.02


@dataclass
class MessageDef:
    """A DEFINEd list of variables, shared by every connection that defined the same list."""

    msg: int
    variables: tuple[Variable, ...]
    holders: set[int] = field(default_factory=set)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables)


@dataclass
class _Group:
    """The buffer of one dtype group of a stream: columns of the same numeric dtype."""

    type_name: str  # ASTCom element type of the group, e.g. "f64"
    dtype: np.dtype
    columns: list[int]  # column indices in the message's flat column list
    traced_pos: np.ndarray  # buffer columns filled from the trace
    trace_cols: np.ndarray  # ... from these trace columns
    getters: list[tuple[int, int, Variable]]  # (buffer col, width, variable) read via get()
    buf: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    untraced: list[tuple[int, int, Variable]] = field(default_factory=list)
    all_traced: bool = False  # every buffer column, in order, comes from the trace


class StreamGroup:
    """One message sampled every `k` ticks, shared by all connections streaming it at that rate."""

    def __init__(self, message: MessageDef, k: int, samples_per_packet: int,
                 loop_rate_hz: float) -> None:
        self.message = message
        self.k = k
        self.spp = samples_per_packet
        self.period_us = k * 1e6 / loop_rate_hz  # as the spec writes it, to the last bit
        self.subscribers: dict[int, ServerConnection] = {}
        self.seq = 0
        self.fill = 0
        self.packet_tick = 0
        self.packet_t_us = 0
        self.columns: list[str] = []
        self.groups: list[_Group] = []
        self._build_layout()

    def _build_layout(self) -> None:
        by_dtype: dict[str, _Group] = {}
        for var in self.message.variables:
            base, width = var.spec.base, var.spec.n_columns
            group = by_dtype.get(base)
            if group is None:
                group = _Group(base, np.dtype(var.spec.dtype), [], np.empty(0, np.intp),
                               np.empty(0, np.intp), [])
                by_dtype[base] = group
                self.groups.append(group)
            pos = len(group.columns)
            first = len(self.columns)
            if width == 1:
                self.columns.append(var.name)
            else:
                self.columns += [f"{var.name}[{i}]" for i in range(width)]
            group.columns += range(first, first + width)
            if var.trace_column is not None:
                group.traced_pos = np.append(group.traced_pos, pos)
                group.trace_cols = np.append(group.trace_cols, var.trace_column)
            group.getters.append((pos, width, var))
        for group in self.groups:
            group.buf = np.zeros((self.spp, len(group.columns)), dtype=group.dtype)
            group.untraced = [g for g in group.getters if g[2].trace_column is None]
            group.all_traced = np.array_equal(group.traced_pos, np.arange(len(group.columns)))

    def layout(self) -> dict[str, Any]:
        """Return the column layout sent in the STREAM_START reply."""
        return {"columns": self.columns, "dtypes": [g.type_name for g in self.groups],
                "groups": [g.columns for g in self.groups]}

    @property
    def trace_columns(self) -> set[int]:
        return {int(c) for g in self.groups for c in g.trace_cols}

    def sample(self, first_tick: int, first_t_us: int, n_ticks: int, tick_period_us: float,
               trace: np.ndarray | None, codec: Codec) -> None:
        """Copy the samples due in ticks [first_tick, first_tick + n_ticks) into the buffers."""
        k = self.k
        start = -(-first_tick // k) * k  # first tick on the absolute k-grid
        if start >= first_tick + n_ticks:
            return
        if self.fill and start != self.packet_tick + self.fill * k:
            self._flush(codec, self.fill)  # the device skipped ticks: no packet spans a gap
        # The rows due are an arithmetic progression: strided views of the trace, no index
        # arrays (this runs once per device block, hundreds of times a second).
        first_row = start - first_tick
        n_rows = -(-(n_ticks - first_row) // k)
        current = [self._current_row(g, trace is None) for g in self.groups]
        done = 0
        while done < n_rows:
            if self.fill == 0:
                tick = start + done * k
                self.packet_tick = tick
                self.packet_t_us = first_t_us + round_half_up((tick - first_tick) * tick_period_us)
            take = min(n_rows - done, self.spp - self.fill)
            a = first_row + done * k
            rows = trace[a:a + (take - 1) * k + 1:k] if trace is not None else None
            for group, row in zip(self.groups, current, strict=True):
                target = group.buf[self.fill:self.fill + take]
                if row is not None:
                    target[:] = row
                if rows is None or not len(group.trace_cols):
                    continue
                if group.all_traced:  # one copy, straight into the packet buffer
                    # (mode="clip": the columns are the layout's own, always in range, and
                    # np.take's default checks them through a temporary copy, 2-3x slower)
                    np.take(rows, group.trace_cols, axis=1, out=target, mode="clip")
                else:
                    target[:, group.traced_pos] = rows[:, group.trace_cols]
            self.fill += take
            done += take
            if self.fill == self.spp:
                self._flush(codec, self.spp)

    def _current_row(self, group: _Group, include_traced: bool) -> np.ndarray | None:
        getters = group.getters if include_traced else group.untraced
        if not getters:
            return None
        row = np.zeros(len(group.columns), dtype=group.dtype)
        for pos, width, var in getters:
            value = var.get()
            row[pos:pos + width] = np.ravel(value) if width > 1 else value
        return row

    def _flush(self, codec: Codec, n: int) -> None:
        arrays = [g.buf if n == self.spp else g.buf[:n] for g in self.groups]
        frame = codec.encode(data_frame(self.message.msg, self.seq, self.packet_tick,
                                        self.packet_t_us, self.period_us, self.k, n, arrays))
        self.seq += 1
        self.fill = 0
        for conn in self.subscribers.values():
            conn.push_stream(frame, n)


@dataclass
class PendingInvoke:
    """An INVOKE whose device function returned an awaitable; finish with `complete`."""

    function: Function
    awaitable: Any

    def complete(self, value: Any) -> dict[str, Any]:
        return {"value": _check_return(self.function, value)}


class EndpointService:
    """Execute requests for every connection of one endpoint; sample streams in publish."""

    def __init__(self, collection: Collection, codec: Codec, *, loop_rate_hz: float,
                 limits: ServiceLimits | None = None,
                 clock_us: Callable[[], int] | None = None) -> None:
        self.collection = collection
        self.codec = codec
        self.loop_rate_hz = float(loop_rate_hz)
        self.tick_period_us = 1e6 / self.loop_rate_hz
        self.limits = limits or ServiceLimits()
        self.clock_us = clock_us or (lambda: time.time_ns() // 1000)
        self.connections: dict[int, ServerConnection] = {}
        self.messages: dict[int, MessageDef] = {}
        self._by_names: dict[tuple[str, ...], MessageDef] = {}
        self._next_msg = 1
        self.groups: dict[tuple[int, int], StreamGroup] = {}
        self._streams_of: dict[int, dict[int, StreamGroup]] = {}
        self.tick = -1
        self.t_us = 0
        self.wanted_trace_columns = np.empty(0, dtype=np.intp)
        self.dropped_samples_closed = 0
        self._handlers: dict[type[Command], Callable[[ServerConnection, Any], Any]] = {
            List: self._list, Define: self._define, Undefine: self._undefine, Read: self._read,
            Write: self._write, Invoke: self._invoke, StreamStart: self._stream_start,
            StreamStop: self._stream_stop, Ping: self._ping, Stats: self._stats,
        }

    # -- connections ----------------------------------------------------------------------
    def attach(self, conn: ServerConnection) -> None:
        self.connections[conn.client_id] = conn
        self._streams_of[conn.client_id] = {}

    def detach(self, conn: ServerConnection) -> None:
        """Forget a connection: its streams stop and its message references are released."""
        if self.connections.pop(conn.client_id, None) is None:
            return
        self.dropped_samples_closed += conn.dropped_samples
        for group in list(self._streams_of.pop(conn.client_id, {}).values()):
            self._unsubscribe(conn, group)
        for message in list(self.messages.values()):
            self._release(conn, message)
        self._update_wanted()

    # -- requests -------------------------------------------------------------------------
    def execute(self, conn: ServerConnection, command: Command) -> dict[str, Any] | PendingInvoke:
        """Run one request; return the reply map, or a PendingInvoke to await; raise AstcomError."""
        return self._handlers[type(command)](conn, command)

    def _list(self, conn: ServerConnection, cmd: List) -> dict[str, Any]:
        return {"entries": [info.as_dict() for info in self.collection.infos(cmd.prefix)]}

    def _define(self, conn: ServerConnection, cmd: Define) -> dict[str, Any]:
        if len(cmd.names) > self.limits.max_names_per_message:
            raise LimitExceeded(f"DEFINE of {len(cmd.names)} names; at most "
                                f"{self.limits.max_names_per_message} per message")
        names = tuple(cmd.names)
        message = self._by_names.get(names)
        if message is None:
            variables = tuple(self.collection.variable(n) for n in names)
            if len(self.messages) >= self.limits.max_messages:
                raise TooMany(f"the register holds {self.limits.max_messages} messages; "
                              "UNDEFINE some first")
            message = MessageDef(self._next_msg, variables)
            self._next_msg += 1
            self.messages[message.msg] = message
            self._by_names[names] = message
        message.holders.add(conn.client_id)
        return {"msg": message.msg, "types": [v.type for v in message.variables]}

    def _message(self, conn: ServerConnection, msg: int) -> MessageDef:
        message = self.messages.get(msg)
        if message is None or conn.client_id not in message.holders:
            raise UnknownMessage(f"message {msg} is not defined on this connection; DEFINE it first")
        return message

    def _undefine(self, conn: ServerConnection, cmd: Undefine) -> dict[str, Any]:
        message = self._message(conn, cmd.msg)
        self._release(conn, message)
        self._update_wanted()
        return {}

    def _release(self, conn: ServerConnection, message: MessageDef) -> None:
        if conn.client_id not in message.holders:
            return
        streams = self._streams_of.get(conn.client_id, {})
        group = streams.pop(message.msg, None)
        if group is not None:
            self._unsubscribe(conn, group)
        message.holders.discard(conn.client_id)
        if not message.holders:
            del self.messages[message.msg]
            del self._by_names[message.names]

    def _read(self, conn: ServerConnection, cmd: Read) -> dict[str, Any]:
        message = self._message(conn, cmd.msg)
        values = [v.spec.to_wire(v.get()) for v in message.variables]
        return {"tick": self.tick, "t_us": self.t_us, "values": values}

    def _write(self, conn: ServerConnection, cmd: Write) -> dict[str, Any]:
        message = self._message(conn, cmd.msg)
        if len(cmd.values) != len(message.variables):
            raise InvalidValue(f"WRITE of message {cmd.msg}: {len(cmd.values)} values for "
                               f"{len(message.variables)} variables {list(message.names)}")
        for var in message.variables:
            if not var.writable:
                raise NotWritable(f"{var.name} is read-only (kind {var.kind}, access {var.access})")
        # Check every value before setting any, so a message is applied whole or not at all.
        coerced = [v.spec.coerce(x, where=v.name) for v, x in zip(message.variables, cmd.values,
                                                                 strict=True)]
        for var, value in zip(message.variables, coerced, strict=True):
            var.check_range(value)
        for var, value in zip(message.variables, coerced, strict=True):
            assert var.set is not None
            try:
                var.set(value)
            except (ValueError, TypeError) as exc:
                raise InvalidValue(f"{var.name}: the device refused {value!r}: {exc}") from None
        return {"tick": self.tick}

    def _invoke(self, conn: ServerConnection, cmd: Invoke) -> dict[str, Any] | PendingInvoke:
        function = self.collection.function(cmd.name)
        if len(cmd.args) != len(function.args):
            raise InvalidValue(f"{function.name} takes {len(function.args)} arguments "
                               f"{function.signature}, got {len(cmd.args)}")
        args = [spec.coerce(value, where=f"{function.name}({name})")
                for (name, spec), value in zip(function.args, cmd.args, strict=True)]
        try:
            value = function.fn(*args)
        except Exception as exc:
            raise DeviceError(f"{function.name} failed: {type(exc).__name__}: {exc}") from None
        if inspect.isawaitable(value):
            return PendingInvoke(function, value)
        return {"value": _check_return(function, value)}

    def _stream_start(self, conn: ServerConnection, cmd: StreamStart) -> dict[str, Any]:
        message = self._message(conn, cmd.msg)
        bad = [f"{v.name} ({v.type})" for v in message.variables if v.spec.n_columns == 0]
        if bad:
            raise InvalidValue(f"cannot stream {', '.join(bad)}: streams carry numeric scalars "
                               "and fixed-size numeric arrays")
        lowest = self.loop_rate_hz / MAX_PERIOD_TICKS
        if not lowest <= cmd.rate_hz <= self.loop_rate_hz * (1 + 1e-9):
            raise InvalidValue(f"rate_hz {cmd.rate_hz} out of range: expected {lowest:.6g} <= "
                               f"rate_hz <= {self.loop_rate_hz:g}: at most the device loop rate "
                               "(every tick), at least one sample every 2^32 ticks")
        streams = self._streams_of[conn.client_id]
        if cmd.msg not in streams and len(streams) >= self.limits.max_streams_per_client:
            raise TooMany(f"this connection already runs {len(streams)} streams (the maximum)")
        k = max(1, round(self.loop_rate_hz / cmd.rate_hz))
        group = self.groups.get((cmd.msg, k))
        if group is None:
            n_columns = sum(v.spec.n_columns for v in message.variables)
            spp = round(self.loop_rate_hz / k * self.limits.flush_interval_s)
            spp = max(1, min(spp, self.limits.max_array_len // max(1, n_columns)))
            group = StreamGroup(message, k, spp, self.loop_rate_hz)
            self.groups[(cmd.msg, k)] = group
        old = streams.get(cmd.msg)
        if old is not None and old is not group:
            self._unsubscribe(conn, old)
        streams[cmd.msg] = group
        group.subscribers[conn.client_id] = conn
        self._update_wanted()
        return {"msg": cmd.msg, "rate_hz": self.loop_rate_hz / k, "period_ticks": k,
                "period_us": group.period_us, "samples_per_packet": group.spp, **group.layout()}

    def _stream_stop(self, conn: ServerConnection, cmd: StreamStop) -> dict[str, Any]:
        group = self._streams_of[conn.client_id].pop(cmd.msg, None)
        if group is None:
            raise UnknownMessage(f"no stream of message {cmd.msg} runs on this connection")
        self._unsubscribe(conn, group)
        self._update_wanted()
        return {}

    def _unsubscribe(self, conn: ServerConnection, group: StreamGroup) -> None:
        group.subscribers.pop(conn.client_id, None)
        if not group.subscribers:
            self.groups.pop((group.message.msg, group.k), None)

    def _ping(self, conn: ServerConnection, cmd: Ping) -> dict[str, Any]:
        # t_us: the endpoint host's wall clock now; tick_t_us: the device (mount) time of the
        # last computed tick. Both, so a client can estimate either offset (spec §4, PING).
        return {"t_us": TimestampUs(self.clock_us()), "tick": self.tick,
                "tick_t_us": self.t_us if self.tick >= 0 else None}

    def _stats(self, conn: ServerConnection, cmd: Stats) -> dict[str, Any]:
        return self.stats()

    def stats(self) -> dict[str, Any]:
        """Return clients, streams, dropped samples and queue depths (the STATS reply)."""
        clients = [{"id": c.client_id, "name": c.peer_name, "role": c.role.label,
                    "streams": len(self._streams_of.get(c.client_id, {})),
                    "queue_depth": c.queue_depth, "dropped_samples": c.dropped_samples,
                    "dropped_packets": c.dropped_packets}
                   for c in self.connections.values()]
        return {
            "clients": len(self.connections),
            "pending": sum(1 for c in self.connections.values() if c.role is Role.NONE),
            "streams": sum(len(s) for s in self._streams_of.values()),
            "sampling_groups": len(self.groups),
            "messages": len(self.messages),
            "tick": self.tick,
            "t_us": self.t_us,
            "dropped_samples": self.dropped_samples_closed + sum(c["dropped_samples"] for c in clients),
            "queue_depths": {str(c["id"]): c["queue_depth"] for c in clients},
            "per_client": clients,
        }

    def _update_wanted(self) -> None:
        cols: set[int] = set()
        for group in self.groups.values():
            cols |= group.trace_columns
        self.wanted_trace_columns = np.array(sorted(cols), dtype=np.intp)

    # -- device loop ------------------------------------------------------------------------
    def publish(self, first_tick: int, first_t_us: int, n_ticks: int,
                trace: np.ndarray | None) -> None:
        """Record that ticks [first_tick, first_tick + n_ticks) are computed; sample streams."""
        if n_ticks <= 0:
            return
        self.tick = first_tick + n_ticks - 1
        self.t_us = first_t_us + round_half_up((n_ticks - 1) * self.tick_period_us)
        for group in list(self.groups.values()):
            group.sample(first_tick, first_t_us, n_ticks, self.tick_period_us, trace, self.codec)


def _check_return(function: Function, value: Any) -> Any:
    if function.returns is None:
        return None
    try:
        return function.returns.to_wire(function.returns.coerce(value, where=function.name))
    except InvalidValue as exc:
        raise DeviceError(f"{function.name} returned a value that does not match its declared "
                          f"type {function.returns.name}: {exc}") from None
