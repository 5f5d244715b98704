"""The server store: InfluxDB 1.x over HTTP, the database of the paper.

Writes are batched line protocol (``POST /write?db=DB&precision=u``), one point per
sample time in measurement ``signals`` with one field per signal (floats written with
Python's shortest round-trip repr, so InfluxDB keeps them bit-exact; integers with the
``i`` suffix), tagged with the session. Gaps go to ``recorder_gaps`` and the signal
units to ``recorder_signals``. Queries are InfluxQL (``GET /query?epoch=u``).

Every batch goes to a spool directory on disk first (fsynced), at least once per flush
interval, and is then sent, oldest first; a batch leaves the spool only once InfluxDB has
taken it. So a recorder killed at any moment loses at most its last flush interval; what
it spooled is sent by the next recording that uses the same spool — which is keyed by
server *and* database (``<spool>/<host>_<port>__<db>/``), so it can only go where it was
meant to. A ``session-*.json`` marker names each live session and its last spooled sample;
a marker left by a dead process becomes a "recorder died" gap. Nothing is dropped: a batch
that InfluxDB rejects as malformed (4xx) is kept in ``rejected-*.lp`` and reported. HTTP
runs on a writer thread so the event loop keeps receiving samples meanwhile.
"""

from __future__ import annotations

import base64
import json
import logging
import os
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .background import BackgroundWriter, new_session_id
from .decimation import Envelope
from .exceptions import EmptyStore, InfluxError, QueryError, StoreError
from .samples import Gap, SampleBlock, SignalInfo

__all__ = [
    "DEFAULT_BATCH_LINES",
    "MEASUREMENT",
    "InfluxConnection",
    "InfluxStoreReader",
    "InfluxStoreWriter",
    "line_protocol",
]

log = logging.getLogger("virtualstar.recorder.influx")

MEASUREMENT = "signals"
GAPS_MEASUREMENT = "recorder_gaps"
EVENTS_MEASUREMENT = "events"  # the event log (docs/events.md); tags source, level, kind, seq
SIGNALS_MEASUREMENT = "recorder_signals"
DEFAULT_BATCH_LINES = 5000  # InfluxDB 1.x documents 5 000–10 000 points per write as optimal
DEFAULT_TIMEOUT_S = 5.0
RETRY_INTERVAL_S = 0.5  # while spooling, try the database again at most this often
MAX_PENDING_BATCHES = 4
CLOSE_DRAIN_S = 10.0
QUERY_CHUNK_ROWS = 50_000
MAX_TIME_US = (2**63 - 2) // 1000  # InfluxDB keeps nanoseconds in an int64
DEFAULT_FLUSH_INTERVAL_S = 1.0  # wall seconds: at most this much is lost to a crash
CRASH_REASON = "recorder died"


def _process_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _clamp(t_us: int) -> int:
    return max(-MAX_TIME_US, min(MAX_TIME_US, int(t_us)))


def _escape_key(text: str) -> str:
    return text.replace("\\", "\\\\").replace(",", r"\,").replace("=", r"\=").replace(" ", r"\ ")


