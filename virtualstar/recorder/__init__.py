"""The recorder (the paper's Database Relay): stream controller signals over ASTCom into a
store with their exact mount timestamps, query and plot them, and run the whole-night
sine experiment on the emulator.

Stores: hourly Parquet files (`ParquetStoreWriter`/`ParquetStoreReader`, the default)
and InfluxDB 1.x over HTTP (`InfluxStoreWriter`/`InfluxStoreReader`). The experiment
(`virtualstar.recorder.experiment`) and the plots (`virtualstar.recorder.plots`, matplotlib)
are imported on their own.
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
from .export import write_csv, write_mat
from .influx_store import InfluxConnection, InfluxStoreReader, InfluxStoreWriter
from .parquet_store import ParquetStoreReader, ParquetStoreWriter
from .samples import Gap, SampleBlock, SignalInfo
from .stores import TeeWriter, open_reader, open_writer
from .storespec import StoreSpec, parse_store_spec
from .subscriber import Recorder, RecordingSummary, SampleSink, client_connector

__all__ = [
    "EmptyStore",
    "Envelope",
    "ExperimentError",
    "Gap",
    "InfluxConnection",
    "InfluxError",
    "InfluxStoreReader",
    "InfluxStoreWriter",
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
    "TeeWriter",
    "client_connector",
    "envelope",
    "open_reader",
    "open_writer",
    "parse_store_spec",
    "rebucket",
    "write_csv",
    "write_mat",
]
