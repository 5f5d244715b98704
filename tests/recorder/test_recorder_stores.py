"""The Parquet store, envelopes, exports and the parsing of store and time arguments."""

from __future__ import annotations

import csv

import numpy as np
import pyarrow.parquet as pq
import pytest
from recorder_helpers import START_US
from scipy.io import loadmat

from virtualstar.recorder import (
    ParquetStoreReader,
    ParquetStoreWriter,
    QueryError,
    SampleBlock,
    SignalInfo,
    StoreSpecError,
    envelope,
    parse_store_spec,
)
from virtualstar.recorder.export import mat_name, write_csv, write_mat
from virtualstar.recorder.samples import Gap
from virtualstar.recorder.timeparse import parse_time_bound

SIGNALS = [SignalInfo("axis.az.position", "rad", "float64"),
           SignalInfo("axis.az.current", "A", "float64"),
           SignalInfo("axis.az.error_arcsec", "arcsec", "float32"),  # the emulator's f32 wire type
           SignalInfo("counter", "", "int64")]
F32 = np.finfo(np.float32)


def _synthetic(n: int, period_us: int = 1000, seed: int = 1) -> SampleBlock:
    """Samples with full-precision random floats, extreme values and a drifting clock."""
    rng = np.random.default_rng(seed)
    t = START_US + np.arange(n, dtype=np.int64) * period_us + (np.arange(n) // 700)
    pos = np.cumsum(rng.normal(0, 1e-6, n)) + rng.random(n) * 1e-12
    cur = rng.normal(0, 1, n)
    cur[:4] = [np.finfo(float).tiny, -0.0, 1e308, 5e-324]
    err = rng.normal(0, 0.05, n).astype(np.float32)
    err[:4] = [F32.tiny, -0.0, F32.max, F32.smallest_subnormal]
    return SampleBlock(t, {"axis.az.position": pos, "axis.az.current": cur,
                           "axis.az.error_arcsec": err,
                           "counter": np.arange(n, dtype=np.int64) * 3 - 7})


def _write(path, block: SampleBlock, pieces: int = 7, **kw) -> ParquetStoreWriter:
    w = ParquetStoreWriter(path, **kw)
    w.begin(SIGNALS, source="test", rate_hz=1000.0)
    for part in np.array_split(np.arange(len(block)), pieces):
        w.write(block.slice(int(part[0]), int(part[-1]) + 1))
    w.close()
    return w


def test_parquet_store_round_trips_every_value_and_timestamp_bit_exactly(tmp_path):
    block = _synthetic(150_000)  # 2.5 min across 21:00:00: two hourly files
    w = _write(tmp_path / "s", block, row_group_rows=20_000)
    reader = ParquetStoreReader(tmp_path / "s")
    assert len(reader.sample_files) == 2 and w.rows_written == len(block)
    assert {f.name[:12] for f in reader.sample_files} == {"20260301T20Z", "20260301T21Z"}
    back = reader.window(block.t_us[0], block.t_us[-1] + 1)
    np.testing.assert_array_equal(back.t_us, block.t_us)
    for name, values in block.columns.items():
        assert back.columns[name].dtype == values.dtype
        assert back.columns[name].tobytes() == values.tobytes()  # bit-exact, -0.0 included
    assert reader.time_range() == (block.t_us[0], block.t_us[-1])
    assert reader.count() == len(block)
    assert [s.name for s in reader.signals()] == [s.name for s in SIGNALS]
    assert reader.signals()[0].unit == "rad"


def test_parquet_files_are_standard_and_use_the_compact_encodings(tmp_path):
    block = _synthetic(30_000)
    _write(tmp_path / "s", block)
    f = ParquetStoreReader(tmp_path / "s").sample_files[0]
    table = pq.read_table(f)  # any Parquet reader, no knowledge of ours
    np.testing.assert_array_equal(table.column("t_us").to_numpy(), block.t_us[:len(table)])
    col = pq.ParquetFile(f).metadata.row_group(0)
    encodings = {col.column(i).path_in_schema: col.column(i).encodings for i in range(col.num_columns)}
    assert "DELTA_BINARY_PACKED" in encodings["t_us"]
    assert "DELTA_BINARY_PACKED" in encodings["counter"]
    assert "BYTE_STREAM_SPLIT" in encodings["axis.az.position"]
    assert col.column(0).compression == "ZSTD"


def test_a_float32_signal_is_stored_as_float32_and_round_trips_bit_exactly(tmp_path):
    block = _synthetic(70_000)
    _write(tmp_path / "s", block, row_group_rows=30_000)
    reader = ParquetStoreReader(tmp_path / "s")
    name = "axis.az.error_arcsec"
    assert {s.name: s.dtype for s in reader.signals()}[name] == "float32"
    f = reader.sample_files[0]
    assert str(pq.read_schema(f).field(name).type) == "float"  # arrow float32, not a widened copy
    rg = pq.ParquetFile(f).metadata.row_group(0)
    col = next(rg.column(i) for i in range(rg.num_columns) if rg.column(i).path_in_schema == name)
    assert col.physical_type == "FLOAT"
    assert "BYTE_STREAM_SPLIT" in col.encodings
    back = reader.window(int(block.t_us[0]), int(block.t_us[-1]) + 1, [name])
    assert back.columns[name].dtype == np.float32
    assert back.columns[name].tobytes() == block.columns[name].tobytes()  # -0.0, subnormals
    a = int(block.t_us[0]) // 1_000_000 * 1_000_000
    env = reader.envelope(a, int(block.t_us[-1]) + 1, [name], buckets=7)  # from the 1-s overview
    expected = _envelope_by_masks(block.t_us, block.columns[name], a, env.bucket_us)
    assert env.mins[name].dtype == np.float32
    np.testing.assert_array_equal(env.mins[name], [e[2] for e in expected])
    np.testing.assert_array_equal(env.maxs[name], [e[3] for e in expected])


def test_window_query_returns_exactly_the_half_open_interval(tmp_path):
    block = _synthetic(20_000)
    _write(tmp_path / "s", block, row_group_rows=3000)
    reader = ParquetStoreReader(tmp_path / "s")
    a, b = int(block.t_us[1234]), int(block.t_us[5678])
    got = reader.window(a, b, ["counter"])
    np.testing.assert_array_equal(got.columns["counter"], block.columns["counter"][1234:5678])
    assert got.names == ["counter"]
    assert len(reader.window(START_US - 7_200_000_000, START_US - 3_600_000_000)) == 0
    with pytest.raises(QueryError, match="unknown signal.*holds"):
        reader.window(a, b, ["nope"])


def _envelope_by_masks(t, values, start, bucket):
    """A second, slow implementation: one boolean mask per bucket."""
    out = []
    k0, k1 = (t[0] - start) // bucket, (t[-1] - start) // bucket
    for k in range(k0, k1 + 1):
        m = (t >= start + k * bucket) & (t < start + (k + 1) * bucket)
        if m.any():
            out.append((start + k * bucket, int(m.sum()), values[m].min(), values[m].max()))
    return out


def test_envelope_from_the_stored_overview_matches_a_direct_computation(tmp_path):
    block = _synthetic(150_000)
    _write(tmp_path / "s", block, row_group_rows=9_999)
    reader = ParquetStoreReader(tmp_path / "s")
    a = int(block.t_us[0]) // 1_000_000 * 1_000_000
    b = int(block.t_us[-1]) + 1
    env = reader.envelope(a, b, ["axis.az.current"], buckets=30)  # 5-s buckets from the 1-s overview
    assert env.bucket_us == 5_000_000
    expected = _envelope_by_masks(block.t_us, block.columns["axis.az.current"], a, env.bucket_us)
    assert [(int(t), int(n)) for t, n in zip(env.t_us, env.n, strict=True)] == [e[:2] for e in expected]
    np.testing.assert_array_equal(env.mins["axis.az.current"], [e[2] for e in expected])
    np.testing.assert_array_equal(env.maxs["axis.az.current"], [e[3] for e in expected])
    a, b = int(block.t_us[100]), int(block.t_us[900])
    fine = reader.envelope(a, b, ["counter"], buckets=8)  # sub-second buckets: from the samples
    assert fine.bucket_us == -(-(b - a) // 8)
    expected = _envelope_by_masks(block.t_us[100:900], block.columns["counter"][100:900], a,
                                  fine.bucket_us)
    assert [(int(t), int(n), lo, hi) for t, n, lo, hi in zip(
        fine.t_us, fine.n, fine.mins["counter"], fine.maxs["counter"], strict=True)] == expected


def test_envelope_keeps_nan_out_of_min_and_max():
    t = np.arange(10, dtype=np.int64)
    v = np.array([1.0, np.nan, 3, 4, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan])
    env = envelope(t, {"x": v}, 5)
    assert env.mins["x"][0] == 1.0 and env.maxs["x"][0] == 4.0
    assert np.isnan(env.mins["x"][1])


def test_gaps_round_trip_through_the_gap_table(tmp_path):
    w = ParquetStoreWriter(tmp_path / "s")
    w.begin(SIGNALS)
    w.write(_synthetic(10))
    gaps = [Gap(START_US + 9000, START_US + 20000, 10, "dropped"),
            Gap(START_US + 30000, START_US + 90000, -1, "restart")]
    for g in gaps:
        w.write_gap(g)
    w.close()
    got = ParquetStoreReader(tmp_path / "s").gaps()
    assert [(g.after_t_us, g.before_t_us, g.lost_samples, g.reason) for g in got] == \
           [(g.after_t_us, g.before_t_us, g.lost_samples, g.reason) for g in gaps]
    assert all(g.session == w.session for g in got)


def test_csv_and_mat_exports_keep_values_and_times_exact(tmp_path):
    block = _synthetic(5000)
    rows = write_csv([block.slice(0, 2000), block.slice(2000, 5000)], block.names, tmp_path / "x.csv")
    assert rows == 5000
    with (tmp_path / "x.csv").open() as f:
        data = list(csv.DictReader(f))
    assert [int(r["t_us"]) for r in data] == block.t_us.tolist()
    assert [float(r["axis.az.current"]) for r in data] == block.columns["axis.az.current"].tolist()
    err = np.array([float(r["axis.az.error_arcsec"]) for r in data])  # the exact float32 values
    assert err.astype(np.float32).tobytes() == block.columns["axis.az.error_arcsec"].tobytes()
    np.testing.assert_array_equal(err, block.columns["axis.az.error_arcsec"])
    assert [int(r["counter"]) for r in data] == block.columns["counter"].tolist()
    write_mat(block, SIGNALS, tmp_path / "x.mat")
    mat = loadmat(tmp_path / "x.mat")
    assert mat["t_us"].dtype == np.int64
    np.testing.assert_array_equal(mat["t_us"].ravel(), block.t_us)
    np.testing.assert_array_equal(mat[mat_name("axis.az.position")].ravel(),
                                  block.columns["axis.az.position"])
    np.testing.assert_array_equal(mat["counter"].ravel(), block.columns["counter"])
    err_mat = mat[mat_name("axis.az.error_arcsec")].ravel()
    assert err_mat.dtype == np.float32  # MATLAB single
    assert err_mat.tobytes() == block.columns["axis.az.error_arcsec"].tobytes()
    assert [str(x[0]) for x in mat["names"].ravel()] == [s.name for s in SIGNALS]


def test_a_store_refuses_a_signal_recorded_before_with_another_type(tmp_path):
    _write(tmp_path / "s", _synthetic(100))
    w = ParquetStoreWriter(tmp_path / "s")
    with pytest.raises(OSError, match="counter.*int64.*float64"):
        w.begin([SignalInfo("counter", "", "float64")])
    w.close()


def test_reading_an_empty_or_missing_store_says_what_is_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ParquetStoreReader(tmp_path / "none")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="no sample files"):
        ParquetStoreReader(tmp_path / "empty")


@pytest.mark.parametrize(("text", "kind", "where"), [
    ("parquet:/data/night", "parquet", "/data/night"),
    ("night1", "parquet", "night1"),
    ("influx:http://127.0.0.1:8086/telescope", "influx", "telescope"),
])
def test_store_specs_name_the_store(text, kind, where):
    spec = parse_store_spec(text)
    assert spec.kind == kind
    assert (str(spec.path) if kind == "parquet" else spec.database) == where


@pytest.mark.parametrize("text", ["", "influx:http://127.0.0.1:8086", "influx:ftp://x/db",
                                  "mongo:x", "parquet:"])
def test_bad_store_specs_list_the_accepted_forms(text):
    with pytest.raises(StoreSpecError, match="expected|e.g."):
        parse_store_spec(text)


def test_time_bounds_accept_the_documented_forms():
    s, e = START_US, START_US + 3_600_000_000
    assert parse_time_bound("start", s, e) == s
    assert parse_time_bound("end", s, e) == e + 1
    assert parse_time_bound("+2", s, e) == s + 2_000_000
    assert parse_time_bound("-0.5", s, e) == e + 1 - 500_000
    assert parse_time_bound("2026-03-01T20:59:00Z", s, e) == START_US
    assert parse_time_bound(str(s + 7), s, e) == s + 7
    with pytest.raises(QueryError, match="--to 'soon'.*expected"):
        parse_time_bound("soon", s, e, option="--to")


def test_an_hour_met_again_gets_a_file_of_its_own_and_nothing_is_replaced(tmp_path):
    from virtualstar.recorder.parquet_store import HOUR_US, ParquetStoreReader, ParquetStoreWriter
    from virtualstar.recorder.samples import SampleBlock, SignalInfo

    hour = 493_000 * HOUR_US
    writer = ParquetStoreWriter(tmp_path / "s")
    writer.begin([SignalInfo("x", "", "float64")])
    for start in (hour, hour + HOUR_US, hour + 10_000_000):  # the clock goes back an hour
        t = start + np.arange(100, dtype=np.int64) * 1000
        writer.write(SampleBlock(t, {"x": np.arange(100.0)}))
    writer.close()
    assert ParquetStoreReader(tmp_path / "s").count() == 300
