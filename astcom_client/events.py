"""A device's structured event log: what happened, when, how serious — served over ASTCom.

An event is a plain record, the same in every part of VirtualStar (the emulator, the
VSS, the recorder; docs/events.md)::

    {"seq": 7, "t_us": 1772395200220000, "utc": "2026-03-01T20:00:00.220000Z",
     "source": "emulator", "level": "warning", "kind": "fault",
     "message": "az axis faulted: following error", "fields": {"axis": "az", "bits": 8}}

`t_us` is mount time (µs since 1970 UTC), `level` one of `LEVELS`, `kind` a short word
(state, fault, fault_reset, param, command, clock_sync, underrun, connection, operation,
phase, gap, session, anomaly...), `fields` a flat map of JSON values. `EventLog` keeps
the newest `capacity` events in order with a sequence number, so a reader that asks
for everything after the last `seq` it saw never misses one unless it fell `capacity`
behind (the gap is then visible in `seq`). No I/O and no clock: the caller gives times.
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

__all__ = ["LEVELS", "Event", "EventLog", "level_rank", "utc_text"]

LEVELS = ("debug", "info", "warning", "error")
DEFAULT_CAPACITY = 10_000


def level_rank(level: str) -> int:
    """Return the rank of `level` (debug 0 … error 3); ValueError names the valid ones."""
    try:
        return LEVELS.index(level)
    except ValueError:
        raise ValueError(f"level {level!r}: expected one of {', '.join(LEVELS)}") from None


def utc_text(t_us: int) -> str:
    """Return mount time `t_us` as ISO-8601 UTC text with microseconds."""
    return datetime.fromtimestamp(t_us // 1_000_000, UTC).replace(
        microsecond=t_us % 1_000_000).isoformat().replace("+00:00", "Z")


@dataclass(frozen=True)
class Event:
    """One structured event (see the module docstring for the fields)."""

    t_us: int
    source: str
    level: str
    kind: str
    message: str
    fields: dict[str, Any] = field(default_factory=dict)
    seq: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {"seq": self.seq, "t_us": self.t_us, "utc": utc_text(self.t_us),
                "source": self.source, "level": self.level, "kind": self.kind,
                "message": self.message, "fields": self.fields}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Event:
        """Build an event from its dict form; KeyError/ValueError on a malformed one."""
        level_rank(str(doc["level"]))
        return cls(int(doc["t_us"]), str(doc["source"]), str(doc["level"]), str(doc["kind"]),
                   str(doc.get("message", "")), dict(doc.get("fields") or {}),
                   int(doc.get("seq", 0)))


class EventLog:
    """The newest `capacity` events of one source, numbered from 1."""

    def __init__(self, source: str, *, capacity: int = DEFAULT_CAPACITY) -> None:
        self.source = source
        self._events: deque[Event] = deque(maxlen=capacity)
        self.last_seq = 0

    def add(self, t_us: int, level: str, kind: str, message: str, **fields: Any) -> Event:
        """Append an event at mount time `t_us`; return it (with its `seq`)."""
        level_rank(level)
        self.last_seq += 1
        event = Event(int(t_us), self.source, level, kind, message, fields, self.last_seq)
        self._events.append(event)
        return event

    def since(self, seq: int) -> list[Event]:
        """Return the events numbered after `seq`, oldest first."""
        if not self._events or seq >= self.last_seq:
            return []
        first = self._events[0].seq
        start = max(0, seq + 1 - first)
        return list(self._events)[start:]

    def since_json(self, seq: int) -> str:
        """`since` as a JSON list of dicts (the ASTCom function `log.since` returns this)."""
        return json.dumps([e.as_dict() for e in self.since(int(seq))])
