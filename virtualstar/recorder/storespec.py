"""Parse a store specification: ``parquet:DIR`` (or a bare directory) and ``influx:URL/DB``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from .exceptions import StoreSpecError

__all__ = ["DEFAULT_INFLUX_URL", "StoreSpec", "parse_store_spec"]

DEFAULT_INFLUX_URL = "http://127.0.0.1:8086"
_FORMS = "expected parquet:DIR, a directory, or influx:http://HOST:PORT/DATABASE"


@dataclass(frozen=True)
class StoreSpec:
    """A parsed store: kind "parquet" with `path`, or kind "influx" with `url` and `database`."""

    kind: str
    path: Path | None = None
    url: str = ""
    database: str = ""

    def __str__(self) -> str:
        if self.kind == "parquet":
            return f"parquet:{self.path}"
        return f"influx:{self.url}/{self.database}"


def parse_store_spec(text: str) -> StoreSpec:
    """Return the StoreSpec of `text`; raise StoreSpecError naming the accepted forms."""
    text = text.strip()
    if not text:
        raise StoreSpecError(f"empty store specification; {_FORMS}")
    kind, sep, rest = text.partition(":")
    if sep and kind == "parquet":
        if not rest:
            raise StoreSpecError(f"store {text!r} names no directory; {_FORMS}")
        return StoreSpec("parquet", path=Path(rest))
    if sep and kind == "influx":
        parts = urlsplit(rest)
        if parts.scheme not in ("http", "https") or not parts.netloc:
            raise StoreSpecError(f"store {text!r}: the InfluxDB address must be http(s)://HOST:PORT/"
                                 f"DATABASE, e.g. influx:{DEFAULT_INFLUX_URL}/telescope")
        database = parts.path.strip("/")
        if not database or "/" in database:
            raise StoreSpecError(f"store {text!r} names no database after the address; "
                                 f"e.g. influx:{DEFAULT_INFLUX_URL}/telescope")
        return StoreSpec("influx", url=f"{parts.scheme}://{parts.netloc}", database=database)
    if sep and len(kind) > 1 and kind.isalpha():
        raise StoreSpecError(f"unknown store kind {kind!r} in {text!r}; {_FORMS}")
    return StoreSpec("parquet", path=Path(text))
