"""The sine experiment at reduced length: the signals it records are the ones commanded."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pyarrow.parquet as pq
import pytest

from virtualstar.recorder import ParquetStoreReader
from virtualstar.recorder.experiment import SineExperiment, commanded_position, run_sine_experiment

ARCSEC_PER_RAD = 180 / math.pi * 3600
START_US = 1_772_398_680_000_000  # 2026-03-01T20:58:00Z: the run crosses an hour boundary


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    exp = SineExperiment(hours=3 / 60, period_s=60.0, start_us=START_US)
    out = tmp_path_factory.mktemp("sine")
    return exp, asyncio.run(run_sine_experiment(exp, out))


def test_sine_experiment_records_every_sample_at_1_khz_without_loss(run):
    exp, result = run
    reader = ParquetStoreReader(result.store)
    block = reader.window(0, 2**62)
    assert result.recording.lost == 0 and result.recording.gaps == []
    assert len(block) == result.recording.samples
    dt = np.diff(block.t_us)
    # 1 kHz of mount time; the mount clock drifts 2 ppm, i.e. 2 µs per 1-s packet
    assert dt.min() >= 998 and dt.max() <= 1002
    assert len(block) == round((block.t_us[-1] - block.t_us[0]) / 1000) + 1
    t0 = result.trajectory_t0_us
    assert block.t_us[0] <= t0 and block.t_us[-1] >= t0 + exp.duration_us
    assert len(reader.sample_files) == 2  # hourly partitions
    assert block.names == exp.names


def test_sine_experiment_position_follows_the_commanded_drifting_sine(run):
    exp, result = run
    block = ParquetStoreReader(result.store).window(0, 2**62)
    t0 = result.trajectory_t0_us
    cmd, _ = commanded_position(exp, block.t_us, t0)
    pos = block.columns["axis.az.position"]
    moving = (block.t_us >= t0) & (block.t_us <= t0 + exp.duration_us)
    off_arcsec = (cmd - pos)[moving] * ARCSEC_PER_RAD
    assert np.abs(off_arcsec).max() < 0.5
    # it really moved: 3 min at 0.0095 rad/min, speed v(1 - cos ωt) averaging v
    travel = pos[-1] - pos[0]
    assert travel == pytest.approx(exp.v_rad_s * exp.duration_us / 1e6, rel=0.01)
    # the recorded tracking error is the same difference, seen by the controller
    err = block.columns["axis.az.error_arcsec"][moving]
    assert np.abs(err - off_arcsec).max() < 0.01
    current = block.columns["axis.az.current"]
    assert np.isfinite(current).all() and np.abs(current).max() < 10.0  # below the limit


def test_sine_experiment_stores_each_signal_in_the_type_the_emulator_streams(run):
    from mount_emulator import layout

    exp, result = run
    wire = {s.name: s.type for s in layout.STATE_SLOTS}
    # position in rad stays f64; motor current and the arcsec error are the MCU's f32
    assert [wire[n] for n in exp.names] == ["f64", "f32", "f32"]
    reader = ParquetStoreReader(result.store)
    assert [s.dtype for s in reader.signals()] == ["float64", "float32", "float32"]
    block = reader.window(0, 2**62)
    assert [block.columns[n].dtype for n in exp.names] == [np.float64, np.float32, np.float32]
    schema = pq.read_schema(reader.sample_files[0])
    assert [str(schema.field(n).type) for n in exp.names] == ["double", "float", "float"]


def test_sine_experiment_writes_both_figures(run):
    _, result = run
    names = sorted(p.name for p in result.plots)
    assert names == ["fig6_overview.png", "fig7_first_2s.png"]
    for p in result.plots:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


@pytest.mark.parametrize(("kw", "match"), [({"axis": "ra"}, "az or el"), ({"hours": 0}, "hours"),
                                           ({"record_hz": 20_000}, "10000"),
                                           ({"axis": "el", "hours": 12}, "elevation")])
def test_sine_experiment_refuses_impossible_runs(kw, match):
    with pytest.raises(ValueError, match=match):
        SineExperiment(**kw)
