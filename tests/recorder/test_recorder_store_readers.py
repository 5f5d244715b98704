"""The Parquet store is read, bit for bit, by the tools the issue names: pandas, polars, DuckDB.

Each reader is used the way docs/recorder.md shows a user, with no code of ours in between.
MATLAB's parquetread cannot run here; it reads the same standard files (and `vs data export
--mat` writes .mat files, tested in test_recorder_stores.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_recorder_stores import SIGNALS, _synthetic, _write

pd = pytest.importorskip("pandas", reason="pandas is a test extra: pip install -e '.[test]'")
pl = pytest.importorskip("polars", reason="polars is a test extra: pip install -e '.[test]'")
duckdb = pytest.importorskip("duckdb", reason="duckdb is a test extra: pip install -e '.[test]'")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    block = _synthetic(150_000)  # crosses an hour boundary: two sample files
    path = tmp_path_factory.mktemp("readers") / "night"
    _write(path, block, row_group_rows=20_000)
    return path, block


def _assert_same(t_us, columns, block) -> None:
    order = np.argsort(t_us, kind="stable")
    np.testing.assert_array_equal(np.asarray(t_us)[order], block.t_us)
    for s in SIGNALS:
        got = np.asarray(columns[s.name])[order]
        assert got.dtype == block.columns[s.name].dtype, s.name
        assert got.tobytes() == block.columns[s.name].tobytes(), s.name  # bit-exact


def test_pandas_reads_the_samples_folder(store):
    path, block = store
    df = pd.read_parquet(path / "samples")
    _assert_same(df["t_us"].to_numpy(), {s.name: df[s.name].to_numpy() for s in SIGNALS}, block)


def test_polars_reads_the_hourly_files_by_glob(store):
    path, block = store
    df = pl.read_parquet(str(path / "samples" / "*.parquet"))
    _assert_same(df["t_us"].to_numpy(), {s.name: df[s.name].to_numpy() for s in SIGNALS}, block)


def test_duckdb_queries_a_window_with_sql(store):
    path, block = store
    lo, hi = int(block.t_us[1000]), int(block.t_us[3000])
    rows = duckdb.sql(
        f"SELECT t_us, \"axis.az.error_arcsec\" AS err FROM '{path}/samples/*.parquet' "
        f"WHERE t_us >= {lo} AND t_us < {hi} ORDER BY t_us").fetchnumpy()
    np.testing.assert_array_equal(rows["t_us"], block.t_us[1000:3000])
    assert rows["err"].dtype == np.float32
    assert rows["err"].tobytes() == block.columns["axis.az.error_arcsec"][1000:3000].tobytes()