def _quote(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _ident(name: str) -> str:
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _field_texts(values: np.ndarray) -> list[str]:
    kind = values.dtype.kind
    if kind == "f":
        # repr is the shortest text that parses back to the same float64 (exact round trip)
        return [repr(v) for v in values.astype(np.float64).tolist()]
    if kind in "iu":
        return [f"{v}i" for v in values.tolist()]
    if kind == "b":
        return ["true" if v else "false" for v in values.tolist()]
    raise StoreError(f"cannot write dtype {values.dtype} to InfluxDB")


def line_protocol(measurement: str, tags: dict[str, str], block: SampleBlock) -> list[str]:
    """Return one line-protocol line per sample of `block` (time in µs).

    NaN and infinite floats, which InfluxDB cannot store, are left out of their line; a
    line with no field left is dropped.
    """
    head = _escape_key(measurement) + "".join(
        f",{_escape_key(k)}={_escape_key(v)}" for k, v in sorted(tags.items()))
    keys = [_escape_key(n) + "=" for n in block.columns]
    texts = [_field_texts(v) for v in block.columns.values()]
    times = block.t_us.tolist()
    lines = []
    finite = [np.isfinite(v) if v.dtype.kind == "f" else None for v in block.columns.values()]
    if all(f is None or bool(f.all()) for f in finite):
        for i, t in enumerate(times):
            lines.append(f"{head} {','.join(k + c[i] for k, c in zip(keys, texts, strict=True))} {t}")
        return lines
    for i, t in enumerate(times):
        fields = [k + c[i] for k, c, f in zip(keys, texts, finite, strict=True) if f is None or f[i]]
        if fields:
            lines.append(f"{head} {','.join(fields)} {t}")
    return lines


@dataclass(frozen=True)
class InfluxConnection:
    """Where the database is: base URL (http://host:8086), database name, credentials.

    Credentials default to the environment variables INFLUX_USERNAME / INFLUX_PASSWORD.
    """

    url: str
    database: str
    username: str | None = None
    password: str | None = None
    timeout_s: float = DEFAULT_TIMEOUT_S

    @classmethod
    def from_env(cls, url: str, database: str, **kw: Any) -> InfluxConnection:
        return cls(url.rstrip("/"), database, os.environ.get("INFLUX_USERNAME"),
                   os.environ.get("INFLUX_PASSWORD"), **kw)

    def _request(self, path: str, params: dict[str, str], body: bytes | None = None) -> bytes:
        query = urllib.parse.urlencode(params)
        req = urllib.request.Request(f"{self.url}{path}?{query}", data=body,
                                     method="POST" if body is not None else "GET")
        if self.username:
            token = base64.b64encode(f"{self.username}:{self.password or ''}".encode()).decode()
            req.add_header("Authorization", f"Basic {token}")
        if body is not None:
            req.add_header("Content-Type", "text/plain; charset=utf-8")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout_s) as resp:
                return resp.read()
        except urllib.error.HTTPError as exc:
            detail = exc.read().decode(errors="replace").strip()
            raise InfluxError(f"InfluxDB at {self.url} answered {exc.code} to {path}: {detail}",
                              exc.code) from None
        except (urllib.error.URLError, OSError, TimeoutError) as exc:
            reason = getattr(exc, "reason", exc)
            raise InfluxError(f"cannot reach InfluxDB at {self.url}: {reason}") from None

    def write_lines(self, payload: bytes) -> None:
        """POST line protocol (precision µs); raise InfluxError."""
        self._request("/write", {"db": self.database, "precision": "u"}, payload)

    def query(self, q: str, *, write: bool = False) -> list[dict[str, Any]]:
        """Run InfluxQL `q`; return the list of series of every statement (chunks joined)."""
        params = {"db": self.database, "q": q, "epoch": "u", "chunked": "true",
                  "chunk_size": str(QUERY_CHUNK_ROWS)}
        raw = self._request("/query", {"q": q}, b"") if write else self._request("/query", params)
        series: dict[tuple[int, str, str], dict[str, Any]] = {}
        for line in raw.splitlines():
            if not line.strip():
                continue
            doc = json.loads(line)
            if "error" in doc:
                raise InfluxError(f"InfluxDB: {doc['error']}")
            for result in doc.get("results", []):
                if "error" in result:
                    raise QueryError(f"InfluxQL {q!r}: {result['error']}")
                for s in result.get("series", []):
                    key = (result.get("statement_id", 0), s.get("name", ""),
                           json.dumps(s.get("tags", {}), sort_keys=True))
                    if key in series:
                        series[key]["values"].extend(s.get("values", []))
                    else:
                        series[key] = {**s, "values": list(s.get("values", []))}
        return list(series.values())

    def ping(self) -> bool:
        """Return True when the database answers /ping."""
        try:
            self._request("/ping", {})
        except InfluxError:
            return False
        return True


