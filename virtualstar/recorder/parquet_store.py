"""The embedded store: hourly Parquet files of exact samples, a 1-s envelope beside them.

Layout of a store directory::

    DIR/recording.json                         signals (name, unit, dtype) and sessions
    DIR/samples/20261121T22Z-<session>.parquet  t_us (int64) + one column per signal
    DIR/overview/20261121T22Z-<session>.parquet 1-s buckets: t_us, n, <name>__min, <name>__max
    DIR/gaps.csv                                after_t_us, before_t_us, lost_samples, reason, session
    DIR/samples/<hour>-<session>.arrows.inprogress  the hour in progress (parquet_journal.py)
    DIR/writer.lock                             held (fcntl) by the live recorder, its PID inside

Files are standard Parquet (pandas, polars, DuckDB, MATLAB's parquetread): values are
stored exactly as streamed, compressed with zstd; float columns use BYTE_STREAM_SPLIT and
integer columns (t_us first) DELTA_BINARY_PACKED, which shrink smooth signals and
regular clocks the most. A file is partitioned by mount-time hour and written one big
row group at a time from a background thread, so memory stays bounded by one row group
and the event loop keeps receiving while zstd compresses. The hour in progress is an
append-only journal, durable every second; it becomes the hour's Parquet file when the
hour (or the recording) ends, or when the store is next opened after a crash.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import time
import warnings
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .background import BackgroundWriter, new_session_id
from .damage import (
    Damage,
    DamagedFileWarning,
    damaged_reason,
    footer_problem,
    row_group_span,
    short_error,
    warn_damaged,
)
from .decimation import Envelope, envelope, rebucket
from .event_store import EventJournal, read_events
from .exceptions import EmptyStore, QueryError, StoreError
from .parquet_journal import (
    GAP_FIELDS,
    HOUR_US,
    JOURNAL_SUFFIX,
    HourJournal,
    RecoveryReport,
    WriterLock,
    finalize_journal,
    hour_of,
    hour_span_us,
    live_writer_pid,
    recover,
    session_of,
)
from .samples import UNKNOWN_LOST, Gap, SampleBlock, SignalInfo
from .timeparse import utc_text

__all__ = [
    "DEFAULT_FLUSH_INTERVAL_S",
    "DEFAULT_ROW_GROUP_ROWS",
    "OVERVIEW_BUCKET_US",
    "PARQUET_FORMAT",
    "ParquetStoreReader",
    "ParquetStoreWriter",
    "recover_store",
    "utc_text",
]

PARQUET_FORMAT = "virtualstar-recorder/1"
DEFAULT_ROW_GROUP_ROWS = 1 << 16  # ≈ 65 s at 1 kHz: big enough for zstd (+0.4 % vs 4×), fast 2-s queries
DEFAULT_ZSTD_LEVEL = 3
OVERVIEW_BUCKET_US = 1_000_000
MAX_PENDING_FLUSHES = 2  # row groups handed to the writer thread before `write` waits
DEFAULT_FLUSH_INTERVAL_S = 1.0  # wall seconds: at most this much is lost to a crash


def _hour_label(hour: int) -> str:
    return datetime.fromtimestamp(hour * 3600, UTC).strftime("%Y%m%dT%HZ")




class ParquetStoreWriter:
    """Write one recording session into a store directory (created when missing).

    Use: ``w = ParquetStoreWriter(dir); w.begin(signals, source=..., rate_hz=...);``
    ``w.write(block)...; w.write_gap(gap); w.close()``. The hour in progress is journalled
    (parquet_journal.py): what was handed to `write` more than `flush_interval_s` ago
    survives a SIGKILL or a power loss. Raises StoreError when the directory cannot be
    written, another recorder is writing it, or it holds signals of other types under the
    same names.
    """

    def __init__(self, path: str | Path, *, row_group_rows: int = DEFAULT_ROW_GROUP_ROWS,
                 zstd_level: int = DEFAULT_ZSTD_LEVEL,
                 flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S) -> None:
        self.path = Path(path)
        self.row_group_rows = int(row_group_rows)
        self.zstd_level = int(zstd_level)
        self.flush_interval_s = float(flush_interval_s)
        self.session = ""
        self.signals: list[SignalInfo] = []
        self.rows_written = 0
        self.files: list[Path] = []
        self.recovered: RecoveryReport | None = None
        self._schema: pa.Schema | None = None
        self._buffer: list[SampleBlock] = []
        self._buffered = 0
        self._hour: int | None = None
        self._last_flush = time.monotonic()
        self._thread = BackgroundWriter("parquet-writer", MAX_PENDING_FLUSHES, self._store_error)
        self._lock = WriterLock(self.path)
        self._journal: HourJournal | None = None
        self._journal_hour: int | None = None
        self._events: EventJournal | None = None
        self._closed = False

    # -- session -------------------------------------------------------------------------
    def begin(self, signals: list[SignalInfo], *, source: str = "", rate_hz: float = 0.0,
              period_us: float = 0.0) -> str:
        """Start a session of `signals`; return its id. Raises StoreError.

        A store left by a recorder that died is recovered first (`self.recovered` says so).
        """
        self.signals = list(signals)
        self.session = new_session_id()
        try:
            (self.path / "samples").mkdir(parents=True, exist_ok=True)
            (self.path / "overview").mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"cannot create the store directory {self.path}: {exc.strerror}") from None
        self._lock.acquire()
        try:
            self.recovered = recover(self.path, row_group_rows=self.row_group_rows,
                                     zstd_level=self.zstd_level,
                                     overview_bucket_us=OVERVIEW_BUCKET_US, hold_lock=self._lock)
            meta = _read_meta(self.path)
            known = _known_signals(meta, self.path)
        except (StoreError, OSError) as exc:
            self._lock.release()
            if isinstance(exc, StoreError):
                raise
            raise StoreError(f"cannot recover {self.path} before recording: {exc}") from None
        for s in self.signals:
            old = known.get(s.name)
            if old is not None and old.get("dtype") != s.dtype:
                self._lock.release()
                raise StoreError(f"store {self.path} already holds {s.name} as {old.get('dtype')}; "
                                 f"this recording streams it as {s.dtype}: use another directory")
            known[s.name] = asdict(s)
        meta["format"] = PARQUET_FORMAT
        meta["signals"] = list(known.values())
        meta.setdefault("sessions", []).append({
            "id": self.session, "source": source, "rate_hz": rate_hz, "period_us": period_us,
            "names": [s.name for s in self.signals],
            "started_utc": datetime.now(UTC).isoformat(timespec="seconds")})
        _write_meta(self.path, meta)
        fields = [pa.field("t_us", pa.int64(), nullable=False,
                           metadata={"unit": "us", "doc": "mount time, µs since 1970 UTC"})]
        fields += [pa.field(s.name, pa.from_numpy_dtype(np.dtype(s.dtype)),
                            metadata={"unit": s.unit}) for s in self.signals]
        self._schema = pa.schema(fields, metadata={"format": PARQUET_FORMAT,
                                                   "session": self.session})
        self._last_flush = time.monotonic()
        self._events = EventJournal(self.path, self.session)
        return self.session

    # -- samples -------------------------------------------------------------------------
    def write(self, block: SampleBlock) -> None:
        """Buffer `block`; journal what is buffered every flush interval or row group, and
        finish an hour as soon as a sample of a later hour arrives."""
        if len(block) == 0:
            self.flush_if_due()
            return
        hours = block.t_us // HOUR_US
        if hours[0] != hours[-1]:  # split at each hour boundary
            cuts = np.flatnonzero(np.diff(hours)) + 1
            for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(block)], strict=True):
                self.write(block.slice(int(a), int(b)))
            return
        hour = int(hours[0])
        if self._hour is not None and hour != self._hour:
            self._flush()
            self._thread.submit(self._finish_hour)
        self._hour = hour
        self._buffer.append(block)
        self._buffered += len(block)
        if self._buffered >= self.row_group_rows:
            self._flush()
        else:
            self.flush_if_due()

    def flush_if_due(self) -> None:
        """Journal what is buffered if the flush interval has passed (call it when idle too)."""
        if self._buffer and time.monotonic() - self._last_flush >= self.flush_interval_s:
            self._flush()

    def write_gap(self, gap: Gap) -> None:
        """Append `gap` to gaps.csv at once (gaps are rare and must survive a crash)."""
        path = self.path / "gaps.csv"
        new = not path.exists()
        try:
            with path.open("a", newline="") as f:
                w = csv.writer(f)
                if new:
                    w.writerow(GAP_FIELDS)
                w.writerow([gap.after_t_us, gap.before_t_us, gap.lost_samples, gap.reason,
                            gap.session or self.session])
        except OSError as exc:
            raise StoreError(f"cannot append to {path}: {exc.strerror}") from None

    def write_events(self, events: list) -> None:
        """Append structured events (astcom_client.events.Event) to the store at once."""
        if self._events is None:
            raise StoreError("write_events before begin: start the session first")
        self._events.append(events)

    def flush(self) -> None:
        """Journal what is buffered and wait until it is on disk."""
        self._flush()
        self._thread.wait(0)

    def close(self) -> None:
        """Write the rest, finish the hour's files; raise StoreError if a write failed."""
        if self._closed:
            return
        self._closed = True
        try:
            self._flush()
            self._thread.submit(self._finish_hour)
            self._thread.wait(0)
            if self._events is not None:
                self._events.finish()
        finally:
            self._thread.shutdown()
            self._lock.release()

    def __enter__(self) -> ParquetStoreWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _flush(self) -> None:
        self._last_flush = time.monotonic()
        if not self._buffer:
            return
        blocks, self._buffer, self._buffered = self._buffer, [], 0
        self._thread.submit(self._append, self._hour, blocks)

    def _store_error(self, exc: BaseException) -> BaseException:
        if isinstance(exc, StoreError):
            return exc
        return StoreError(f"writing the store {self.path} failed: {exc}")

    # -- the writer thread ---------------------------------------------------------------
    def _append(self, hour: int, blocks: list[SampleBlock]) -> None:
        assert self._schema is not None
        t_us = np.concatenate([b.t_us for b in blocks]) if len(blocks) > 1 else blocks[0].t_us
        columns = [pa.array(t_us, pa.int64())]
        for s in self.signals:
            col = (np.concatenate([b.columns[s.name] for b in blocks]) if len(blocks) > 1
                   else blocks[0].columns[s.name])
            columns.append(pa.array(col))
        if self._journal is not None and self._journal_hour != hour:
            self._finish_hour()
        if self._journal is None:
            name = f"{_hour_label(hour)}-{self.session}"
            part = 1
            # an hour met again (a device clock set back) gets a file of its own, never
            # replacing the one already finished
            while (self.path / "samples" / f"{name}.parquet").exists():
                part += 1
                name = f"{_hour_label(hour)}-{self.session}-{part}"
            self._journal = HourJournal(self.path / "samples" / (name + JOURNAL_SUFFIX),
                                        self._schema)
            self._journal_hour = hour
        self._journal.append(pa.Table.from_arrays(columns, schema=self._schema))
        self.rows_written += len(t_us)

    def _finish_hour(self) -> None:
        """Close the hour's journal and turn it into the hour's Parquet file and overview."""
        if self._journal is None:
            return
        journal, self._journal = self._journal, None
        journal.close()
        stem = journal.path.name[: -len(JOURNAL_SUFFIX)]
        done = finalize_journal(journal.path, self.path / "samples" / f"{stem}.parquet",
                                self.path / "overview" / f"{stem}.parquet",
                                row_group_rows=self.row_group_rows, zstd_level=self.zstd_level,
                                overview_bucket_us=OVERVIEW_BUCKET_US)
        self.files += done.files


