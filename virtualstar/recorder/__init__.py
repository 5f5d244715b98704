"""The recorder (the paper's Database Relay): stream controller signals over ASTCom into a
store with their exact mount timestamps, query and plot them, and run the whole-night
sine experiment on the emulator.

Stores: hourly Parquet files (`ParquetStoreWriter`/`ParquetStoreReader`, the default)
and InfluxDB 1.x over HTTP (`InfluxStoreWriter`/`InfluxStoreReader`).
"""

from .decimation import Envelope, envelope, rebucket
from .exceptions import (
    EmptyStore,
    ExperimentError,
    InfluxError,
    QueryError,
    RecorderError,
    StoreError,
    StoreSpecError,
)
from .parquet_store import ParquetStoreReader, ParquetStoreWriter
from .samples import Gap, SampleBlock, SignalInfo
from .storespec import StoreSpec, parse_store_spec
from .subscriber import Recorder, RecordingSummary, SampleSink, client_connector

__all__ = [
    "EmptyStore",
    "Envelope",
    "ExperimentError",
    "Gap",
    "InfluxError",
    "ParquetStoreReader",
    "ParquetStoreWriter",
    "QueryError",
    "Recorder",
    "RecorderError",
    "RecordingSummary",
    "SampleBlock",
    "SampleSink",
    "SignalInfo",
    "StoreError",
    "StoreSpec",
    "StoreSpecError",
    "client_connector",
    "envelope",
    "parse_store_spec",
    "rebucket",
]
