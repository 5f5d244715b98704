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

Kinds that anyone can cause in bulk (connections, failed logins) can be kept apart
(`kept_apart={"connection": 2000, "auth": 2000}`): each such kind has a ring of its
own, so a flood of them pushes out only older events of the same kind, never the
operations, faults, commands and safety events of the main ring. `dropped` counts the
events that fell out of the log, by kind.
"""

from __future__ import annotations

import bisect
import heapq
import json
from collections import Counter, deque
from collections.abc import Mapping
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
    """The newest `capacity` events of one source, numbered from 1.

    `kept_apart` maps a kind to the capacity of a ring of its own (see the module
    docstring); every other kind shares the main ring of `capacity` events.
    """

    def __init__(self, source: str, *, capacity: int = DEFAULT_CAPACITY,
                 kept_apart: Mapping[str, int] | None = None) -> None:
        self.source = source
        self._events: deque[Event] = deque(maxlen=capacity)
        self._apart: dict[str, deque[Event]] = {
            kind: deque(maxlen=int(size)) for kind, size in (kept_apart or {}).items()}
        self.last_seq = 0
        self.dropped: Counter[str] = Counter()

    def add(self, t_us: int, level: str, kind: str, message: str, **fields: Any) -> Event:
        """Append an event at mount time `t_us`; return it (with its `seq`)."""
        level_rank(level)
        self.last_seq += 1
        event = Event(int(t_us), self.source, level, kind, message, fields, self.last_seq)
        ring = self._apart.get(kind, self._events)
        if ring.maxlen is not None and len(ring) == ring.maxlen:
            self.dropped[ring[0].kind] += 1
        ring.append(event)
        return event

    def __len__(self) -> int:
        return len(self._events) + sum(len(ring) for ring in self._apart.values())

    def since(self, seq: int) -> list[Event]:
        """Return the events numbered after `seq`, oldest first."""
        if seq >= self.last_seq:
            return []
        rings = [self._events, *self._apart.values()]
        parts = [_after(ring, seq) for ring in rings if ring]
        if len(parts) == 1:
            return parts[0]
        return list(heapq.merge(*parts, key=lambda e: e.seq))

    def since_json(self, seq: int) -> str:
        """`since` as a JSON list of dicts (the ASTCom function `log.since` returns this)."""
        return json.dumps([e.as_dict() for e in self.since(int(seq))])


def _after(ring: deque[Event], seq: int) -> list[Event]:
    """The events of one ring (in seq order) numbered after `seq`."""
    if not ring or ring[-1].seq <= seq:
        return []
    if ring[0].seq > seq:
        return list(ring)
    events = list(ring)
    return events[bisect.bisect_right(events, seq, key=lambda e: e.seq):]
