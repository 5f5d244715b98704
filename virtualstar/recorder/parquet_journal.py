"""The hour in progress of a Parquet store, kept so that a crash loses seconds, not hours.

A Parquet file is readable only once its footer is written, at the end of its hour. So the
hour in progress goes first into an append-only journal, an Arrow IPC *stream* file
(``samples/<hour>-<session>.arrows.inprogress``): every batch is self-delimiting, and a
reader gets every batch written before the last incomplete one. The writer appends a batch
at least once per flush interval and fsyncs it. When the hour ends (the first sample of a
later hour, or the end of the recording) the journal is turned into the hour's Parquet file
and its 1-s overview, and removed.

A store has one writer at a time: it holds an exclusive ``fcntl`` lock on
``writer.lock`` (with its PID inside) for as long as it writes. A journal found while no one
holds the lock belongs to a writer that died (SIGKILL, power loss): `recover` turns it into
the hour's files, as the writer would have, and records the crash as a gap.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .damage import DAMAGED_SUFFIX, is_torn_tail, short_error
from .decimation import envelope, merge_envelope
from .exceptions import StoreError

__all__ = ["CRASH_REASON", "GAP_FIELDS", "JOURNAL_SUFFIX", "LOCK_NAME", "HourJournal", "RecoveryReport", "WriterLock",
           "append_gap", "finalize_journal", "hour_of", "hour_span_us", "live_writer_pid", "recover",
           "session_of", "write_hour_files"]

JOURNAL_SUFFIX = ".arrows.inprogress"
LOCK_NAME = "writer.lock"
CRASH_REASON = "recorder died"
HOUR_US = 3_600_000_000
GAP_FIELDS = ["after_t_us", "before_t_us", "lost_samples", "reason", "session"]
_IPC_OPTIONS = pa.ipc.IpcWriteOptions(compression="lz4")


class WriterLock:
    """The exclusive right to write a store: an fcntl lock on DIR/writer.lock, PID inside.

    The kernel drops the lock when the process dies, however it dies, so a lock that can be
    taken means no live writer.
    """

    def __init__(self, store: Path) -> None:
        self.path = store / LOCK_NAME
        self._fd: int | None = None

    def try_acquire(self) -> bool:
        """Take the lock if no live process holds it; return whether we hold it now."""
        if self._fd is not None:
            return True
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            return False
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd
        return True

    def acquire(self) -> None:
        """Take the lock; raise StoreError naming the live writer's PID when another holds it."""
        if not self.try_acquire():
            raise StoreError(f"another recorder (PID {_pid_in(self.path) or '?'}) is writing "
                             f"{self.path.parent}; record into another directory, or stop it first")

    def release(self) -> None:
        """Give the lock back (the file stays: it is the place of the lock)."""
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None


def live_writer_pid(store: Path) -> int | None:
    """Return the PID of the live recorder writing `store`, or None when none is."""
    lock = WriterLock(store)
    if not lock.path.exists():
        return None
    if lock.try_acquire():
        lock.release()
        return None
    return _pid_in(lock.path) or -1


def _pid_in(path: Path) -> int | None:
    with contextlib.suppress(OSError, ValueError):
        return int(path.read_text().strip() or 0) or None
    return None


