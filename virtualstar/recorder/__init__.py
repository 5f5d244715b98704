"""The recorder (the paper's Database Relay): stream controller signals over ASTCom into a
store with their exact mount timestamps, query and plot them, and run the whole-night
sine experiment on the emulator.

Stores: hourly Parquet files (`ParquetStoreWriter`/`ParquetStoreReader`, the default)
and InfluxDB 1.x over HTTP (`InfluxStoreWriter`/`InfluxStoreReader`). The experiment
(`virtualstar.recorder.experiment`) and the plots (`virtualstar.recorder.plots`, matplotlib)
are imported on their own.
"""

from importlib import import_module
from typing import TYPE_CHECKING, Any

from .exceptions import (
    EmptyStore,
    ExperimentError,
    InfluxError,
    QueryError,
    RecorderError,
    StoreError,
    StoreSpecError,
)
from .storespec import StoreSpec, parse_store_spec

# The rest (numpy, pyarrow, websockets) is imported on first use, so that a command's
# --help or a caller that needs only the errors stays fast (tests/test_import_rules.py).
_LAZY = {
    "Envelope": "decimation", "envelope": "decimation", "rebucket": "decimation",
    "write_csv": "export", "write_mat": "export",
    "InfluxConnection": "influx_store", "InfluxStoreReader": "influx_store",
    "InfluxStoreWriter": "influx_store",
    "ParquetStoreReader": "parquet_store", "ParquetStoreWriter": "parquet_store",
    "Gap": "samples", "SampleBlock": "samples", "SignalInfo": "samples",
    "TeeWriter": "stores", "open_reader": "stores", "open_writer": "stores",
    "Recorder": "subscriber", "RecordingSummary": "subscriber", "SampleSink": "subscriber",
    "client_connector": "subscriber",
}

if TYPE_CHECKING:
    from .decimation import Envelope, envelope, rebucket
    from .export import write_csv, write_mat
    from .influx_store import InfluxConnection, InfluxStoreReader, InfluxStoreWriter
    from .parquet_store import ParquetStoreReader, ParquetStoreWriter
    from .samples import Gap, SampleBlock, SignalInfo
    from .stores import TeeWriter, open_reader, open_writer
    from .subscriber import Recorder, RecordingSummary, SampleSink, client_connector


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


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
