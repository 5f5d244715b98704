"""Synthetic nights written as a recorder store, for the anomaly tests with a known answer."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from virtualstar.recorder.parquet_store import ParquetStoreReader, ParquetStoreWriter
from virtualstar.recorder.samples import SampleBlock, SignalInfo


def write_store(path: Path, t0_us: int, ts_s: np.ndarray, signals: dict[str, np.ndarray],
                rate_hz: float) -> ParquetStoreReader:
    """Write `signals` sampled at `ts_s` seconds after `t0_us` as a store; its reader."""
    t_us = t0_us + np.round(ts_s * 1e6).astype(np.int64)
    with ParquetStoreWriter(path) as w:
        w.begin([SignalInfo(n, "") for n in signals], rate_hz=rate_hz)
        w.write(SampleBlock(t_us, signals))
    return ParquetStoreReader(path)


def settled_track_scores(report, trace: str, t0_us: int, from_s: float, cycle_s: float,
                         slew_s: float) -> np.ndarray:
    """The scores of `trace`'s windows wholly inside the tracks of a slew-then-track cycle,
    from `from_s` on (and after the 900-s reference), 20 s after each slew (settled)."""
    found = next(t for t in report.traces if t.name == trace)
    ts = (found.t_us - t0_us) * 1e-6
    phase = np.mod(ts, cycle_s)
    rows = (ts >= max(from_s, 900.0)) & (phase > slew_s + 20.0) & (phase < cycle_s - 10.0)
    assert rows.sum() > 20
    return found.score[rows]
