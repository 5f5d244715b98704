"""Subscribe to an ASTCom stream and hand every sample, and every gap, to a store.

`SampleSink` turns stream packets into sample blocks and finds gaps from the tick
numbers (a packet whose first tick is later than the one expected after the previous
packet means samples were dropped: their number is exact). `Recorder` owns the
connection: it connects, streams, feeds the sink, and when the endpoint goes away it
reconnects with back-off and records the hole as a "reconnect" gap.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from astcom_client import AstcomError, Client, StreamPacket, parse_type
from astcom_client.events import Event, EventLog

from .exceptions import RecorderError
from .samples import UNKNOWN_LOST, Gap, SampleBlock, SignalInfo

__all__ = ["Recorder", "RecordingSummary", "SampleSink", "StoreWriter"]

log = logging.getLogger("virtualstar.recorder")

DEFAULT_RECONNECT_DELAY_S = 0.2
IDLE_FLUSH_S = 0.5  # a quiet stream still lets the store journal what it holds this often
MAX_RECONNECT_DELAY_S = 5.0
CLIENT_QUEUE_PACKETS = 65_536  # client-side packet queue: a burst of several seconds at 10 kHz
EVENT_POLL_S = 1.0  # wall seconds between two reads of the device's event log (log.since)


class StoreWriter(Protocol):
    """What the recorder needs of a store (ParquetStoreWriter, InfluxStoreWriter)."""

    def begin(self, signals: list[SignalInfo], *, source: str = "", rate_hz: float = 0.0,
              period_us: float = 0.0) -> str: ...

    def write(self, block: SampleBlock) -> None: ...

    def write_gap(self, gap: Gap) -> None: ...

    def close(self) -> None: ...


class SampleSink:
    """Turn packets into blocks for `writer`, finding gaps from tick numbers.

    `names` are the recorded columns, in order; `tick_us` the device tick period (µs),
    used to tell a live gap (ticks and times advance together) from an endpoint that
    restarted (ticks begin again).
    """

    def __init__(self, writer: StoreWriter, names: list[str], *, session: str = "",
                 on_gap: Callable[[Gap], None] | None = None) -> None:
        self.writer = writer
        self.names = list(names)
        self.session = session
        self.on_gap = on_gap
        self.samples = 0
        self.packets = 0
        self.lost = 0
        self.unknown_gaps = 0
        self.gaps: list[Gap] = []
        self.first_t_us: int | None = None
        self.last_t_us: int | None = None
        self.last_tick: int | None = None
        self._period_ticks = 1
        self._tick_us = 0.0
        self._reconnected = False

    def reconnected(self) -> None:
        """Say that the next packet comes over a new connection (its gap is a reconnect)."""
        self._reconnected = True

    def accept(self, packet: StreamPacket) -> None:
        """Store the samples of `packet` and any gap before it."""
        n = packet.n
        if n == 0:
            return
        t_us = packet.t_us
        if self.last_tick is not None:
            self._check_gap(packet, int(t_us[0]))
        self._period_ticks = packet.period_ticks
        self._tick_us = packet.period_us / max(1, packet.period_ticks)
        if packet.values.shape[1] == len(self.names) and not packet.where:
            columns = {name: packet.values[:, j] for j, name in enumerate(self.names)}
        else:
            columns = {name: packet.column(name) for name in self.names}
        self.writer.write(SampleBlock(t_us, columns))
        if self.first_t_us is None:
            self.first_t_us = int(t_us[0])
        self.last_t_us = int(t_us[-1])
        self.last_tick = packet.first_tick + (n - 1) * packet.period_ticks
        self.samples += n
        self.packets += 1

    def _check_gap(self, packet: StreamPacket, first_t_us: int) -> None:
        assert self.last_tick is not None and self.last_t_us is not None
        expected = self.last_tick + self._period_ticks
        reconnect, self._reconnected = self._reconnected, False
        if packet.first_tick == expected and first_t_us > self.last_t_us:
            return
        same_clock = packet.first_tick > self.last_tick and first_t_us > self.last_t_us
        if same_clock:
            lost = (packet.first_tick - expected) // self._period_ticks
            reason = "reconnect" if reconnect else "dropped"
        else:  # the endpoint restarted: ticks began again, only the times tell the hole
            dt = first_t_us - self.last_t_us
            lost = max(0, round(dt / packet.period_us) - 1) if dt > 0 else UNKNOWN_LOST
            reason = "restart"
            lost = UNKNOWN_LOST if dt <= 0 else lost
        gap = Gap(self.last_t_us, first_t_us, int(lost), reason, self.session)
        if lost > 0:
            self.lost += lost
        elif lost == UNKNOWN_LOST:
            self.unknown_gaps += 1
        self.gaps.append(gap)
        self.writer.write_gap(gap)
        if self.on_gap is not None:
            self.on_gap(gap)


@dataclass
class RecordingSummary:
    """What a recording did; `lost` counts samples known missing (exact from ticks)."""

    names: list[str]
    rate_hz: float
    samples: int = 0
    lost: int = 0
    gaps: list[Gap] = field(default_factory=list)
    reconnects: int = 0
    packets: int = 0
    first_t_us: int | None = None
    last_t_us: int | None = None
    wall_s: float = 0.0
    session: str = ""
    store: str = ""

    def as_dict(self) -> dict[str, object]:
        return {"names": self.names, "rate_hz": self.rate_hz, "samples": self.samples,
                "samples_per_signal": self.samples, "lost": self.lost,
                "gaps": [g.__dict__ for g in self.gaps], "reconnects": self.reconnects,
                "packets": self.packets, "first_t_us": self.first_t_us,
                "last_t_us": self.last_t_us, "wall_s": round(self.wall_s, 3),
                "session": self.session, "store": self.store}


def dtype_of(type_name: str) -> str:
    """Return the numpy dtype name of an ASTCom scalar type ("f64" → "float64")."""
    spec = parse_type(type_name)
    if not spec.is_numeric_scalar or spec.dtype is None:
        raise RecorderError(f"type {type_name} cannot be recorded: the recorder takes numeric "
                            "scalar signals (bool, i8..u64, f32, f64)")
    return np.dtype(spec.dtype).name


Connector = Callable[[], Awaitable[Client]]


class _Watched:
    """A store writer that also hands every block to `watch`."""

    def __init__(self, writer: StoreWriter, watch: Callable[[SampleBlock], None]) -> None:
        self._writer = writer
        self._watch = watch

    def write(self, block: SampleBlock) -> None:
        self._writer.write(block)
        self._watch(block)

    def __getattr__(self, name: str):
        return getattr(self._writer, name)


class Recorder:
    """Record `names` at `rate_hz` from the endpoint `connect()` reaches, into `writer`.

    `connect` returns a new connected Client each call (e.g. ``lambda:
    Client.connect(url, password=pw)``); it is called again after the connection is lost.
    Raises RecorderError (or the AstcomError of the endpoint) when the first connection or
    the stream request fails: a wrong URL or signal name is a mistake, not an outage.
    """

    def __init__(self, connect: Connector, names: list[str], rate_hz: float, writer: StoreWriter,
                 *, source: str = "", on_gap: Callable[[Gap], None] | None = None,
                 reconnect_delay_s: float = DEFAULT_RECONNECT_DELAY_S,
                 watch: Callable[[SampleBlock], None] | None = None,
                 event_sources: list | None = None,
                 watch_events: Callable[[list[Event]], None] | None = None,
                 watch_end: Callable[[], None] | None = None) -> None:
        if not names:
            raise RecorderError("name at least one signal to record")
        if len(set(names)) != len(names):
            raise RecorderError(f"signal names repeat: {names}")
        self.connect = connect
        self.names = list(names)
        self.rate_hz = float(rate_hz)
        self.writer = writer
        self.source = source
        self.reconnect_delay_s = reconnect_delay_s
        self._on_gap = on_gap
        # `watch` sees every block written (live anomaly detection, virtualstar.anomalies.live)
        sink_writer = writer if watch is None else _Watched(writer, watch)
        # `watch_events` sees the events stored (the live detectors' motion phases), and
        # `watch_end` is called once the last samples are in, before the store closes
        self._watch_events = watch_events
        self._watch_end = watch_end
        self.sink = SampleSink(sink_writer, self.names, on_gap=self._gap)
        self.summary = RecordingSummary(self.names, self.rate_hz)
        self.log = EventLog("recorder")
        self._logged_seq = 0
        self._device_log = False  # the device serves log.since: its events are stored too
        self._device_seq = 0
        self._client: Client | None = None
        self._start_event: tuple[str, dict] | None = None  # logged at the first sample's time
        # other logs to keep beside the samples (a VSS's: virtualstar.eventlog.VssEventSource):
        # objects with `async since(seq) -> list[Event]`
        self.event_sources = list(event_sources or [])
        self._source_seqs = [0] * len(self.event_sources)
        self._progress = asyncio.Event()
        self._stop = asyncio.Event()
        self.started = asyncio.Event()  # set once the stream runs and the store has begun
        self.signals: list[SignalInfo] = []

    def stop(self) -> None:
        """Ask `run` to finish after the packets already received."""
        self._stop.set()

    def watch(self, watch: Callable[[SampleBlock], None],
              watch_events: Callable[[list[Event]], None] | None = None,
              watch_end: Callable[[], None] | None = None) -> None:
        """From now on hand every block written to `watch`, and so on (as the constructor's
        arguments): live detection switched on while recording. What was written before
        is the caller's to hand over (a forked variant's held recording, say)."""
        self.sink.writer = _Watched(self.writer, watch)
        self._watch_events = watch_events
        self._watch_end = watch_end

    # -- events --------------------------------------------------------------------------
    def _now_us(self) -> int:
        """Mount time of the recorder's own events: the newest sample, else the host clock."""
        return self.sink.last_t_us if self.sink.last_t_us is not None else time.time_ns() // 1000

    def _event(self, level: str, kind: str, message: str, **fields: object) -> None:
        self.log.add(self._now_us(), level, kind, message, **fields)
        self._store_events([])

    def _log_start(self) -> None:
        if self._start_event is not None and (self.sink.first_t_us is not None
                                              or self._stop.is_set()):
            message, fields = self._start_event
            self._start_event = None
            t_us = self.sink.first_t_us if self.sink.first_t_us is not None else self._now_us()
            self.log.add(t_us, "info", "session", message, **fields)

    def _store_events(self, device: list[Event]) -> None:
        """Hand the recorder's new events and the device's to the store (if it keeps them)."""
        self._log_start()
        write = getattr(self.writer, "write_events", None)
        own = self.log.since(self._logged_seq)
        if own:
            self._logged_seq = own[-1].seq
        if write is not None and self.sink.session and (own or device):
            write(sorted(own + device, key=lambda e: e.t_us))
        if self._watch_events is not None and device:
            self._watch_events(device)

    def anomaly_found(self, anomaly) -> None:
        """Log an anomaly the live detectors found (virtualstar.anomalies.Anomaly)."""
        d = anomaly.as_dict()
        self._event("warning", "anomaly", f"{d['kind']} {d['axis'] or ''} anomaly from "
                    f"{d['start_utc']}: {d['detail']}".replace("  ", " "),
                    anomaly_kind=d["kind"], axis=d["axis"], score=d["score"],
                    start_utc=d["start_utc"], end_utc=d["end_utc"],
                    signals=",".join(d["signals"]))

    def _gap(self, gap: Gap) -> None:
        self._event("warning", "gap", f"{gap.lost_samples} samples lost ({gap.reason})",
                    after_t_us=gap.after_t_us, before_t_us=gap.before_t_us,
                    lost_samples=gap.lost_samples, reason=gap.reason)
        if self._on_gap is not None:
            self._on_gap(gap)

    async def poll_device_log(self) -> int:
        """Store the device's events logged since the last poll; return how many."""
        client = self._client
        if not self._device_log or client is None:
            return 0
        import json

        try:
            docs = json.loads(await client.invoke("log.since", self._device_seq))
        except (AstcomError, OSError, ConnectionError, ValueError) as exc:
            log.info("reading the device's event log failed: %s", exc)
            return 0
        events = [Event.from_dict(d) for d in docs]
        if events:
            self._device_seq = events[-1].seq
            self._store_events(events)
        return len(events)

    async def poll_event_sources(self) -> int:
        """Store the events of the other sources (e.g. a VSS) since the last poll."""
        found: list[Event] = []
        for k, source in enumerate(self.event_sources):
            try:
                events = await source.since(self._source_seqs[k])
            except Exception as exc:  # a source that is down must not stop the recording
                log.info("reading the event log of %s failed: %s", source, exc)
                continue
            if events:
                self._source_seqs[k] = max(e.seq for e in events)
                found += events
        if found:
            self._store_events(found)
        return len(found)

    async def _pump_device_log(self) -> None:
        while not self._stop.is_set():
            await self._sleep(EVENT_POLL_S, None)
            await self.poll_device_log()
            await self.poll_event_sources()
            self._store_events([])

    async def wait_for_tick(self, tick: int) -> None:
        """Wait until a sample of tick >= `tick` was received (simulated-time pacing)."""
        while self.sink.last_tick is None or self.sink.last_tick < tick:
            self._progress.clear()
            await self._progress.wait()

    async def _open(self, first: bool) -> tuple[Client, object]:
        client = await self.connect()
        try:
            if first:
                infos = {i.name: i for i in await client.list()}
                unknown = [n for n in self.names if n not in infos]
                if unknown:
                    raise RecorderError(f"the endpoint has no signal {', '.join(unknown)}; "
                                        f"`astcom list URL` shows its {len(infos)} names")
                self._device_log = "log.since" in infos
                bad = [n for n in self.names if infos[n].kind == "function"]
                if bad:
                    raise RecorderError(f"{', '.join(bad)} are functions, not signals")
                try:
                    self.signals = [SignalInfo(n, infos[n].unit, dtype_of(infos[n].type))
                                    for n in self.names]
                except RecorderError as exc:
                    raise RecorderError(f"{exc} ({', '.join(self.names)})") from None
            stream = await client.stream(self.names, rate_hz=self.rate_hz)
        except BaseException:
            await client.close()
            raise
        if first:
            self.summary.rate_hz = stream.rate_hz
            session = self.writer.begin(self.signals, source=self.source, rate_hz=stream.rate_hz,
                                        period_us=1e6 / stream.rate_hz)
            self.sink.session = self.summary.session = session
            self._start_event = (f"recording {', '.join(self.names)} at {stream.rate_hz:g} Hz "
                                 f"from {self.source or 'the device'}",
                                 {"session": session, "names": self.names,
                                  "rate_hz": stream.rate_hz})
        self._client = client
        return client, stream

    async def run(self, duration_s: float | None = None) -> RecordingSummary:
        """Record until `duration_s` (wall seconds) elapse or `stop()`; return the summary.

        The store is closed (files finished) before returning, also on error.
        """
        t0 = time.monotonic()
        deadline = None if duration_s is None else t0 + duration_s
        pump: asyncio.Task | None = None
        client = None
        try:
            client, stream = await self._open(first=True)
            self.started.set()
            if self._device_log or self.event_sources:
                pump = asyncio.ensure_future(self._pump_device_log())
            delay = self.reconnect_delay_s
            while True:
                ended = await self._consume(stream, deadline)
                with contextlib.suppress(Exception):  # the device's last events, if it is there
                    async with asyncio.timeout(2.0):
                        await self.poll_device_log()
                with contextlib.suppress(Exception):
                    async with asyncio.timeout(2.0):
                        await self.poll_event_sources()
                with contextlib.suppress(Exception):
                    async with asyncio.timeout(2.0):
                        await client.close()
                if not ended:
                    break  # stopped or out of time
                log.warning("connection lost; reconnecting")
                self._event("warning", "connection", "connection to the device lost; "
                            "reconnecting")
                client = stream = self._client = None
                while client is None:
                    if self._stop.is_set() or (deadline and time.monotonic() >= deadline):
                        break
                    try:
                        client, stream = await self._open(first=False)
                    except (OSError, ConnectionError, AstcomError, TimeoutError) as exc:
                        log.info("reconnect failed (%s); retrying in %.1f s", exc, delay)
                        await self._sleep(delay, deadline)
                        delay = min(delay * 2, MAX_RECONNECT_DELAY_S)
                if client is None:
                    break
                delay = self.reconnect_delay_s
                self.summary.reconnects += 1
                self.sink.reconnected()
                self._event("info", "connection", "reconnected to the device")
        finally:
            if pump is not None:
                pump.cancel()
                await asyncio.gather(pump, return_exceptions=True)
            for source in self.event_sources:
                close = getattr(source, "close", None)
                if close is not None:
                    with contextlib.suppress(Exception):
                        async with asyncio.timeout(2.0):
                            await close()
            try:
                if self._watch_end is not None and self.sink.session:
                    try:
                        self._watch_end()
                    except Exception as exc:  # a watcher must not cost the store its end
                        log.warning("the recording's watcher failed at its end: %s", exc)
                if self.sink.session:
                    self._stop.set()  # the start event is due now, whatever came
                    self._event("info", "session", f"recording ended: {self.sink.samples} "
                                f"samples, {self.sink.lost} lost",
                                samples=self.sink.samples, lost=self.sink.lost)
                self.writer.close()
            finally:
                self._finish_summary(time.monotonic() - t0)
        return self.summary

    async def _sleep(self, seconds: float, deadline: float | None) -> None:
        if deadline is not None:
            seconds = max(0.0, min(seconds, deadline - time.monotonic()))
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(seconds):
                await self._stop.wait()

    async def _consume(self, stream, deadline: float | None) -> bool:
        """Feed packets to the sink; return True when the connection ended under us.

        Packets are taken in order from the stream's queue (the client fills it from the
        moment the stream starts, so none slips past). On stop or deadline the stream is
        stopped and what it already queued is still stored.
        """
        stopper = asyncio.ensure_future(self._stop.wait())
        getter: asyncio.Future | None = None
        try:
            while True:
                timeout = None if deadline is None else deadline - time.monotonic()
                if timeout is not None and timeout <= 0:
                    break
                if getter is None:
                    getter = asyncio.ensure_future(stream.__anext__())
                wait_s = IDLE_FLUSH_S if timeout is None else min(timeout, IDLE_FLUSH_S)
                done, _ = await asyncio.wait({getter, stopper}, timeout=wait_s,
                                             return_when=asyncio.FIRST_COMPLETED)
                if getter not in done:
                    if stopper in done or (deadline is not None and time.monotonic() >= deadline):
                        break
                    # a quiet stream: what was received must still reach the disk in time
                    flush_if_due = getattr(self.writer, "flush_if_due", None)
                    if flush_if_due is not None:
                        flush_if_due()
                    continue
                try:
                    packet = getter.result()
                except StopAsyncIteration:
                    getter = None
                    return not self._stop.is_set()
                getter = None
                self.sink.accept(packet)
                self._progress.set()
            if getter is not None:
                getter.cancel()
                await asyncio.gather(getter, return_exceptions=True)
                getter = None
            with contextlib.suppress(Exception):
                async with asyncio.timeout(2.0):
                    await stream.stop()
            async for packet in stream:  # what was queued before the stop
                self.sink.accept(packet)
            self._progress.set()
            return False
        finally:
            stopper.cancel()
            await asyncio.gather(stopper, return_exceptions=True)

    def _finish_summary(self, wall_s: float) -> None:
        s = self.summary
        s.samples, s.lost, s.gaps = self.sink.samples, self.sink.lost, list(self.sink.gaps)
        s.packets, s.first_t_us, s.last_t_us = self.sink.packets, self.sink.first_t_us, self.sink.last_t_us
        s.wall_s = wall_s


def client_connector(url: str, *, password: str | None = None) -> Connector:
    """Return a connector for `url` with a client queue deep enough for bursts."""
    async def connect() -> Client:
        return await Client.connect(url, password=password, name="vs-record",
                                    queue_packets=CLIENT_QUEUE_PACKETS)
    return connect
