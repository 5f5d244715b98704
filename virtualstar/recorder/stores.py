"""Open a store by its specification, and tie several writers together."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from .decimation import Envelope
from .influx_store import InfluxConnection, InfluxStoreReader, InfluxStoreWriter
from .parquet_store import ParquetStoreReader, ParquetStoreWriter
from .samples import Gap, SampleBlock, SignalInfo
from .storespec import StoreSpec, parse_store_spec
from .subscriber import StoreWriter

__all__ = ["StoreReader", "TeeWriter", "open_reader", "open_writer"]


class StoreReader(Protocol):
    """What queries and plots need of a store (ParquetStoreReader, InfluxStoreReader)."""

    def signals(self) -> list[SignalInfo]: ...

    def time_range(self) -> tuple[int, int]: ...

    def count(self) -> int: ...

    def window(self, from_t_us: int, to_t_us: int, names: list[str] | None = None) -> SampleBlock: ...

    def envelope(self, from_t_us: int, to_t_us: int, names: list[str] | None = None,
                 buckets: int = 2000) -> Envelope: ...

    def gaps(self) -> list[Gap]: ...


def _spec(spec: str | StoreSpec) -> StoreSpec:
    return parse_store_spec(spec) if isinstance(spec, str) else spec


def open_reader(spec: str | StoreSpec) -> StoreReader:
    """Return a reader of the store `spec` (``parquet:DIR``, ``DIR``, ``influx:URL/DB``)."""
    s = _spec(spec)
    if s.kind == "influx":
        return InfluxStoreReader(InfluxConnection.from_env(s.url, s.database))
    assert s.path is not None
    return ParquetStoreReader(s.path)


def open_writer(spec: str | StoreSpec, *, spool_dir: str | Path | None = None) -> StoreWriter:
    """Return a writer for the store `spec`; `spool_dir` is where InfluxDB batches wait."""
    s = _spec(spec)
    if s.kind == "influx":
        return InfluxStoreWriter(InfluxConnection.from_env(s.url, s.database), spool_dir=spool_dir)
    assert s.path is not None
    return ParquetStoreWriter(s.path)


class TeeWriter:
    """Write the same session to several stores (e.g. Parquet and InfluxDB at once)."""

    def __init__(self, writers: list[StoreWriter]) -> None:
        self.writers = list(writers)

    def begin(self, signals: list[SignalInfo], *, source: str = "", rate_hz: float = 0.0,
              period_us: float = 0.0) -> str:
        sessions = [w.begin(signals, source=source, rate_hz=rate_hz, period_us=period_us)
                    for w in self.writers]
        return sessions[0]

    def write(self, block: SampleBlock) -> None:
        for w in self.writers:
            w.write(block)

    def write_gap(self, gap: Gap) -> None:
        for w in self.writers:
            w.write_gap(gap)

    def write_events(self, events: list) -> None:
        for w in self.writers:
            write = getattr(w, "write_events", None)
            if write is not None:
                write(events)

    def flush_if_due(self) -> None:
        for w in self.writers:
            flush_if_due = getattr(w, "flush_if_due", None)
            if flush_if_due is not None:
                flush_if_due()

    def close(self) -> None:
        errors = []
        for w in self.writers:
            try:
                w.close()
            except Exception as exc:  # close every store even when one fails
                errors.append(exc)
        if errors:
            raise errors[0]
