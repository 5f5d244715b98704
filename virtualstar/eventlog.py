"""Read and filter structured event logs (astcom_client.events) from a store or a VSS.

`EventFilter` says which events a user wants (time, level at least, source, kind, text);
`store_events` reads a recorder store's events; `follow_vss` polls a VirtualStar Server's
`log` command and hands on every new event that passes the filter. `vs log` is a thin
face over these.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass

from astcom_client.events import Event, level_rank, utc_text
from virtualstar.display import safe_text

__all__ = ["FOLLOW_POLL_S", "EventFilter", "VssEventSource", "follow_vss", "format_event",
           "store_events"]

FOLLOW_POLL_S = 0.5
#: Events asked of the VSS's `log` at a time (its default; docs/vss-api.md).
LOG_PAGE_EVENTS = 1000


@dataclass(frozen=True)
class EventFilter:
    """Which events to keep; empty tuples keep every source/kind. Times in mount µs."""

    from_t_us: int | None = None
    to_t_us: int | None = None
    min_level: str = "debug"
    sources: tuple[str, ...] = ()
    kinds: tuple[str, ...] = ()
    text: str = ""

    def __post_init__(self) -> None:
        level_rank(self.min_level)  # ValueError names the valid levels

    def matches(self, e: Event) -> bool:
        if self.from_t_us is not None and e.t_us < self.from_t_us:
            return False
        if self.to_t_us is not None and e.t_us >= self.to_t_us:
            return False
        if level_rank(e.level) < level_rank(self.min_level):
            return False
        if self.sources and e.source not in self.sources:
            return False
        if self.kinds and e.kind not in self.kinds:
            return False
        if self.text:
            hay = (e.message + " " + " ".join(f"{k}={v}" for k, v in e.fields.items())).lower()
            return self.text.lower() in hay
        return True


def format_event(e: Event) -> str:
    """Return one table row: UTC, level, source, kind, message."""
    return (f"{utc_text(e.t_us)}  {safe_text(e.level):<7} {safe_text(e.source):<8} "
            f"{safe_text(e.kind):<11} {safe_text(e.message)}")


def store_events(reader) -> list[Event]:
    """Return a store reader's events (a store without events has none)."""
    events = getattr(reader, "events", None)
    return list(events()) if events is not None else []


async def follow_vss(url: str, flt: EventFilter, on_event: Callable[[Event], None], *,
                     password: str | None = None, history: bool = True, follow: bool = True,
                     duration_s: float | None = None,
                     on_dropped: Callable[[dict[str, int]], None] | None = None) -> int:
    """Hand on a VSS's events that pass `flt` (polling `log`); return how many passed.

    `history` also hands on what the log already holds. Without `follow`, reads the log
    once, to its newest event, and returns. With it, keeps polling until `duration_s`
    wall seconds have passed (None: until cancelled). `on_dropped` gets the server's count
    of events its rings dropped, by kind, whenever it changes (a reader must know what it
    cannot see).
    """
    dropped_seen: dict[str, int] = {}
    from virtualstar.vss_client import VssClient

    passed = 0
    deadline = None if duration_s is None else time.monotonic() + duration_s
    async with await VssClient.connect(url, password=password) as client:
        since = 0
        if not history:
            since = int((await client.request("log", {"since": 0, "limit": 1}))["last_seq"])
        while True:
            doc = await client.request("log", {"since": since, "limit": LOG_PAGE_EVENTS})
            dropped = {str(k): int(v) for k, v in dict(doc.get("dropped") or {}).items() if v}
            if on_dropped is not None and dropped != dropped_seen:
                dropped_seen = dropped
                on_dropped(dropped)
            for d in doc["events"]:
                e = Event.from_dict(d)
                since = max(since, e.seq)
                if flt.matches(e):
                    passed += 1
                    on_event(e)
            if doc["events"] and since < int(doc.get("last_seq", since)):
                continue  # more are waiting: read on at once
            if not follow or (deadline is not None and time.monotonic() >= deadline):
                return passed
            await asyncio.sleep(FOLLOW_POLL_S if deadline is None
                                else max(0.0, min(FOLLOW_POLL_S, deadline - time.monotonic())))




class VssEventSource:
    """A VSS's event log as a recorder event source: `await since(seq)` returns the events
    after `seq` through any client with `request(cmd, params)` (`VssClient`, the
    in-process `LocalVssClient`), or through a connection it opens itself to `url`."""

    def __init__(self, client=None, *, url: str = "", password: str | None = None) -> None:
        self.client = client
        self.url = url
        self.password = password
        self._own = False  # the connection is ours to close

    async def close(self) -> None:
        if self._own and self.client is not None:
            await self.client.close()
            self.client = None

    def __repr__(self) -> str:
        return f"the VSS {self.url or '(in-process)'}"

    async def since(self, seq: int) -> list[Event]:
        if self.client is None:
            from virtualstar.vss_client import VssClient

            self.client = await VssClient.connect(self.url, password=self.password,
                                                  reconnect=True)
            self._own = True
        out: list[Event] = []
        while True:
            doc = await self.client.request("log", {"since": seq})
            events = [Event.from_dict(d) for d in doc["events"]]
            out += events
            if len(events) < LOG_PAGE_EVENTS:
                return out
            seq = events[-1].seq
