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


def decode_request(text: str | bytes) -> Request:
    """Parse one client frame; raise BadRequest saying what is wrong and the expected layout."""
    layout = 'expected {"id": <number or text>, "cmd": "<command>", "params": {...}}'
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise BadRequest(f"the frame is not UTF-8 text; {layout}") from None
    if len(text) > MAX_MESSAGE_BYTES:
        raise BadRequest(f"the message has {len(text)} bytes, more than {MAX_MESSAGE_BYTES}")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise BadRequest(f"the message is not JSON ({exc.msg} at character {exc.pos}); "
                         f"{layout}") from None
    if not isinstance(doc, dict):
        raise BadRequest(f"the message is a JSON {type(doc).__name__}, not an object; {layout}")
    rid = doc.get("id")
    if isinstance(rid, bool) or not isinstance(rid, int | str):
        raise BadRequest(f"'id' is {rid!r}; {layout}")
    cmd = doc.get("cmd")
    if not isinstance(cmd, str) or not cmd:
        raise BadRequest(f"'cmd' is {cmd!r}; {layout}")
    params = doc.get("params", {})
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise BadRequest(f"'params' is a {type(params).__name__}, not an object; {layout}")
    extra = sorted(set(doc) - {"id", "cmd", "params"})
    if extra:
        raise BadRequest(f"unknown keys {extra} in the message; {layout}")
    return Request(rid, cmd, params)