def _write_error(exc: BaseException) -> BaseException:
    if isinstance(exc, StoreError | InfluxError):
        return exc
    return StoreError(f"writing to InfluxDB failed: {exc}")


def spool_key(url: str, database: str) -> str:
    """Return the spool subdirectory of one server and database: ``<host>_<port>__<db>``."""
    where = urllib.parse.urlsplit(url)
    port = where.port or (443 if where.scheme == "https" else 8086)
    text = f"{where.hostname or 'localhost'}_{port}__{database}"
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in text)


class InfluxStoreWriter:
    """Write a recording session to InfluxDB in batches through a durable spool.

    `spool_dir` (default ``<tmp>/vs-record-spool``) holds one subdirectory per server and
    database; batches left there (the database stayed down past `close`, or the recorder
    died) are written by the next writer of the same server and database.
    """

    def __init__(self, conn: InfluxConnection, *, spool_dir: str | Path | None = None,
                 batch_lines: int = DEFAULT_BATCH_LINES, close_drain_s: float = CLOSE_DRAIN_S,
                 flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S) -> None:
        self.conn = conn
        root = Path(spool_dir) if spool_dir else Path(tempfile.gettempdir()) / "vs-record-spool"
        self.spool_dir = root / spool_key(conn.url, conn.database)
        self.batch_lines = int(batch_lines)
        self.close_drain_s = close_drain_s
        self.flush_interval_s = float(flush_interval_s)
        self._last_submit = time.monotonic()
        self._last_t_us: int | None = None
        self.crashed_sessions: list[Gap] = []
        self.session = ""
        self.signals: list[SignalInfo] = []
        self.lines_written = 0
        self.lines_spooled = 0
        self.spooled_batches = 0
        self.rejected: list[Path] = []
        self._lines: list[str] = []
        self._thread = BackgroundWriter("influx-writer", MAX_PENDING_BATCHES, _write_error)
        self._next_retry = 0.0
        self._database_ready = False
        self._closed = False
        try:
            self.spool_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"cannot create the spool directory {self.spool_dir}: {exc.strerror}") from None

    def begin(self, signals: list[SignalInfo], *, source: str = "", rate_hz: float = 0.0,
              period_us: float = 0.0) -> str:
        """Start a session; describe the signals in recorder_signals. Never raises when down."""
        self.signals = list(signals)
        self.session = new_session_id()
        if not self.conn.ping():
            log.warning("InfluxDB at %s does not answer: recording into the spool %s; the "
                        "batches are written when it answers (this or a later recording)",
                        self.conn.url, self.spool_dir)
        for gap in self._dead_sessions():
            self.crashed_sessions.append(gap)
            self.write_gap(gap)
        self._write_marker()
        now_us = time.time_ns() // 1000
        for s in self.signals:
            self._lines.append(
                f"{SIGNALS_MEASUREMENT},name={_escape_key(s.name)} unit={_quote(s.unit)},"
                f"dtype={_quote(s.dtype)},rate_hz={float(rate_hz)!r},session={_quote(self.session)},"
                f"source={_quote(source)} {now_us}")
        self._submit()
        return self.session

    def write(self, block: SampleBlock) -> None:
        """Queue the samples of `block`; spool a batch when full or every flush interval."""
        if len(block):
            self._lines.extend(line_protocol(MEASUREMENT, {"session": self.session}, block))
            self._last_t_us = int(block.t_us[-1])
        if len(self._lines) >= self.batch_lines:
            self._submit()
        else:
            self.flush_if_due()

    def flush_if_due(self) -> None:
        """Spool what is queued if the flush interval has passed (call it when idle too)."""
        if self._lines and time.monotonic() - self._last_submit >= self.flush_interval_s:
            self._submit()

    def write_gap(self, gap: Gap) -> None:
        """Queue a recorder_gaps point at the gap's end time (its start when the end is unknown)."""
        at = gap.before_t_us if gap.before_t_us >= 0 else gap.after_t_us
        self._lines.append(
            f"{GAPS_MEASUREMENT},session={_escape_key(gap.session or self.session)} "
            f"after_t_us={gap.after_t_us}i,before_t_us={gap.before_t_us}i,"
            f"lost_samples={gap.lost_samples}i,reason={_quote(gap.reason)} {at}")

    def write_events(self, events: list) -> None:
        """Queue structured events (astcom_client.events.Event) as points of `events`; the
        source's seq is a tag, so two events at one microsecond both stay."""
        for e in events:
            self._lines.append(
                f"{EVENTS_MEASUREMENT},source={_escape_key(e.source)},level={_escape_key(e.level)},"
                f"kind={_escape_key(e.kind)},seq={e.seq},session={_escape_key(self.session)} "
                f"message={_quote(e.message)},fields={_quote(json.dumps(e.fields))} "
                f"{_clamp(e.t_us)}")

    def flush(self) -> None:
        """Hand over what is queued and wait until it is written or spooled."""
        self._submit()
        self._thread.wait(0)

    def close(self) -> None:
        """Write the rest; try the spool for `close_drain_s`; what stays is reported, not lost."""
        if self._closed:
            return
        self._closed = True
        try:
            self._submit()
            self._thread.submit(self._final_drain)
            self._thread.wait(0)
        finally:
            self._thread.shutdown()
        self._marker().unlink(missing_ok=True)
        left = self.spooled_files()
        if left:
            log.warning("InfluxDB at %s unreachable: %d batch file(s) stay in %s and will be "
                        "written by the next recording that uses this spool", self.conn.url,
                        len(left), self.spool_dir)

    def spooled_files(self) -> list[Path]:
        return sorted(self.spool_dir.glob("batch-*.lp"))

    def _submit(self) -> None:
        self._last_submit = time.monotonic()
        if not self._lines:
            return
        payload = ("\n".join(self._lines) + "\n").encode()
        n = len(self._lines)
        self._lines = []
        self._thread.submit(self._deliver, payload, n, self._last_t_us)

    # -- sessions that died --------------------------------------------------------------
    def _marker(self) -> Path:
        return self.spool_dir / f"session-{self.session}.json"

    def _write_marker(self, last_t_us: int | None = None) -> None:
        """Say (durably) that this session is alive and what it spooled last."""
        doc = {"session": self.session, "pid": os.getpid(), "last_t_us": last_t_us}
        tmp = self._marker().with_suffix(".tmp")
        tmp.write_text(json.dumps(doc))
        os.replace(tmp, self._marker())

    def _dead_sessions(self) -> list[Gap]:
        """Return a "recorder died" gap per marker whose process is gone; remove the marker."""
        gaps = []
        for marker in sorted(self.spool_dir.glob("session-*.json")):
            try:
                doc = json.loads(marker.read_text())
            except (OSError, ValueError):
                continue
            if _process_alive(int(doc.get("pid", 0))):
                continue
            last = doc.get("last_t_us")
            if last is not None:
                gaps.append(Gap(int(last), -1, -1, CRASH_REASON, str(doc.get("session", ""))))
            marker.unlink(missing_ok=True)
        return gaps

    # -- the writer thread ---------------------------------------------------------------
    def _try(self, payload: bytes) -> bool:
        """Write `payload`; return False when the database is unreachable (so spool it)."""
        try:
            if not self._database_ready:
                self.conn.query(f"CREATE DATABASE {_ident(self.conn.database)}", write=True)
                self._database_ready = True
            self.conn.write_lines(payload)
            return True
        except InfluxError as exc:
            if exc.status is not None and 400 <= exc.status < 500:
                path = self.spool_dir / f"rejected-{time.time_ns()}.lp"
                path.write_bytes(payload)
                self.rejected.append(path)
                raise InfluxError(f"{exc} (the batch is kept in {path})", exc.status) from None
            self._next_retry = time.monotonic() + RETRY_INTERVAL_S
            log.info("InfluxDB unreachable, spooling: %s", exc)
            return False

    def _drain_spool(self) -> bool:
        """Write spooled batches oldest first; return True when the spool is empty."""
        for path in self.spooled_files():
            if not self._try(path.read_bytes()):
                return False
            self.lines_written += int(path.stem.rsplit("-", 1)[-1])
            path.unlink()
        return True

    def _deliver(self, payload: bytes, n: int, last_t_us: int | None) -> None:
        path = self._spool(payload, n)  # on disk before anything is sent: a kill keeps it
        if last_t_us is not None:
            self._write_marker(last_t_us)
        if time.monotonic() >= self._next_retry:
            self._drain_spool()
        if path.exists():  # the database did not take it now
            self.lines_spooled += n
            self.spooled_batches += 1

    def _spool(self, payload: bytes, n: int) -> Path:
        name = f"batch-{time.time_ns():020d}-{n}.lp"
        tmp = self.spool_dir / (name + ".tmp")
        with open(tmp, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.spool_dir / name)  # a batch file is either whole or absent
        return self.spool_dir / name

    def _final_drain(self) -> None:
        deadline = time.monotonic() + self.close_drain_s
        while self.spooled_files() and time.monotonic() < deadline:
            self._next_retry = 0.0
            if self._drain_spool():
                return
            time.sleep(RETRY_INTERVAL_S)


