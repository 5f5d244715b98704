"""Fork a lockstep run at a mount time: the pieces `run_plan_on_emulator(branches=)` needs.

A lockstep run is deterministic: a variant that differs from it only from mount time T on
(a fault injected at T) moves exactly as the run until T. Instead of simulating that
prefix again, the run's process forks at T (`os.fork`): the child is the whole world
(emulator, VSS, recorder, their tasks) as it stands at T, and goes on as the variant.

Two things of a running process do not survive a fork as they are:

* the event loop's epoll instance and wake-up socket pair are shared with the parent
  (the kernel's objects, not copies), so either process could consume the other's
  wake-ups; and asyncio ties "the running loop" to the PID. `own_loop_after_fork` gives
  the child a selector and a wake-up pipe of its own and makes the loop its running loop.
* a store writer's open files and writer thread (ParquetStoreWriter journals from a
  thread into files whose offsets parent and child would share). `HeldWriter` therefore
  holds the recording in memory, opens nothing and starts no thread, and writes the whole
  store only when it is closed, into the store the process (parent or child) names then.
"""

from __future__ import annotations

import asyncio
import os
import select
import selectors
import signal
from collections.abc import Callable
from typing import Any

from virtualstar.recorder.background import new_session_id
from virtualstar.recorder.subscriber import Connector, Recorder, StoreWriter

from .exceptions import PlanningError
from .recording import RunRecording

__all__ = ["HeldRecording", "HeldWriter", "own_loop_after_fork"]


class HeldWriter:
    """A store writer that keeps the session in memory and writes it at `close`.

    `open_target()` makes the real writer (any StoreWriter) at close; change it before
    then to send the recording elsewhere (a forked variant's own store). The store it
    writes holds the same samples, gaps and events, in the same order, as one written live.
    Memory: the samples themselves (a 30-minute night of 8 signals at 1 kHz: ~130 MB).
    """

    def __init__(self, open_target: Callable[[], StoreWriter]) -> None:
        self.open_target = open_target
        self.session = ""
        self._ops: list[tuple[str, Any]] = []
        self._begin: tuple[list, dict[str, Any]] | None = None

    def begin(self, signals, *, source: str = "", rate_hz: float = 0.0,
              period_us: float = 0.0) -> str:
        if self._begin is None:
            self._begin = (list(signals), {"source": source, "rate_hz": rate_hz,
                                           "period_us": period_us})
            self.session = new_session_id()
        return self.session

    def write(self, block) -> None:
        if len(block):
            self._ops.append(("write", block))

    def write_gap(self, gap) -> None:
        self._ops.append(("gap", gap))

    def write_events(self, events: list) -> None:
        if events:
            self._ops.append(("events", list(events)))

    def close(self) -> None:
        """Write the held session into `open_target()`'s store; raise what it raises."""
        if self._begin is None:
            return
        ops, self._ops = self._ops, []
        target = self.open_target()
        signals, options = self._begin
        session = target.begin(signals, **options)
        try:
            write_events = getattr(target, "write_events", None)
            for op, arg in ops:
                if op == "write":
                    target.write(arg)
                elif op == "gap":
                    if arg.session == self.session:
                        arg = type(arg)(arg.after_t_us, arg.before_t_us, arg.lost_samples,
                                        arg.reason, session)
                    target.write_gap(arg)
                elif write_events is not None:
                    write_events(arg)
        finally:
            target.close()


class HeldRecording:
    """A RunRecording whose recorder writes through a HeldWriter (`held`, once made):
    the process may fork while it records. `stores` may be changed before the end."""

    def __init__(self, recording: RunRecording) -> None:
        self.recording = recording
        self.stores = recording.stores
        self.held: HeldWriter | None = None

    def recorder(self, connect: Connector, source: str, *,
                 event_sources: list | None = None) -> Recorder:
        self.held = HeldWriter(lambda: self.recording.writer(self.stores))
        r = self.recording
        return Recorder(connect, list(r.names), r.rate_hz, self.held, source=source,
                        event_sources=event_sources)

    def summary(self, recorder: Recorder) -> dict[str, Any]:
        doc = recorder.summary.as_dict()
        doc["store"] = ", ".join(self.stores)
        return doc


def own_loop_after_fork(loop: asyncio.AbstractEventLoop) -> None:
    """In the child of an `os.fork()` made while `loop` runs: give `loop` an epoll
    instance and a wake-up socket pair of the child's own, and make it the running loop
    again (asyncio ties the running loop to the PID). Raises PlanningError on a loop
    that is not a selector loop on epoll (Linux)."""
    sel = getattr(loop, "_selector", None)
    if not isinstance(sel, selectors.EpollSelector):
        raise PlanningError("forking a run needs asyncio's selector loop on epoll (Linux)")
    fresh = select.epoll()
    for key in sel.get_map().values():
        fresh.register(key.fd, (select.EPOLLIN if key.events & selectors.EVENT_READ else 0)
                       | (select.EPOLLOUT if key.events & selectors.EVENT_WRITE else 0))
    sel._selector.close()  # the child's descriptor only: the parent's instance stays
    sel._selector = fresh
    loop._close_self_pipe()  # closes the child's copies; the parent keeps its pair
    loop._make_self_pipe()
    if getattr(loop, "_signal_handlers", None):
        signal.set_wakeup_fd(loop._csock.fileno())
    asyncio.events._set_running_loop(loop)


def write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def read_all(fd: int) -> bytes:
    """Read `fd` to its end (blocking)."""
    chunks = []
    while chunk := os.read(fd, 1 << 16):
        chunks.append(chunk)
    return b"".join(chunks)
