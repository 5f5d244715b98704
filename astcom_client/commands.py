"""One small frozen dataclass per ASTCom command, encoded to and decoded from frames.

A request frame is the msgpack array ``[OP, seq, args]`` where OP is the command name,
seq a client-chosen unsigned integer echoed in the reply and args a map of the fields
below. Replies are ``["OK", seq, result]`` or ``["ERR", seq, {"code", "message"}]``;
stream packets are ``["DATA", ...]`` (see `StreamPacket`). Decoding goes through the
`COMMANDS` table; every class checks its field types so the handlers never see a
malformed request.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from .auth import Role
from .exceptions import MalformedFrame

__all__ = [
    "COMMANDS",
    "PROTOCOL_VERSION",
    "Auth",
    "Bye",
    "Command",
    "Define",
    "Hello",
    "Invoke",
    "List",
    "Ping",
    "Read",
    "Stats",
    "StreamStart",
    "StreamStop",
    "Undefine",
    "Write",
    "decode_request",
]

PROTOCOL_VERSION = "1.0"
MAX_SEQ = 2**63 - 1
_INT = (int,)
_NUM = (int, float)


_FIELD_CACHE: dict[type, tuple[tuple[str, bool], ...]] = {}


def _fields(cls: type) -> tuple[tuple[str, bool], ...]:
    """Return (name, required) of a command's fields, computed once per class."""
    fields = _FIELD_CACHE.get(cls)
    if fields is None:
        fields = tuple((f.name, f.default is dataclasses.MISSING
                        and f.default_factory is dataclasses.MISSING)
                       for f in dataclasses.fields(cls))
        _FIELD_CACHE[cls] = fields
    return fields


@dataclass(frozen=True)
class Command:
    """Base of every request; subclasses set OP, ROLE and SCHEMA."""

    OP: ClassVar[str] = ""
    ROLE: ClassVar[Role] = Role.OBSERVER  # the least role allowed to send it
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {}

    def to_args(self) -> dict[str, Any]:
        """Return the args map sent on the wire."""
        return {name: getattr(self, name) for name, _ in _fields(type(self))}

    def to_frame(self, seq: int) -> list[Any]:
        """Return the request frame ``[OP, seq, args]`` (before msgpack)."""
        return [self.OP, seq, self.to_args()]

    @classmethod
    def from_args(cls, args: dict[str, Any]) -> Command:
        """Build the command from a decoded args map; raise MalformedFrame naming the field."""
        values: dict[str, Any] = {}
        for name, required in _fields(cls):
            if name not in args or (args[name] is None and not required):
                # an optional field sent as nil means its default (spec §3)
                if required:
                    raise MalformedFrame(f"{cls.OP}: missing field {name!r}")
                continue
            value = args[name]
            allowed = cls.SCHEMA[name]
            if not isinstance(value, allowed) or (isinstance(value, bool) and bool not in allowed):
                names = "/".join(t.__name__ for t in allowed)
                raise MalformedFrame(f"{cls.OP}: field {name!r} must be {names}, "
                                     f"got {type(value).__name__}")
            values[name] = value
        return cls(**values)


@dataclass(frozen=True)
class Hello(Command):
    OP: ClassVar[str] = "HELLO"
    ROLE: ClassVar[Role] = Role.NONE
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"version": (str,), "client": (str,)}
    version: str
    client: str = ""


@dataclass(frozen=True)
class Auth(Command):
    OP: ClassVar[str] = "AUTH"
    ROLE: ClassVar[Role] = Role.NONE
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {
        "cnonce": (bytes,), "mac": (bytes,), "role": (str, type(None))}
    cnonce: bytes
    mac: bytes
    role: str | None = None


@dataclass(frozen=True)
class List(Command):
    OP: ClassVar[str] = "LIST"
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"prefix": (str,)}
    prefix: str = ""


@dataclass(frozen=True)
class Define(Command):
    OP: ClassVar[str] = "DEFINE"
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"names": (list,)}
    names: list[str] = field(default_factory=list)

    @classmethod
    def from_args(cls, args: dict[str, Any]) -> Command:
        cmd = super().from_args(args)
        assert isinstance(cmd, Define)
        if "names" not in args or not cmd.names:
            raise MalformedFrame("DEFINE: field 'names' must be a non-empty array of names")
        if not all(isinstance(n, str) for n in cmd.names):
            raise MalformedFrame("DEFINE: every entry of 'names' must be a string")
        return cmd


@dataclass(frozen=True)
class Undefine(Command):
    OP: ClassVar[str] = "UNDEFINE"
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"msg": _INT}
    msg: int


@dataclass(frozen=True)
class Read(Command):
    OP: ClassVar[str] = "READ"
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"msg": _INT}
    msg: int


