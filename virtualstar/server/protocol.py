"""VSS client API messages: JSON text frames over a WebSocket (docs/vss-api.md).

::

    client → server   {"id": 7, "cmd": "slew", "params": {"star": "Vega"}}
    server → client   {"id": 7, "ok": true, "result": {...}}
                      {"id": 7, "ok": false, "error": {"code": "bad_request", "message": "..."}}
    server → client   {"event": "fault", "data": {...}, "seq": 12}      (pushed, no id)

Every connection starts with a ``hello`` event and receives a ``heartbeat``
event every second, so a client notices a silent server even while the socket
stays open. These dataclasses are the only place that knows the layout.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

from .exceptions import BadRequest

__all__ = ["API_VERSION", "ErrorReply", "Event", "Reply", "Request", "decode_request", "encode"]

API_VERSION = 1
MAX_MESSAGE_BYTES = 1 << 20
# Security limits of the JSON reader (docs/vss-api.md, "Limits"): a message nested
# deeper, or holding a longer number, is refused with bad_request before anything
# looks at it. Python's own reader would raise RecursionError or ValueError instead.
MAX_DEPTH = 32
MAX_NUMBER_CHARS = 40  # digits, sign, point and exponent: far beyond any float or int64


@dataclass(frozen=True)
class Request:
    """A command from a client; `id` is echoed in the reply."""

    id: int | str
    cmd: str
    params: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps({"id": self.id, "cmd": self.cmd, "params": self.params})


@dataclass(frozen=True)
class Reply:
    """A successful answer to request `id`."""

    id: int | str
    result: Any

    def to_json(self) -> str:
        return encode({"id": self.id, "ok": True, "result": self.result})


@dataclass(frozen=True)
class ErrorReply:
    """A refused request: a short `code` and a message saying what was wrong and what is expected."""

    id: int | str | None
    code: str
    message: str

    def to_json(self) -> str:
        return encode({"id": self.id, "ok": False, "error": {"code": self.code,
                                                              "message": self.message}})


@dataclass(frozen=True)
class Event:
    """A server-pushed event (state change, fault, progress, heartbeat)."""

    event: str
    data: dict[str, Any]
    seq: int = 0

    def to_json(self) -> str:
        return encode({"event": self.event, "data": self.data, "seq": self.seq})


def _clean(value: Any) -> Any:
    """Replace NaN/inf (not JSON) by None, numpy scalars by Python numbers, recursively."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, str | bytes):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def encode(doc: dict[str, Any]) -> str:
    """Return the JSON text of a message (NaN and infinities become null)."""
    return json.dumps(_clean(doc), allow_nan=False)


class _Refused(Exception):
    """A number or constant the reader refuses (raised from its hooks)."""


def _number(kind: type):
    def parse(text: str):
        if len(text) > MAX_NUMBER_CHARS:
            raise _Refused(f"a number of {len(text)} characters (at most {MAX_NUMBER_CHARS})")
        value = kind(text)
        if kind is float and not math.isfinite(value):
            raise _Refused(f"the number {text[:20]}, beyond the range of a float")
        return value
    return parse


def _constant(text: str):
    raise _Refused(f"{text}, which is not a JSON number")


_DECODER = json.JSONDecoder(parse_int=_number(int), parse_float=_number(float),
                            parse_constant=_constant)


def _depth_exceeds(doc: Any, limit: int) -> bool:
    """True when `doc` nests containers deeper than `limit` (iterative: no recursion)."""
    stack = [(doc, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            value = value.values()
        elif not isinstance(value, list):
            continue
        if depth > limit:
            return True
        stack.extend((v, depth + 1) for v in value if isinstance(v, dict | list))
    return False


def decode_request(text: str | bytes) -> Request:
    """Parse one client frame; raise BadRequest saying what is wrong and the expected layout.

    The BadRequest carries the request's `id` (`.request_id`) once it is known, so the
    error reply can echo it.
    """
    layout = 'expected {"id": <number or text>, "cmd": "<command>", "params": {...}}'
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise BadRequest(f"the frame is not UTF-8 text; {layout}") from None
    if len(text) > MAX_MESSAGE_BYTES:
        raise BadRequest(f"the message has {len(text)} bytes, more than {MAX_MESSAGE_BYTES}")
    try:
        doc = _DECODER.decode(text)
    except json.JSONDecodeError as exc:
        raise BadRequest(f"the message is not JSON ({exc.msg} at character {exc.pos}); "
                         f"{layout}") from None
    except _Refused as exc:
        raise BadRequest(f"the message holds {exc}; {layout}") from None
    except RecursionError:
        raise BadRequest(f"the message nests deeper than {MAX_DEPTH} levels") from None
    if _depth_exceeds(doc, MAX_DEPTH):
        raise BadRequest(f"the message nests deeper than {MAX_DEPTH} levels")
    if not isinstance(doc, dict):
        raise BadRequest(f"the message is a JSON {type(doc).__name__}, not an object; {layout}")
    rid = doc.get("id")
    if isinstance(rid, bool) or not isinstance(rid, int | str) or not _plain_id(rid):
        raise BadRequest(f"'id' is {_short(rid)}; {layout} (an integer of at most 64 bits, or "
                         f"text of at most {MAX_ID_CHARS} characters)")
    cmd = doc.get("cmd")
    if not isinstance(cmd, str) or not cmd or len(cmd) > 64:
        raise _with_id(BadRequest(f"'cmd' is {_short(cmd)}; {layout}"), rid)
    params = doc.get("params", {})
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise _with_id(BadRequest(f"'params' is a {type(params).__name__}, not an object; "
                                  f"{layout}"), rid)
    extra = sorted(set(doc) - {"id", "cmd", "params"})
    if extra:
        raise _with_id(BadRequest(f"unknown keys {_short(extra)} in the message; {layout}"), rid)
    return Request(rid, cmd, params)


MAX_ID_CHARS = 128


def _plain_id(rid: int | str) -> bool:
    if isinstance(rid, str):
        return len(rid) <= MAX_ID_CHARS
    return -(2**63) <= rid < 2**63


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _with_id(exc: BadRequest, rid: int | str) -> BadRequest:
    exc.request_id = rid  # type: ignore[attr-defined]
    return exc