class HourJournal:
    """An append-only Arrow IPC stream of one hour's samples; each `append` is durable."""

    def __init__(self, path: Path, schema: pa.Schema) -> None:
        self.path = path
        try:
            self._file = open(path, "wb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise StoreError(f"cannot create {path}: {exc.strerror}") from None
        self._writer = pa.ipc.new_stream(self._file, schema, options=_IPC_OPTIONS)
        self.rows = 0

    def append(self, table: pa.Table) -> None:
        """Write `table` as whole batches, then flush and fsync: it survives a crash from now."""
        self._writer.write_table(table)
        self._file.flush()
        os.fsync(self._file.fileno())
        self.rows += table.num_rows

    def close(self) -> None:
        """End the stream (an end-of-stream marker) and close the file."""
        self._writer.close()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()


@dataclass
class JournalEnd:
    """How reading a journal ended: `problem` is None at its end or at a torn last batch
    (a writer that died), else what is wrong with the bytes after `good_bytes`."""

    good_bytes: int = 0
    size_bytes: int = 0
    problem: str | None = None


def read_journal(path: Path, end: JournalEnd | None = None) -> Iterator[pa.RecordBatch]:
    """Yield every complete batch of a journal, stopping at a torn last one or at damage.

    `end`, when given, is filled in with how the reading ended (JournalEnd).
    """
    end = end if end is not None else JournalEnd()
    try:
        source = pa.OSFile(str(path))  # read batch by batch: memory stays one batch
    except OSError as exc:
        raise StoreError(f"cannot read {path}: {exc}") from None
    with source:
        end.size_bytes = source.size()
        try:
            reader = pa.ipc.open_stream(source)
        except (pa.ArrowException, OSError, ValueError) as exc:
            # killed before the schema was complete: nothing to recover; else damage
            end.problem = None if is_torn_tail(exc) else f"its schema: {short_error(exc)}"
            return
        while True:
            end.good_bytes = source.tell()
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                return
            except (pa.ArrowException, OSError, ValueError) as exc:
                # the batch being written when the writer died, or bytes that are wrong
                if not is_torn_tail(exc):
                    end.problem = (f"unreadable after byte {end.good_bytes} of "
                                   f"{end.size_bytes}: {short_error(exc)}")
                return
            yield batch


@dataclass
class FinalizedHour:
    """What `finalize_journal` wrote: rows, first and last sample time (µs), the files."""

    rows: int = 0
    first_t_us: int | None = None
    last_t_us: int | None = None
    files: list[Path] = field(default_factory=list)
    damaged: Path | None = None  # the journal moved aside (.damaged), when it was damaged
    problem: str | None = None  # what was wrong with it


def finalize_journal(journal: Path, samples_final: Path, overview_final: Path, *,
                     row_group_rows: int, zstd_level: int,
                     overview_bucket_us: int) -> FinalizedHour:
    """Turn a journal into the hour's Parquet file and its 1-s overview; remove the journal.

    Row groups of `row_group_rows`; memory stays within one row group. Each file is written
    under a temporary name, fsynced and renamed, so a crash here leaves the journal, which a
    later `recover` finalizes again. A damaged journal (bytes that are wrong, not a torn
    last batch) gives its batches before the damage, and is moved aside as
    ``<name>.damaged`` instead of removed (`done.damaged`, `done.problem`).
    """
    end = JournalEnd()
    done = write_hour_files(read_journal(journal, end), samples_final, overview_final,
                            row_group_rows=row_group_rows, zstd_level=zstd_level,
                            overview_bucket_us=overview_bucket_us)
    if end.problem is None:
        journal.unlink(missing_ok=True)
    else:  # evidence: never deleted
        done.damaged = journal.with_name(journal.name + DAMAGED_SUFFIX)
        done.problem = end.problem
        os.replace(journal, done.damaged)
    return done


def write_hour_files(batches: Iterable[pa.RecordBatch], samples_final: Path,
                     overview_final: Path, *, row_group_rows: int, zstd_level: int,
                     overview_bucket_us: int) -> FinalizedHour:
    """Write an hour's samples (`batches`, in time order) as its Parquet file and 1-s
    overview, each under a temporary name then renamed; nothing when there are no rows."""
    done = FinalizedHour()
    pending: list[pa.RecordBatch] = []
    pending_rows = 0
    writer: pq.ParquetWriter | None = None
    overview_parts = []
    temp = samples_final.with_name(samples_final.name + ".tmp")

    def write_group() -> None:
        nonlocal writer, pending, pending_rows
        table = pa.Table.from_batches(pending)
        pending, pending_rows = [], 0
        if writer is None:
            writer = parquet_writer(temp, table.schema, zstd_level)
        writer.write_table(table, row_group_size=table.num_rows)
        t = table.column("t_us").to_numpy()
        names = [n for n in table.column_names if n != "t_us"]
        overview_parts.append(envelope(t, {n: table.column(n).to_numpy(zero_copy_only=False)
                                          for n in names}, overview_bucket_us))
        done.rows += table.num_rows
        done.first_t_us = int(t[0]) if done.first_t_us is None else done.first_t_us
        done.last_t_us = int(t[-1])

    schema = None
    for batch in batches:
        schema = batch.schema
        if batch.num_rows == 0:
            continue
        pending.append(batch)
        pending_rows += batch.num_rows
        if pending_rows >= row_group_rows:
            write_group()
    if pending:
        write_group()
    if writer is not None:
        writer.close()
        _fsync_and_rename(temp, samples_final)
        done.files.append(samples_final)
        assert schema is not None
        _write_overview(merge_envelope(overview_parts), schema, overview_final, zstd_level)
    return done


def overview_schema(samples_schema: pa.Schema) -> pa.Schema:
    """Return the 1-s overview's columns for a samples schema: t_us, n, <name>__min/max."""
    fields = [pa.field("t_us", pa.int64()), pa.field("n", pa.int64())]
    for f in samples_schema:
        if f.name != "t_us":
            fields += [pa.field(f"{f.name}__min", f.type), pa.field(f"{f.name}__max", f.type)]
    return pa.schema(fields)


def _write_overview(env, samples_schema: pa.Schema, final: Path, zstd_level: int) -> None:
    schema = overview_schema(samples_schema).with_metadata({"bucket_us": str(env.bucket_us)})
    arrays = [pa.array(env.t_us, pa.int64()), pa.array(env.n, pa.int64())]
    for f in samples_schema:
        if f.name != "t_us":
            arrays += [pa.array(np.asarray(env.mins[f.name]), f.type),
                       pa.array(np.asarray(env.maxs[f.name]), f.type)]
    temp = final.with_name(final.name + ".tmp")
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), temp, compression="zstd",
                   compression_level=zstd_level)
    _fsync_and_rename(temp, final)


