"""Events beside the samples of a Parquet store: a durable journal, then one Parquet table.

    DIR/events.jsonl                  the journal: one JSON event per line, appended and
                                      fsynced as events arrive (events are rare; each must
                                      survive a crash like a gap does)
    DIR/events/<session>.parquet      the session's events once it ends: seq, t_us, source,
                                      level, kind, message, fields (JSON text), session

A reader takes both (the journal holds a live or crashed session's events), oldest first.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from astcom_client.events import Event

from .damage import Damage, short_error, warn_damaged
from .exceptions import StoreError

__all__ = ["EventJournal", "read_events"]

JOURNAL = "events.jsonl"
EVENT_SCHEMA = pa.schema([
    pa.field("seq", pa.int64()), pa.field("t_us", pa.int64(), metadata={"unit": "us"}),
    pa.field("source", pa.string()), pa.field("level", pa.string()),
    pa.field("kind", pa.string()), pa.field("message", pa.string()),
    pa.field("fields", pa.string(), metadata={"doc": "JSON object"}),
    pa.field("session", pa.string())])


class EventJournal:
    """Append one session's events to DIR/events.jsonl; `finish` turns them into Parquet."""

    def __init__(self, path: Path, session: str) -> None:
        self.path = Path(path)
        self.session = session
        self.count = 0

    def append(self, events: list[Event]) -> None:
        if not events:
            return
        lines = "".join(json.dumps({**e.as_dict(), "session": self.session}) + "\n"
                        for e in events)
        try:
            with (self.path / JOURNAL).open("a") as f:
                f.write(lines)
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise StoreError(f"cannot append to {self.path / JOURNAL}: {exc.strerror}") from None
        self.count += len(events)

    def finish(self) -> None:
        """Write this session's journalled events as events/<session>.parquet; drop them
        from the journal (other sessions' lines, from a crashed recorder, stay)."""
        journal = self.path / JOURNAL
        if not journal.exists():
            return
        docs, others = [], []
        for line in journal.read_bytes().split(b"\n"):
            if not line.strip():
                continue
            try:
                doc = json.loads(line.decode("utf-8"))
                if not isinstance(doc, dict):
                    raise ValueError("not an event")
            except ValueError:
                others.append(line)  # cut by a crash, or damaged: kept, never dropped
                continue
            if doc.get("session") == self.session:
                docs.append(doc)
            else:
                others.append(line)
        if docs:
            (self.path / "events").mkdir(exist_ok=True)
            table = pa.Table.from_pylist([{
                "seq": d["seq"], "t_us": d["t_us"], "source": d["source"], "level": d["level"],
                "kind": d["kind"], "message": d["message"], "fields": json.dumps(d["fields"]),
                "session": d["session"]} for d in docs], schema=EVENT_SCHEMA)
            final = self.path / "events" / f"{self.session}.parquet"
            tmp = final.with_suffix(".parquet.tmp")
            pq.write_table(table, tmp, compression="zstd")
            os.replace(tmp, final)
        if others:
            tmp = journal.with_suffix(".jsonl.tmp")
            tmp.write_bytes(b"".join(x + b"\n" for x in others))
            os.replace(tmp, journal)
        else:
            journal.unlink()


def read_events(path: Path) -> list[Event]:
    """Return every event of the store at `path`, ordered by mount time then sequence.

    Needs no sample file. A damaged events/<session>.parquet is skipped, and unreadable
    journal lines beyond the one a crash may cut are counted, each with a
    DamagedFileWarning naming the file.
    """
    out: list[Event] = []
    for f in sorted((Path(path) / "events").glob("*.parquet")):
        try:
            rows = pq.read_table(f).to_pylist()
            out += [Event(int(row["t_us"]), row["source"], row["level"], row["kind"],
                          row["message"], json.loads(row["fields"] or "{}"), int(row["seq"]))
                    for row in rows]
        except (OSError, pa.ArrowException, ValueError, KeyError, TypeError) as exc:
            warn_damaged(Damage(f, short_error(exc)), Path(path), "its events are skipped")
    journal = Path(path) / JOURNAL
    if journal.exists():
        lines = journal.read_bytes().split(b"\n")
        bad = 0
        for i, line in enumerate(lines):
            event = _event_of(line)
            if event is not None:
                out.append(event)
            elif line.strip() and i < len(lines) - 1:
                bad += 1  # an unterminated last line is one a crash cut: not damage
        if bad:
            warn_damaged(Damage(journal, f"{bad} unreadable line(s)"), Path(path),
                         "those lines are skipped")
    out.sort(key=lambda e: (e.t_us, e.source, e.seq))
    return out


def _event_of(line: bytes) -> Event | None:
    """Return the event of one journal line, or None when it is not one."""
    try:
        return Event.from_dict(json.loads(line.decode("utf-8")))
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