@dataclass(frozen=True)
class Write(Command):
    OP: ClassVar[str] = "WRITE"
    ROLE: ClassVar[Role] = Role.OPERATOR
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"msg": _INT, "values": (list,)}
    msg: int
    values: list[Any]


@dataclass(frozen=True)
class Invoke(Command):
    OP: ClassVar[str] = "INVOKE"
    ROLE: ClassVar[Role] = Role.OPERATOR
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"name": (str,), "args": (list,)}
    name: str
    args: list[Any] = field(default_factory=list)


@dataclass(frozen=True)
class StreamStart(Command):
    OP: ClassVar[str] = "STREAM_START"
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"msg": _INT, "rate_hz": _NUM}
    msg: int
    rate_hz: float


@dataclass(frozen=True)
class StreamStop(Command):
    OP: ClassVar[str] = "STREAM_STOP"
    SCHEMA: ClassVar[dict[str, tuple[type, ...]]] = {"msg": _INT}
    msg: int


@dataclass(frozen=True)
class Ping(Command):
    OP: ClassVar[str] = "PING"
    ROLE: ClassVar[Role] = Role.NONE


@dataclass(frozen=True)
class Stats(Command):
    OP: ClassVar[str] = "STATS"


@dataclass(frozen=True)
class Bye(Command):
    OP: ClassVar[str] = "BYE"
    ROLE: ClassVar[Role] = Role.NONE


COMMANDS: dict[str, type[Command]] = {
    cls.OP: cls
    for cls in (Hello, Auth, List, Define, Undefine, Read, Write, Invoke, StreamStart,
                StreamStop, Ping, Stats, Bye)
}


def decode_request(frame: Any) -> tuple[int, Command]:
    """Return (seq, command) from a decoded request frame; raise MalformedFrame."""
    if not isinstance(frame, list) or len(frame) != 3:
        raise MalformedFrame("a request frame is the array [OP, seq, args]")
    op, seq, args = frame
    if not isinstance(seq, int) or isinstance(seq, bool) or not 0 <= seq <= MAX_SEQ:
        raise MalformedFrame("request seq must be an unsigned integer below 2**63")
    cls = COMMANDS.get(op) if isinstance(op, str) else None
    if cls is None:
        raise MalformedFrame(f"unknown command {op!r}; expected one of {' '.join(COMMANDS)}",
                             ) from None
    if not isinstance(args, dict):
        raise MalformedFrame(f"{op}: args must be a map")
    return seq, cls.from_args(args)


@dataclass(slots=True)  # not frozen: frozen dataclasses are slow to build on the hot path
class DataFrame:
    """A stream packet as sent on the wire.

    ``["DATA", msg, seq, first_tick, first_t_us, period_us, period_ticks, n, arrays]``:
    sample i (0 ≤ i < n) was taken at tick ``first_tick + i * period_ticks`` and time
    ``first_t_us + round_half_up(i * period_us)`` (see timing.py); ``arrays`` holds one 2-D array (n × columns)
    per dtype group of the stream's layout.
    """

    msg: int
    seq: int
    first_tick: int
    first_t_us: int
    period_us: float
    period_ticks: int
    n: int
    arrays: list[Any]

    def to_frame(self) -> list[Any]:
        """Return the DATA frame (before msgpack)."""
        return data_frame(self.msg, self.seq, self.first_tick, self.first_t_us, self.period_us,
                          self.period_ticks, self.n, self.arrays)

    @classmethod
    def from_frame(cls, frame: list[Any]) -> DataFrame:
        """Build from a decoded DATA frame; raise MalformedFrame on a wrong layout."""
        if len(frame) != 9:
            raise MalformedFrame(f"a DATA frame has 9 elements, got {len(frame)}")
        _, msg, seq, first_tick, first_t_us, period_us, period_ticks, n, arrays = frame
        for value in (msg, seq, first_tick, first_t_us, period_ticks, n):
            if type(value) is not int:
                raise MalformedFrame("DATA: msg, seq, first_tick, first_t_us, period_ticks, n "
                                     "must be integers")
        if type(arrays) is not list or not isinstance(period_us, int | float):
            raise MalformedFrame("DATA: period_us must be a number and arrays an array")
        return cls(msg, seq, first_tick, first_t_us, float(period_us), period_ticks, n, arrays)


def data_frame(msg: int, seq: int, first_tick: int, first_t_us: int, period_us: float,
               period_ticks: int, n: int, arrays: list[Any]) -> list[Any]:
    """Return a DATA frame (before msgpack) without building a DataFrame (the hot path)."""
    return ["DATA", msg, seq, first_tick, first_t_us, period_us, period_ticks, n, arrays]