def parquet_writer(path: Path, schema: pa.Schema, zstd_level: int) -> pq.ParquetWriter:
    """Open a Parquet writer with the store's encodings (zstd; BYTE_STREAM_SPLIT for floats,
    DELTA_BINARY_PACKED for integers: smooth signals and regular clocks shrink most)."""
    encodings = {"t_us": "DELTA_BINARY_PACKED"}
    for f in schema:
        if f.name != "t_us":
            if pa.types.is_floating(f.type):
                encodings[f.name] = "BYTE_STREAM_SPLIT"
            elif pa.types.is_integer(f.type):
                encodings[f.name] = "DELTA_BINARY_PACKED"
    try:
        return pq.ParquetWriter(path, schema, compression="zstd", compression_level=zstd_level,
                                use_dictionary=False, column_encoding=encodings,
                                write_statistics=True)
    except OSError as exc:
        raise StoreError(f"cannot create {path}: {exc}") from None


def _fsync_and_rename(temp: Path, final: Path) -> None:
    fd = os.open(temp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(temp, final)
    dir_fd = os.open(final.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)  # the rename itself must survive a power loss
    finally:
        os.close(dir_fd)


@dataclass
class RecoveryReport:
    """What `recover` found and did: journals finalized, rows kept, the crash gap."""

    store: Path
    journals: list[Path] = field(default_factory=list)
    rows: int = 0
    last_t_us: int | None = None
    unreadable: list[Path] = field(default_factory=list)
    #: damaged files moved aside (<name>.damaged) with what was wrong, each also a gap
    damaged: list[tuple[Path, str]] = field(default_factory=list)

    def __str__(self) -> str:
        where = (f", the last sample at t_us {self.last_t_us}" if self.last_t_us is not None
                 else "")
        text = (f"recovered {self.store}: its recorder died; {len(self.journals)} unfinished "
                f"hour file(s) finalized, {self.rows} samples kept{where}; the crash is "
                "recorded as a gap" if self.journals else f"recovered {self.store}")
        if self.unreadable:
            text += ("; unreadable (written by an older recorder, no journal): "
                     + ", ".join(p.name for p in self.unreadable))
        for moved, problem in self.damaged:
            text += (f"; DAMAGED {moved.name.removesuffix(DAMAGED_SUFFIX)} ({problem}): "
                     f"moved aside as {moved.name}, its loss recorded as a gap")
        return text


def recover(store: Path, *, row_group_rows: int, zstd_level: int, overview_bucket_us: int,
            hold_lock: WriterLock | None = None) -> RecoveryReport | None:
    """Finalize the journals of a writer that died; return what was done, None if nothing.

    Does nothing while a live writer holds the store's lock (its journals are its own), unless
    the caller holds the lock itself (`hold_lock`, a writer starting in the same store).
    """
    samples_dir = store / "samples"
    journals = sorted(samples_dir.glob("*" + JOURNAL_SUFFIX)) if samples_dir.is_dir() else []
    legacy = sorted(samples_dir.glob("*.parquet.inprogress")) if samples_dir.is_dir() else []
    if not journals and not legacy:
        return None
    lock = hold_lock or WriterLock(store)
    if hold_lock is None and not lock.try_acquire():
        return None
    try:
        report = RecoveryReport(store)
        sessions: dict[str, int] = {}
        for journal in journals:
            stem = journal.name[: -len(JOURNAL_SUFFIX)]
            done = finalize_journal(journal, samples_dir / f"{stem}.parquet",
                                    store / "overview" / f"{stem}.parquet",
                                    row_group_rows=row_group_rows, zstd_level=zstd_level,
                                    overview_bucket_us=overview_bucket_us)
            report.journals.append(journal)
            report.rows += done.rows
            session = session_of(journal)
            if done.damaged is not None:
                assert done.problem is not None
                report.damaged.append((done.damaged, done.problem))
                # after the last sample kept (or the hour's start): what followed is lost
                after = (done.last_t_us if done.last_t_us is not None
                         else hour_span_us(journal)[0])
                append_gap(store, [after, -1, -1, f"damaged: samples/{journal.name} "
                                    f"({done.problem}); moved aside as {done.damaged.name}",
                                    session])
            if done.last_t_us is not None:
                sessions[session] = max(sessions.get(session, done.last_t_us), done.last_t_us)
                report.last_t_us = max(report.last_t_us or done.last_t_us, done.last_t_us)
        for old in legacy:
            target = old.with_name(old.name.replace(".inprogress", ".unrecoverable"))
            os.replace(old, target)
            report.unreadable.append(target)
        for session, last in sessions.items():
            # after_t_us: the last sample kept; before_t_us unknown (-1): nothing was received
            # after it by this session
            append_gap(store, [last, -1, -1, CRASH_REASON, session])
        return report
    finally:
        if hold_lock is None:
            lock.release()


def hour_of(path: Path) -> int | None:
    """Return the mount-time hour (hours since 1970) in an hour file's name
    (<YYYYmmddTHHZ>-<session>...), None if it has none."""
    import datetime as dt

    try:
        when = dt.datetime.strptime(path.name[:12], "%Y%m%dT%HZ").replace(tzinfo=dt.UTC)
    except ValueError:
        return None
    return int(when.timestamp()) // 3600


def hour_span_us(path: Path) -> tuple[int, int]:
    """Return [start, end) µs of the hour in a file's name, (-1, -1) if it names none."""
    hour = hour_of(path)
    return (hour * HOUR_US, (hour + 1) * HOUR_US) if hour is not None else (-1, -1)


def session_of(path: Path) -> str:
    """Return the session in an hour file's name (<hour>-<session>[-part].<suffixes>)."""
    stem = path.name.split(".", 1)[0]
    return stem.split("-", 1)[1] if "-" in stem else ""


def append_gap(store: Path, row: list[object]) -> None:
    """Append one row (GAP_FIELDS) to the store's gaps.csv, with the header when new."""
    path = store / "gaps.csv"
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.writer(f)
        if new:
            w.writerow(GAP_FIELDS)
        w.writerow(row)