class InfluxStoreReader:
    """Query a recording in InfluxDB: signals, time range, windows, envelopes, gaps."""

    def __init__(self, conn: InfluxConnection) -> None:
        self.conn = conn
        self._fields: dict[str, str] | None = None
        self._float_dtypes: dict[str, str] | None = None

    def _field_types(self) -> dict[str, str]:
        if self._fields is None:
            series = self.conn.query(f"SHOW FIELD KEYS FROM {_ident(MEASUREMENT)}")
            self._fields = {row[0]: row[1] for s in series for row in s["values"]}
            if not self._fields:
                raise EmptyStore(f"database {self.conn.database} at {self.conn.url} holds no "
                                 f"{MEASUREMENT} measurement")
        return self._fields

    def signals(self) -> list[SignalInfo]:
        """Return the recorded signals (units from recorder_signals where known)."""
        units: dict[str, tuple[str, str]] = {}
        for s in self.conn.query(f"SELECT last(unit) AS unit, last(dtype) AS dtype FROM "
                                 f"{_ident(SIGNALS_MEASUREMENT)} GROUP BY \"name\""):
            name = s.get("tags", {}).get("name", "")
            if s["values"]:
                units[name] = (s["values"][0][1] or "", s["values"][0][2] or "")
        out = []
        for name, ftype in self._field_types().items():
            unit, dtype = units.get(name, ("", ""))
            out.append(SignalInfo(name, unit, dtype or ("int64" if ftype == "integer" else "float64")))
        return out

    def _float_dtype(self, name: str) -> str:
        """Return the recorded float dtype of `name` (float32 signals come back as float32)."""
        if self._float_dtypes is None:
            self._float_dtypes = {s.name: s.dtype for s in self.signals()
                                  if s.dtype in ("float32", "float64")}
        return self._float_dtypes.get(name, "float64")

    def _names(self, names: list[str] | None) -> list[str]:
        have = list(self._field_types())
        if not names:
            return have
        unknown = [n for n in names if n not in have]
        if unknown:
            raise QueryError(f"unknown signal(s) {', '.join(unknown)}; the database holds "
                             f"{', '.join(have)}")
        return list(names)

    def time_range(self) -> tuple[int, int]:
        """Return (first, last) sample time, µs."""
        name = _ident(next(iter(self._field_types())))
        first = self.conn.query(f"SELECT {name} FROM {_ident(MEASUREMENT)} ORDER BY time ASC LIMIT 1")
        last = self.conn.query(f"SELECT {name} FROM {_ident(MEASUREMENT)} ORDER BY time DESC LIMIT 1")
        if not first or not last:
            raise EmptyStore(f"database {self.conn.database} holds no samples")
        return int(first[0]["values"][0][0]), int(last[0]["values"][0][0])

    def count(self) -> int:
        """Return the number of sample times stored."""
        name = _ident(next(iter(self._field_types())))
        s = self.conn.query(f"SELECT count({name}) FROM {_ident(MEASUREMENT)}")
        return int(s[0]["values"][0][1]) if s else 0

    def window(self, from_t_us: int, to_t_us: int, names: list[str] | None = None) -> SampleBlock:
        """Return every sample with from_t_us <= t_us < to_t_us, sorted by time."""
        names = self._names(names)
        types = self._field_types()
        q = (f"SELECT {', '.join(_ident(n) for n in names)} FROM {_ident(MEASUREMENT)} "
             f"WHERE time >= {_clamp(from_t_us)}u AND time < {_clamp(to_t_us)}u")
        rows = [r for s in self.conn.query(q) for r in s["values"]]
        rows.sort(key=lambda r: r[0])
        t = np.array([r[0] for r in rows], dtype=np.int64)
        cols = {}
        for j, n in enumerate(names, start=1):
            if types.get(n) == "integer":
                cols[n] = np.array([r[j] for r in rows], dtype=np.int64)
            else:
                # InfluxDB holds float64; a float32 signal's values are exact float32 values
                cols[n] = np.array([np.nan if r[j] is None else r[j] for r in rows],
                                   dtype=np.float64).astype(self._float_dtype(n))
        return SampleBlock(t, cols)

    def envelope(self, from_t_us: int, to_t_us: int, names: list[str] | None = None,
                 buckets: int = 2000) -> Envelope:
        """Return the min/max envelope in about `buckets` buckets (InfluxQL GROUP BY time)."""
        names = self._names(names)
        if buckets < 1:
            raise QueryError(f"buckets must be >= 1, got {buckets}")
        if to_t_us <= from_t_us:
            raise QueryError(f"empty window: --to ({to_t_us}) must be after --from ({from_t_us})")
        bucket_us = max(1, -(-(to_t_us - from_t_us) // buckets))
        sel = [f"count({_ident(names[0])})"] + [f"{f}({_ident(n)})" for n in names
                                                for f in ("min", "max")]
        q = (f"SELECT {', '.join(sel)} FROM {_ident(MEASUREMENT)} WHERE time >= {_clamp(from_t_us)}u "
             f"AND time < {_clamp(to_t_us)}u GROUP BY time({bucket_us}u, {int(from_t_us) % bucket_us}u) "
             "fill(none)")
        rows = sorted((r for s in self.conn.query(q) for r in s["values"]), key=lambda r: r[0])
        t = np.array([r[0] for r in rows], dtype=np.int64)
        n = np.array([r[1] for r in rows], dtype=np.int64)
        mins = {nm: np.array([r[2 + 2 * j] for r in rows], dtype=np.float64)
                for j, nm in enumerate(names)}
        maxs = {nm: np.array([r[3 + 2 * j] for r in rows], dtype=np.float64)
                for j, nm in enumerate(names)}
        return Envelope(bucket_us, t, n, mins, maxs)

    def events(self) -> list:
        """Return the stored events (astcom_client.events.Event) by time."""
        from astcom_client.events import Event

        series = self.conn.query(f"SELECT seq, message, fields, source, level, kind "
                                 f"FROM {_ident(EVENTS_MEASUREMENT)}")
        out = [Event(int(r[0]), r[4], r[5], r[6], r[2] or "", json.loads(r[3] or "{}"),
                     int(r[1])) for s in series for r in s["values"]]
        out.sort(key=lambda e: (e.t_us, e.source, e.seq))
        return out

    def gaps(self) -> list[Gap]:
        """Return every recorded gap in time order."""
        series = self.conn.query(f"SELECT after_t_us, before_t_us, lost_samples, reason, session "
                                 f"FROM {_ident(GAPS_MEASUREMENT)}")
        return [Gap(int(r[1]), int(r[2]), int(r[3]), r[4], r[5] or "")
                for s in series for r in s["values"]]
