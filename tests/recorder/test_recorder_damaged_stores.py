"""Damaged stores: each damaged file is named, the rest stays readable, nothing is deleted.

Damage is made the way it happens: a copy cut short (truncated Parquet hour), bytes
overwritten in the middle of a file (a bad sector, a careless hand), a recording.json cut
short, junk lines in the event journal. What was written is known exactly, so what must
still read back is known too.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from astcom_client.events import Event
from virtualstar.cli.main import app
from virtualstar.recorder.damage import DamagedFileWarning
from virtualstar.recorder.exceptions import StoreError
from virtualstar.recorder.parquet_journal import JOURNAL_SUFFIX
from virtualstar.recorder.parquet_store import HOUR_US, ParquetStoreReader, ParquetStoreWriter
from virtualstar.recorder.samples import SampleBlock, SignalInfo

runner = CliRunner()
FIRST_US = 1_772_400_600_000_000  # 2026-03-01T21:30:00Z: 2 h over three hourly files
RATE_HZ = 50
SIGNALS = [SignalInfo("axis.az.position", "rad", "float64"),
           SignalInfo("axis.az.current", "A", "float32"),
           SignalInfo("axis.az.error_arcsec", "arcsec", "float32")]


def _block(t_us: np.ndarray) -> SampleBlock:
    s = (t_us - FIRST_US) / 1e6
    rng = np.random.default_rng(int(t_us[0]) % 2**32)
    return SampleBlock(t_us, {
        "axis.az.position": 0.3 + 7.29e-5 * s,
        "axis.az.current": (0.2 + 0.01 * rng.standard_normal(len(s))).astype(np.float32),
        "axis.az.error_arcsec": (0.01 * rng.standard_normal(len(s))).astype(np.float32)})


def _write_store(path: Path, hours: float = 2.0, *, row_group_rows: int = 30_000) -> np.ndarray:
    """Record `hours` at RATE_HZ into a fresh store; return every t_us written."""
    t = FIRST_US + np.arange(int(hours * 3600 * RATE_HZ), dtype=np.int64) * (1_000_000 // RATE_HZ)
    with ParquetStoreWriter(path, row_group_rows=row_group_rows) as w:
        w.begin(SIGNALS, source="test", rate_hz=RATE_HZ)
        for i in range(0, len(t), 10_000):
            w.write(_block(t[i:i + 10_000]))
        w.write_events([Event(int(t[0]), "recorder", "info", "session", "recording starts")])
    return t


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> tuple[Path, np.ndarray]:
    path = tmp_path_factory.mktemp("pristine") / "store"
    return path, _write_store(path)


@pytest.fixture
def store(pristine, tmp_path) -> tuple[Path, np.ndarray]:
    path, t = pristine
    copy = tmp_path / "store"
    shutil.copytree(path, copy)
    return copy, t


def _hour_file(store: Path, hour_label: str) -> Path:
    return next((store / "samples").glob(f"{hour_label}-*.parquet"))


def _no_traceback(result) -> None:
    assert "Traceback" not in result.output and result.exception is None \
        or isinstance(result.exception, SystemExit), result.output


# -- a truncated Parquet hour -------------------------------------------------------------

def test_a_truncated_hour_is_named_skipped_and_reported_as_a_gap(store):
    path, t = store
    middle = _hour_file(path, "20260301T22Z")
    size = middle.stat().st_size
    os.truncate(middle, size // 2)  # a copy cut short: the footer is gone
    with pytest.warns(DamagedFileWarning, match=middle.name):
        reader = ParquetStoreReader(path)
    block = reader.window(int(t[0]), int(t[-1]) + 1)
    kept = (t // HOUR_US) != middle_hour(middle)
    assert np.array_equal(block.t_us, t[kept])  # every other sample, exactly
    damaged = [g for g in reader.gaps() if g.reason.startswith("damaged")]
    assert len(damaged) == 1 and middle.name in damaged[0].reason
    assert (damaged[0].after_t_us, damaged[0].before_t_us) == (
        middle_hour(middle) * HOUR_US, (middle_hour(middle) + 1) * HOUR_US)
    assert middle.stat().st_size == size // 2  # reading never changes the store


def middle_hour(f: Path) -> int:
    from virtualstar.recorder.parquet_journal import hour_of

    hour = hour_of(f)
    assert hour is not None
    return hour


@pytest.mark.parametrize("args", [
    ["info"], ["info", "--json"], ["query", "--json"], ["query", "--decimate", "100", "--json"],
    ["query", "--csv"], ["anomalies", "--json"], ["export", "--csv", "{tmp}/out.csv"],
    ["plot", "-o", "{tmp}/figs"],
])
def test_vs_data_reads_around_a_truncated_hour_without_a_traceback(store, tmp_path, args):
    path, t = store
    middle = _hour_file(path, "20260301T22Z")
    os.truncate(middle, middle.stat().st_size - 1000)
    result = runner.invoke(app, ["data", args[0], str(path),
                                 *[a.format(tmp=tmp_path) for a in args[1:]]])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    assert f"samples/{middle.name} is damaged" in result.stderr
    if args[:2] == ["query", "--json"]:
        doc = json.loads(result.stdout)
        assert len(doc["t_us"]) == int(np.sum(t // HOUR_US != middle_hour(middle)))
    if args == ["info", "--json"]:
        doc = json.loads(result.stdout)
        assert any(g["reason"].startswith("damaged") for g in doc["gaps"])


def test_a_row_group_that_does_not_decode_costs_only_that_row_group(store):
    path, t = store
    first = _hour_file(path, "20260301T21Z")
    meta = pq.read_metadata(first)
    assert meta.num_row_groups >= 2
    col = meta.row_group(1).column(1)  # axis.az.position of the second row group
    start = col.data_page_offset
    with open(first, "r+b") as f:  # its data page overwritten: the footer still reads
        f.seek(start + 8)
        f.write(os.urandom(2000))
    lo, hi = meta.row_group(1).column(0).statistics.min, meta.row_group(1).column(0).statistics.max
    with pytest.warns(DamagedFileWarning, match="row group 1"):
        block = ParquetStoreReader(path).window(int(t[0]), int(t[-1]) + 1)
    lost = (t >= lo) & (t <= hi)
    assert np.array_equal(block.t_us, t[~lost])
    # vs data recover keeps the readable row groups, sets the file aside, records the gap
    result = runner.invoke(app, ["data", "recover", str(path), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert [d["file"] for d in doc["damaged"]] == [first.name]
    aside = first.with_name(first.name + ".damaged")
    assert aside.exists() and first.exists()
    with _no_damage_warnings():
        again = ParquetStoreReader(path)
        assert np.array_equal(again.window(int(t[0]), int(t[-1]) + 1).t_us, t[~lost])
        gap = [g for g in again.gaps() if g.reason.startswith("damaged")]
    assert [(g.after_t_us, g.before_t_us) for g in gap] == [(lo, hi)]


def test_recover_sets_a_truncated_hour_aside_with_its_overview(store):
    path, t = store
    middle = _hour_file(path, "20260301T22Z")
    original = middle.read_bytes()
    middle.write_bytes(original[: len(original) // 3])
    result = runner.invoke(app, ["data", "recover", str(path)])
    _no_traceback(result)
    assert result.exit_code == 0 and "DAMAGED " + middle.name in result.stdout
    aside = middle.with_name(middle.name + ".damaged")
    assert aside.read_bytes() == original[: len(original) // 3]  # kept, byte for byte
    assert not middle.exists()
    assert (path / "overview" / (middle.name + ".orphaned")).exists()
    with _no_damage_warnings():
        reader = ParquetStoreReader(path)
        block = reader.window(int(t[0]), int(t[-1]) + 1)
        env = reader.envelope(int(t[0]), int(t[-1]) + 1, buckets=120)
        assert np.array_equal(block.t_us, t[(t // HOUR_US) != middle_hour(middle)])
        assert env.n.sum() == len(block)  # the overview agrees with the samples
        assert any(middle.name in g.reason for g in reader.gaps())


# -- a journal with random bytes inside ----------------------------------------------------

def _crashed_store(path: Path, batches: int = 20, rows: int = 1000) -> tuple[Path, np.ndarray,
                                                                               list[int]]:
    """A store whose recorder 'died' with its hour in a journal of `batches` batches; return
    the journal, every t_us written, and the byte offset where each batch ends."""
    t = FIRST_US + 600_000_000 + np.arange(batches * rows, dtype=np.int64) * 20_000
    w = ParquetStoreWriter(path, flush_interval_s=0.0)
    w.begin(SIGNALS, source="test", rate_hz=RATE_HZ)
    for i in range(batches):
        w.write(_block(t[i * rows:(i + 1) * rows]))
        w.flush()
    journal = next((path / "samples").glob("*" + JOURNAL_SUFFIX))
    w._journal._file.close()  # the writer 'dies': no end-of-stream, no Parquet, lock freed
    w._lock.release()
    w._thread.shutdown()
    ends = []
    with pa.OSFile(str(journal)) as source:  # pyarrow's own reading: where each batch ends
        reader = pa.ipc.open_stream(source)
        for _ in range(batches):
            reader.read_next_batch()
            ends.append(source.tell())
    return journal, t, ends


def test_random_bytes_in_a_journal_keep_every_batch_before_them_and_the_file(tmp_path):
    path = tmp_path / "store"
    journal, t, ends = _crashed_store(path)
    at = ends[11] + 8  # the 13th batch's header, after its length (IPC has no checksums:
    # values overwritten inside a batch's data are found only when LZ4 refuses them)
    damaged = bytearray(journal.read_bytes())
    damaged[at:at + 300] = np.random.default_rng(1).integers(0, 256, 300, np.uint8).tobytes()
    journal.write_bytes(bytes(damaged))
    result = runner.invoke(app, ["data", "recover", str(path), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["samples"] == 12 * 1000  # the twelve batches before the damage
    assert [d["file"] for d in doc["damaged"]] == [journal.name]
    aside = journal.with_name(journal.name + ".damaged")
    assert aside.read_bytes() == bytes(damaged)  # the evidence, untouched
    reader = ParquetStoreReader(path)
    assert np.array_equal(reader.window(int(t[0]), int(t[-1]) + 1).t_us, t[:12_000])
    reasons = [g.reason for g in reader.gaps()]
    assert any(r.startswith("damaged") and journal.name in r for r in reasons)
    assert "recorder died" in reasons


def test_random_bytes_over_a_journals_schema_keep_the_file_aside(tmp_path):
    path = tmp_path / "store"
    journal, _, _ = _crashed_store(path, batches=3)
    damaged = bytearray(journal.read_bytes())
    damaged[20:120] = bytes(range(100))
    journal.write_bytes(bytes(damaged))
    result = runner.invoke(app, ["data", "recover", str(path)])
    _no_traceback(result)
    assert result.exit_code == 0 and "DAMAGED" in result.stdout
    assert journal.with_name(journal.name + ".damaged").read_bytes() == bytes(damaged)


def test_a_journal_torn_by_a_crash_is_not_called_damaged(tmp_path):
    path = tmp_path / "store"
    journal, t, ends = _crashed_store(path, batches=5)
    os.truncate(journal, ends[3] + 100)  # the writer died while writing the fifth batch
    result = runner.invoke(app, ["data", "recover", str(path), "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["samples"] == 4000 and doc["damaged"] == []
    assert not list((path / "samples").glob("*.damaged")) and not journal.exists()


# -- recording.json, events, gaps ----------------------------------------------------------

def test_a_truncated_recording_json_is_named_and_the_samples_still_read(store):
    path, t = store
    meta = path / "recording.json"
    meta.write_bytes(meta.read_bytes()[:40])
    result = runner.invoke(app, ["data", "info", str(path), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    assert "recording.json is damaged: not valid JSON (cut short?)" in result.stderr
    doc = json.loads(result.stdout)
    assert doc["samples"] == len(t)
    assert [s["name"] for s in doc["signals"]] == [s.name for s in SIGNALS]
    assert [s["dtype"] for s in doc["signals"]] == [s.dtype for s in SIGNALS]
    with pytest.raises(StoreError, match="recording.json is damaged"):
        ParquetStoreWriter(path).begin(SIGNALS)
    assert ParquetStoreWriter(path)._lock.try_acquire()  # the refused writer let go


@pytest.mark.parametrize("junk", [b"\xff\xfe not json at all\n", b'{"t_us": "soon"}\n',
                                  b"[1, 2, 3]\n", b"\x00" * 50 + b"\n"])
def test_junk_lines_in_the_event_journal_are_counted_and_the_rest_shown(tmp_path, junk):
    path = tmp_path / "store"
    journal = path / "events.jsonl"
    path.mkdir()
    good = [Event(FIRST_US + i, "vss", "info", "phase", f"phase {i}") for i in range(3)]
    lines = [json.dumps({**e.as_dict(), "session": "s"}).encode() + b"\n" for e in good]
    journal.write_bytes(lines[0] + junk + lines[1] + lines[2])
    # no sample file at all: vs log reads the events all the same
    result = runner.invoke(app, ["log", str(path), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    assert [d["message"] for d in json.loads(result.stdout)] == ["phase 0", "phase 1", "phase 2"]
    assert "events.jsonl is damaged (1 unreadable line(s))" in result.stderr


def test_vs_log_reads_a_store_whose_samples_are_all_damaged(store):
    path, _ = store
    for f in (path / "samples").glob("*.parquet"):
        os.truncate(f, 10)
    info = runner.invoke(app, ["data", "info", str(path)])
    _no_traceback(info)
    assert info.exit_code == 2 and "no readable sample files" in info.stderr
    result = runner.invoke(app, ["log", str(path), "--json"])
    assert result.exit_code == 0, result.output
    assert [d["message"] for d in json.loads(result.stdout)] == ["recording starts"]


def test_a_damaged_event_file_is_named_and_skipped(store):
    path, _ = store
    events = next((path / "events").glob("*.parquet"))
    events.write_bytes(b"PAR1" + b"\x00" * 64)
    result = runner.invoke(app, ["log", str(path), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0 and json.loads(result.stdout) == []
    assert f"events/{events.name} is damaged" in result.stderr


def test_unreadable_rows_of_gaps_csv_are_named_and_skipped(store):
    path, _ = store
    with (path / "gaps.csv").open("ab") as f:
        f.write(b"1,2,3,dropped,s\nnot,a,number,x,y\n\xff\xfe\n")
    result = runner.invoke(app, ["data", "info", str(path), "--json"])
    _no_traceback(result)
    assert result.exit_code == 0, result.output
    assert [g["lost_samples"] for g in json.loads(result.stdout)["gaps"]] == [3]
    assert "gaps.csv is damaged (2 unreadable row(s))" in result.stderr


class _no_damage_warnings:
    """Fail if a DamagedFileWarning is raised inside (the store is whole again)."""

    def __enter__(self):
        import warnings

        self._ctx = warnings.catch_warnings()
        self._ctx.__enter__()
        warnings.simplefilter("error", DamagedFileWarning)

    def __exit__(self, *exc):
        self._ctx.__exit__(*exc)
