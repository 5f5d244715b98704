"""Errors of the recorder, one tree; each also inherits the matching built-in.

::

    RecorderError
    ├── StoreSpecError (ValueError)      a --store text that names no known store
    ├── StoreError (OSError)             a store that cannot be opened, read or written
    │   └── EmptyStore (FileNotFoundError)   no samples where a store was expected
    ├── InfluxError (ConnectionError)    InfluxDB refused a request or cannot be reached
    ├── QueryError (ValueError)          a bad time window, signal name or bucket count
    └── ExperimentError (RuntimeError)   the emulated run did not go as planned
"""

from __future__ import annotations

__all__ = [
    "EmptyStore",
    "ExperimentError",
    "InfluxError",
    "QueryError",
    "RecorderError",
    "StoreError",
    "StoreSpecError",
]


class RecorderError(Exception):
    """Base of every recorder error."""


class StoreSpecError(RecorderError, ValueError):
    """A store specification names no store we know."""


class StoreError(RecorderError, OSError):
    """A store cannot be opened, read or written."""


class EmptyStore(StoreError, FileNotFoundError):
    """A store holds no samples."""


class InfluxError(RecorderError, ConnectionError):
    """InfluxDB refused a request or cannot be reached; `.status` is the HTTP status or None."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


class QueryError(RecorderError, ValueError):
    """A query asks for a window, signal or bucket count the store cannot give."""


class ExperimentError(RecorderError, RuntimeError):
    """The emulated experiment failed (a fault, an underrun, a lost sample)."""