def recover_store(path: str | Path) -> RecoveryReport | None:
    """Finish a store whose recorder died (see parquet_journal.recover); None if nothing to do."""
    return recover(Path(path), row_group_rows=DEFAULT_ROW_GROUP_ROWS,
                   zstd_level=DEFAULT_ZSTD_LEVEL, overview_bucket_us=OVERVIEW_BUCKET_US)


def _read_meta(path: Path) -> dict[str, Any]:
    """Return recording.json ({} when there is none); raise StoreError naming it, with
    what is wrong, when it is damaged (cut short, not JSON, not an object)."""
    meta_path = path / "recording.json"
    if not meta_path.exists():
        return {}
    try:
        raw = meta_path.read_bytes()
    except OSError as exc:
        raise StoreError(f"cannot read {meta_path}: {exc.strerror}") from None
    try:
        meta = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise StoreError(f"{meta_path} is damaged: not UTF-8 text (byte {exc.start} of "
                         f"{len(raw)})") from None
    except ValueError as exc:
        cut = " (cut short?)" if getattr(exc, "pos", -1) >= len(raw.rstrip()) else ""
        raise StoreError(f"{meta_path} is damaged: not valid JSON{cut}: {exc}") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("signals", []), list) \
            or not isinstance(meta.get("sessions", []), list):
        raise StoreError(f"{meta_path} is damaged: expected an object with 'signals' and "
                         "'sessions' lists")
    return meta


