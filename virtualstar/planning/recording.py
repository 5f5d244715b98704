"""Signals recorded beside a program run (`vs run --record NAME ...`).

The recorder subscribes to the mount's ASTCom stream for the whole run, so every block
can be looked at afterwards sample by sample (`vs data`, keyed by the block's mount times
in the run's result). On the embedded emulator it joins in memory and, in lockstep, loses
nothing (mount time waits for the recorder too); against a real server it connects to
the mount's own endpoint (`--mount URL`) from a thread of its own, beside the blocking
API call that follows the run.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import Any, TypeVar

from virtualstar.recorder import RecorderError, parse_store_spec
from virtualstar.recorder.stores import TeeWriter, open_writer
from virtualstar.recorder.subscriber import Connector, Recorder, client_connector

__all__ = ["DEFAULT_RECORD_STORE", "RunRecording", "ThreadedRecording", "record_beside"]

DEFAULT_RECORD_STORE = "parquet:run-recording"
START_TIMEOUT_S = 30.0  # the recorder's first connection and stream request
T = TypeVar("T")


@dataclass(frozen=True)
class RunRecording:
    """Which signals to record during a run, how often, and where."""

    names: tuple[str, ...]
    rate_hz: float = 100.0
    stores: tuple[str, ...] = (DEFAULT_RECORD_STORE,)

    def __post_init__(self) -> None:
        if not self.names:
            raise RecorderError("--record: name at least one signal (see `astcom list URL`)")
        if not self.rate_hz > 0:
            raise RecorderError(f"--record-rate {self.rate_hz}: expected a positive number "
                                "of samples per second")
        for spec in self.stores:
            parse_store_spec(spec)  # a wrong store is refused before the run starts

    def recorder(self, connect: Connector, source: str, *,
                 event_sources: list | None = None) -> Recorder:
        """`event_sources`: other event logs kept in the store (the VSS's: its phases)."""
        return Recorder(connect, list(self.names), self.rate_hz, self.writer(), source=source,
                        event_sources=event_sources)

    def writer(self, stores: tuple[str, ...] | None = None):
        """A writer into `stores` (default: this recording's), all of them at once."""
        writers = [open_writer(parse_store_spec(s))
                   for s in (self.stores if stores is None else stores)]
        return writers[0] if len(writers) == 1 else TeeWriter(writers)

    def summary(self, recorder: Recorder) -> dict[str, Any]:
        doc = recorder.summary.as_dict()
        doc["store"] = ", ".join(self.stores)
        return doc


async def _started(recorder: Recorder, task: asyncio.Task) -> None:
    """Return once `recorder` streams; raise what stopped it from starting."""
    ready = asyncio.ensure_future(recorder.started.wait())
    try:
        done, _ = await asyncio.wait({ready, task}, timeout=START_TIMEOUT_S,
                                     return_when=asyncio.FIRST_COMPLETED)
    finally:
        ready.cancel()
    if task in done:
        task.result()  # raises the recorder's error
        raise RecorderError("the recorder ended before it began")
    if not done:
        task.cancel()
        raise RecorderError(f"the recorder could not start streaming within {START_TIMEOUT_S:.0f} s")


async def record_beside(recording: RunRecording, connect: Connector, source: str,
                        main: Awaitable[T], *,
                        event_sources: list | None = None) -> tuple[T, dict[str, Any]]:
    """Record while `main` runs (it starts once the stream runs); return its result and the
    recording's summary. A recorder that cannot start (unknown signal, store) raises
    before `main` begins. `event_sources` (e.g. the VSS's log) are kept in the store too."""
    recorder = recording.recorder(connect, source, event_sources=event_sources)
    task = asyncio.ensure_future(recorder.run())
    try:
        await _started(recorder, task)
    except BaseException:
        if asyncio.iscoroutine(main):
            main.close()
        raise
    try:
        result = await main
    finally:
        recorder.stop()
        await task
    return result, recording.summary(recorder)


class ThreadedRecording:
    """A recording from a mount's ASTCom URL in a thread of its own (blocking callers)."""

    def __init__(self, recording: RunRecording, url: str, *, password: str | None = None) -> None:
        self.recording = recording
        self.recorder = recording.recorder(client_connector(url, password=password), url)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="vs-run-recorder", daemon=True)

    def start(self) -> None:
        """Start and return once the stream runs; raise what kept it from starting."""
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S + 5.0):
            raise RecorderError("the recorder did not start")
        if self._error is not None:
            raise self._error

    def stop(self) -> dict[str, Any]:
        """Finish the recording (what was streamed is stored); return its summary."""
        if self._loop is not None and self._thread.is_alive():
            # the thread may be closing its loop this moment (a recording that failed to
            # start, or ended early): then it ends without being told
            with contextlib.suppress(RuntimeError):
                self._loop.call_soon_threadsafe(self.recorder.stop)
        self._thread.join()
        doc = self.recording.summary(self.recorder)
        if self._error is not None:
            doc["error"] = f"{type(self._error).__name__}: {self._error}"
        return doc

    def _main(self) -> None:
        async def go() -> None:
            self._loop = asyncio.get_running_loop()
            task = asyncio.ensure_future(self.recorder.run())
            try:
                await _started(self.recorder, task)
            except BaseException as exc:
                self._error = exc  # before _ready: start() raises it in the caller's thread
                raise
            finally:
                self._ready.set()
            await task

        try:
            asyncio.run(go())
        except BaseException as exc:
            if self._error is None:
                self._error = exc  # the recording ended early: stop() says so
            self._ready.set()