def _known_signals(meta: dict[str, Any], path: Path) -> dict[str, dict[str, Any]]:
    """Return recording.json's signals by name; StoreError when an entry is not a signal."""
    try:
        known = {str(d["name"]): dict(d) for d in meta.get("signals", [])}
        for d in known.values():
            pa.from_numpy_dtype(np.dtype(str(d.get("dtype", "float64"))))
        return known
    except (KeyError, TypeError, ValueError, pa.ArrowException):
        raise StoreError(f"{path / 'recording.json'} is damaged: a 'signals' entry without a "
                         "name or with an unknown dtype") from None


def _write_meta(path: Path, meta: dict[str, Any]) -> None:
    tmp = path / "recording.json.tmp"
    tmp.write_text(json.dumps(meta, indent=2) + "\n")
    os.replace(tmp, path / "recording.json")


class ParquetStoreReader:
    """Read a store directory: signals, time range, windows at full rate, envelopes, gaps.

    Raises EmptyStore when `path` holds no finished sample file.
    """

    def __init__(self, path: str | Path, *, recover_crashed: bool = True) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise EmptyStore(f"store directory {self.path} does not exist")
        #: Damaged files (or row groups) met so far: each is warned about once
        #: (DamagedFileWarning), skipped, and reported by gaps() as a gap.
        self.damaged: list[Damage] = []
        # A recorder that died left its hour in progress as a journal: finish it now (once;
        # `recovered` says what was done). A live recorder's journal is its own.
        self.recovered = recover_store(self.path) if recover_crashed else None
        self.writer_pid = live_writer_pid(self.path)
        try:
            self.meta = _read_meta(self.path)
            _known_signals(self.meta, self.path)
        except StoreError as exc:  # the samples say what they are without it
            warnings.warn(f"{exc}; the signals are read from the sample files instead",
                          DamagedFileWarning, stacklevel=2)
            self.meta = {}
        found = sorted((self.path / "samples").glob("*.parquet"))
        self.sample_files = [f for f in found if self._footer_ok(f, "its hour is skipped")]
        damaged_stems = {d.path.stem for d in self.damaged}
        self.overview_files = [
            f for f in sorted((self.path / "overview").glob("*.parquet"))
            if f.stem not in damaged_stems and self._footer_ok(f, "the envelope of its hour "
                                                                   "is computed from the samples")]
        if not self.sample_files:
            hint = (f" (a recording, PID {self.writer_pid}, is writing it: its hour in progress "
                    "becomes readable when the hour ends)" if self.writer_pid else "")
            if self.damaged:
                raise EmptyStore(f"{self.path} holds no readable sample files (damaged: "
                                 f"{', '.join(d.path.name for d in self.damaged)}){hint}")
            raise EmptyStore(f"{self.path} holds no sample files (samples/*.parquet){hint}")
        self._signals: list[SignalInfo] | None = None

    def _footer_ok(self, f: Path, skipped: str) -> bool:
        """Check a file's Parquet footer; a damaged one is recorded, warned about, and False."""
        problem = footer_problem(f)
        if problem is None:
            return True
        self._damaged(Damage(f, problem, *hour_span_us(f)), skipped)
        return False

    def _damaged(self, damage: Damage, skipped: str) -> None:
        if all((d.path, d.problem) != (damage.path, damage.problem) for d in self.damaged):
            self.damaged.append(damage)
            warn_damaged(damage, self.path, skipped)

    def _read_schema(self, files: list[Path]) -> pa.Schema:
        try:
            return pa.unify_schemas([pq.read_schema(f) for f in files])
        except (OSError, pa.ArrowInvalid) as exc:
            raise StoreError(f"cannot read the Parquet files of {self.path}: {exc}") from None

    @property
    def schema(self) -> pa.Schema:
        """Return the store's columns: t_us and every signal (from recording.json)."""
        fields = [pa.field("t_us", pa.int64())]
        fields += [pa.field(s.name, pa.from_numpy_dtype(np.dtype(s.dtype)),
                            metadata={"unit": s.unit}) for s in self.signals()]
        return pa.schema(fields)

    def signals(self) -> list[SignalInfo]:
        """Return the recorded signals with their units and dtypes."""
        if self._signals is None:
            listed = self.meta.get("signals")
            if listed:
                self._signals = [SignalInfo(str(d["name"]), str(d.get("unit", "")),
                                            str(d.get("dtype", "float64")))
                                 for d in _known_signals(self.meta, self.path).values()]
            else:  # no recording.json: ask the files themselves
                self._signals = [
                    SignalInfo(f.name, (f.metadata or {}).get(b"unit", b"").decode(),
                               np.dtype(f.type.to_pandas_dtype()).name)
                    for f in self._read_schema(self.sample_files) if f.name != "t_us"]
        return self._signals

    def _files(self, files: list[Path], from_t_us: int, to_t_us: int) -> list[Path]:
        """Return the files whose hour (from their name) overlaps [from, to)."""
        keep = []
        for f in files:
            hour = hour_of(f)
            if hour is None or (hour * HOUR_US < to_t_us and (hour + 1) * HOUR_US > from_t_us):
                keep.append(f)
        return keep

    def time_range(self) -> tuple[int, int]:
        """Return (first, last) sample time in the store, µs."""
        lo, hi = None, None
        hours = [h for h in map(hour_of, self.sample_files) if h is not None]
        ends = ({min(hours), max(hours)} if len(hours) == len(self.sample_files) else None)
        for f in self.sample_files:
            if ends is not None and hour_of(f) not in ends:
                continue  # an hourly file lies between the first and the last hour's
            md = pq.ParquetFile(f).metadata
            for i in range(md.num_row_groups):
                st = md.row_group(i).column(0).statistics
                if st is None or not st.has_min_max:
                    continue
                lo = st.min if lo is None else min(lo, st.min)
                hi = st.max if hi is None else max(hi, st.max)
        if lo is None or hi is None:
            raise EmptyStore(f"{self.path} holds no samples")
        return int(lo), int(hi)

    def count(self) -> int:
        """Return the number of stored samples (rows)."""
        return sum(pq.ParquetFile(f).metadata.num_rows for f in self.sample_files)

    def _names(self, names: list[str] | None) -> list[str]:
        have = [s.name for s in self.signals()]
        if not names:
            return have
        unknown = [n for n in names if n not in have]
        if unknown:
            raise QueryError(f"unknown signal(s) {', '.join(unknown)}; the store holds "
                             f"{', '.join(have)}")
        return list(names)

    def window(self, from_t_us: int, to_t_us: int, names: list[str] | None = None) -> SampleBlock:
        """Return every sample with from_t_us <= t_us < to_t_us, sorted by time."""
        names = self._names(names)
        files = self._files(self.sample_files, from_t_us, to_t_us)
        table = self._read_window(files, ["t_us", *names], from_t_us, to_t_us)
        t = table.column("t_us").to_numpy()
        cols = {n: table.column(n).to_numpy(zero_copy_only=False) for n in names}
        if len(t) > 1 and np.any(np.diff(t) < 0):
            order = np.argsort(t, kind="stable")
            t = t[order]
            cols = {n: v[order] for n, v in cols.items()}
        return SampleBlock(t, cols)

    def _read_window(self, files: list[Path], columns: list[str], from_t_us: int,
                     to_t_us: int) -> pa.Table:
        """Read [from, to) of `files`: all at once, or, when a file turns out damaged,
        row group by row group, skipping (and naming) the ones that cannot be read."""
        import pyarrow.dataset as ds  # (and pandas): only where a store is queried

        flt = (ds.field("t_us") >= from_t_us) & (ds.field("t_us") < to_t_us)
        try:
            dataset = ds.dataset([str(f) for f in files], schema=self.schema, format="parquet")
            return dataset.to_table(columns=columns, filter=flt)
        except (OSError, pa.ArrowException, ValueError):
            pass  # some file is damaged inside: find it below
        parts = [self.schema.empty_table().select(columns)]
        for f in files:
            for i, group in self._row_groups(f, from_t_us, to_t_us):
                try:
                    table = group.read_row_group(i, columns=[c for c in columns
                                                             if c in group.schema_arrow.names])
                except (OSError, pa.ArrowException, ValueError) as exc:
                    lo, hi = row_group_span(group, i)
                    self._damaged(Damage(f, f"row group {i}: {short_error(exc)}", lo, hi),
                                  "that row group is skipped")
                    continue
                t = table.column("t_us").to_numpy()
                keep = (t >= from_t_us) & (t < to_t_us)
                table = table.filter(pa.array(keep))
                parts.append(pa.table({c: (table.column(c) if c in table.column_names
                                           else pa.nulls(table.num_rows, self.schema.field(c).type))
                                       for c in columns}).cast(parts[0].schema))
        return pa.concat_tables(parts)

    def _row_groups(self, f: Path, from_t_us: int, to_t_us: int):
        """Yield (index, ParquetFile) of the row groups of `f` that may hold [from, to)."""
        group = pq.ParquetFile(f)
        for i in range(group.metadata.num_row_groups):
            lo, hi = row_group_span(group, i)
            if lo == -1 or (lo < to_t_us and hi >= from_t_us):
                yield i, group

    def envelope(self, from_t_us: int, to_t_us: int, names: list[str] | None = None,
                 buckets: int = 2000) -> Envelope:
        """Return the min/max envelope of [from, to) in about `buckets` buckets.

        Buckets of 1 s or more come from the stored 1-s overview (edges rounded to whole
        seconds); finer ones are computed from the samples themselves.
        """
        names = self._names(names)
        if buckets < 1:
            raise QueryError(f"buckets must be >= 1, got {buckets}")
        if to_t_us <= from_t_us:
            raise QueryError(f"empty window: --to ({to_t_us}) must be after --from ({from_t_us})")
        bucket_us = max(1, -(-(to_t_us - from_t_us) // buckets))
        if bucket_us < OVERVIEW_BUCKET_US or not self.overview_files:
            block = self.window(from_t_us, to_t_us, names)
            return envelope(block.t_us, block.columns, bucket_us, from_t_us)
        bucket_us = -(-bucket_us // OVERVIEW_BUCKET_US) * OVERVIEW_BUCKET_US
        cols = ["t_us", "n"] + [f"{n}__{m}" for n in names for m in ("min", "max")]
        ov_files = self._files(self.overview_files, from_t_us, to_t_us)
        if not ov_files:
            return rebucket(envelope(np.empty(0, np.int64), {n: np.empty(0) for n in names},
                                     OVERVIEW_BUCKET_US), bucket_us)
        lo = from_t_us // OVERVIEW_BUCKET_US * OVERVIEW_BUCKET_US
        import pyarrow.dataset as ds

        try:
            ov = ds.dataset([str(f) for f in ov_files], format="parquet")
            table = ov.to_table(columns=cols, filter=(ds.field("t_us") >= lo)
                                & (ds.field("t_us") < to_t_us))
        except (OSError, pa.ArrowException, ValueError) as exc:
            # a damaged overview: the samples give the same envelope, only slower
            self._damaged(Damage(ov_files[0].parent, f"an overview file cannot be read: {exc}"),
                          "the envelope is computed from the samples")
            block = self.window(from_t_us, to_t_us, names)
            return envelope(block.t_us, block.columns, bucket_us, from_t_us)
        fine = Envelope(OVERVIEW_BUCKET_US, table.column("t_us").to_numpy(),
                        table.column("n").to_numpy(),
                        {n: table.column(f"{n}__min").to_numpy() for n in names},
                        {n: table.column(f"{n}__max").to_numpy() for n in names})
        return rebucket(fine, bucket_us, lo)

    def gaps(self) -> list[Gap]:
        """Return every recorded gap, in file order, then one per damaged file or row group
        met so far (reason "damaged: ...", lost_samples -1, the stretch it may have held).

        Rows of gaps.csv that cannot be read are skipped with a DamagedFileWarning.
        """
        out = []
        path = self.path / "gaps.csv"
        if path.exists():
            text = path.read_bytes().decode("utf-8", errors="replace")
            bad = 0
            for row in csv.reader(text.splitlines()):
                if row == GAP_FIELDS or not row:
                    continue
                try:
                    after, before, lost, reason, session = row
                    out.append(Gap(int(after), int(before), int(lost), reason, session))
                except ValueError:  # a wrong number of fields, or not numbers
                    bad += 1
            if bad:
                self._damaged(Damage(path, f"{bad} unreadable row(s)"), "those rows are skipped")
        for d in self.damaged:
            if d.path.parent.name == "samples":
                out.append(Gap(d.from_t_us, d.to_t_us, UNKNOWN_LOST, damaged_reason(d, self.path),
                               session_of(d.path)))
        return out

    def events(self) -> list:
        """Return the store's structured events (astcom_client.events.Event), by time."""
        return read_events(self.path)

    def iter_blocks(self, names: list[str] | None = None,
                    batch_rows: int = 1 << 18) -> Any:
        """Yield SampleBlocks of the whole store in time order, `batch_rows` at a time."""
        names = self._names(names)
        files = sorted(self.sample_files, key=lambda f: _first_t(f))
        for f in files:
            pf = pq.ParquetFile(f)
            present = [n for n in names if n in pf.schema_arrow.names]
            for i in range(pf.metadata.num_row_groups):
                try:
                    group = pf.read_row_group(i, columns=["t_us", *present])
                except (OSError, pa.ArrowException, ValueError) as exc:
                    lo, hi = row_group_span(pf, i)
                    self._damaged(Damage(f, f"row group {i}: {short_error(exc)}", lo, hi),
                                  "that row group is skipped")
                    continue
                yield from self._blocks_of(group, names, present, batch_rows)

    @staticmethod
    def _blocks_of(group: pa.Table, names: list[str], present: list[str],
                   batch_rows: int) -> Any:
        """Yield a row group as SampleBlocks of `batch_rows`; absent signals are NaN."""
        for batch in group.to_batches(max_chunksize=batch_rows):
            t = batch.column("t_us").to_numpy()
            cols = {}
            for n in names:
                if n in present:
                    cols[n] = batch.column(n).to_numpy(zero_copy_only=False)
                else:
                    cols[n] = np.full(len(t), np.nan)
            yield SampleBlock(t, cols)


def _first_t(path: Path) -> int:
    md = pq.ParquetFile(path).metadata
    with contextlib.suppress(Exception):
        return int(md.row_group(0).column(0).statistics.min)
    return 0

