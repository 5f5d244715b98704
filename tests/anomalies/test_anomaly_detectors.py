"""The pieces of `vs data anomalies` on synthetic signals whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from virtualstar.anomalies import DetectorConfig
from virtualstar.anomalies.current_model import fit_current_model
from virtualstar.anomalies.detectors import run_detectors
from virtualstar.anomalies.robust import runs
from virtualstar.anomalies.segments import SEGMENT_SAMPLES, reduce_blocks
from virtualstar.cli.main import app
from virtualstar.recorder.parquet_store import ParquetStoreWriter
from virtualstar.recorder.samples import SampleBlock, SignalInfo

T0_US = 1_772_395_200_000_000
RATE_HZ = 1000.0
AXES = {"az": {"position": "axis.az.position", "current": "axis.az.current",
               "error_arcsec": "axis.az.error_arcsec"}}


def _block(seconds: float, *, error=None, current=None, t_us=None) -> SampleBlock:
    t = T0_US + np.arange(round(seconds * RATE_HZ), dtype=np.int64) * 1000 if t_us is None \
        else t_us
    n = len(t)
    ts = (t - T0_US) * 1e-6
    pos = 1e-4 * ts  # a steady slow drive
    cur = np.full(n, 0.25) if current is None else current(ts)
    err = np.zeros(n) if error is None else error(ts)
    return SampleBlock(t, {"axis.az.position": pos, "axis.az.current": cur,
                           "axis.az.error_arcsec": err})


def test_segments_put_a_tone_in_its_octave_band_and_fit_the_velocity():
    seg = reduce_blocks(iter([_block(10.0, error=lambda t: np.sin(2 * np.pi * 40.0 * t))]),
                        AXES, RATE_HZ)
    assert len(seg) == 10_000 // SEGMENT_SAMPLES
    bands = seg.features["az.error_band_power"]
    loudest = int(np.argmax(np.median(bands, axis=0)))
    assert seg.band_edges_hz[loudest] <= 40.0 < seg.band_edges_hz[loudest + 1]
    assert seg.features["az.velocity_rad_s"] == pytest.approx(1e-4, rel=1e-9)


def test_segments_survive_any_block_boundaries():
    whole = _block(7.3)
    cut = [whole.slice(a, b) for a, b in ((0, 1000), (1000, 1001), (1001, 5000), (5000, 7300))]
    one = reduce_blocks(iter([whole]), AXES, RATE_HZ)
    many = reduce_blocks(iter(cut), AXES, RATE_HZ)
    assert np.array_equal(one.t_first_us, many.t_first_us)
    for k, v in one.features.items():
        assert np.allclose(v, many.features[k]), k


def test_the_current_model_recovers_a_known_motor_and_its_cogging_period():
    rng = np.random.default_rng(3)
    n = 20_000
    p = np.linspace(-1.0, 2.0, n)  # three radians of travel: the cogging period is sharp
    v = 2e-4 * (1 + np.sin(np.linspace(0, 40, n)))
    a = np.gradient(v)
    truth = 0.02 + 30.0 * v + 0.2 * np.tanh(v / 1e-4) + 0.03 * np.sin(50.0 * p + 0.4)
    i = truth + rng.normal(0, 1e-3, n)
    model = fit_current_model(p, v, a, i, np.arange(n) < n // 2, gravity=False)
    assert model.cogging_periods == pytest.approx(50.0, abs=0.2)
    # the ridge that keeps the friction terms apart costs a little: well below the cogging
    assert np.std(i - model.predict(p, v, a)) < 5e-3


def test_the_clock_detector_finds_the_rate_change_at_its_time():
    n = 3600 * 1000
    step_us = np.full(n - 1, 1000.0)
    change = 2400 * 1000
    step_us[change:] *= 1 + 3e-6  # the clock runs 3 ppm fast from 40 minutes on
    t = T0_US + np.r_[0, np.cumsum(step_us)].round().astype(np.int64)
    seg = reduce_blocks(iter([_block(0, t_us=t)]), AXES, RATE_HZ)
    ref = seg.t_last_us < T0_US + 900_000_000
    found, _ = run_detectors(seg, ref, AXES, DetectorConfig())
    clock = [a for a in found if a.kind == "clock"]
    assert len(clock) == 1 and found == clock
    assert abs(clock[0].start_us - (T0_US + change * 1000)) <= 60_000_000
    ppm = float(clock[0].detail.split("rate ")[1].split(" ppm")[0])
    assert ppm == pytest.approx(3.0, abs=0.05)


def test_the_spike_detector_finds_a_one_sample_jump():
    def error(ts):
        e = 0.02 * np.sin(2 * np.pi * 0.3 * ts)
        e[round(1500.5 * RATE_HZ)] += 1.0
        return e

    seg = reduce_blocks(iter([_block(1800.0, error=error)]), AXES, RATE_HZ)
    ref = seg.t_last_us < T0_US + 900_000_000
    found, _ = run_detectors(seg, ref, AXES, DetectorConfig())
    assert [a.kind for a in found] == ["spike"]
    assert found[0].start_us <= T0_US + 1_500_500_000 < found[0].end_us


def test_runs_join_flags_closer_than_the_bridge():
    flags = np.array([0, 1, 1, 0, 0, 1, 0, 0, 0, 0, 1], dtype=bool)
    assert runs(flags, bridge=1) == [(1, 2), (5, 5), (10, 10)]
    assert runs(flags, bridge=2) == [(1, 5), (10, 10)]


@pytest.fixture
def small_store(tmp_path):
    store = tmp_path / "store"
    with ParquetStoreWriter(store) as w:
        w.begin([SignalInfo("axis.az.position", "rad"), SignalInfo("axis.az.current", "A"),
                 SignalInfo("axis.az.error_arcsec", "arcsec")], rate_hz=RATE_HZ)
        w.write(_block(1200.0, current=lambda t: 0.25 + 0.001 * np.sin(t)))
    return store


@pytest.mark.parametrize(("args", "message"), [
    (["--threshold", "0"], "--threshold"),
    (["--cogging-periods", "-1"], "--cogging-periods"),
    (["--reference-from", "+100", "--reference-to", "+50"], "empty reference"),
    (["--reference-from", "+1000"], "reference stretch"),
    (["--from", "yesterday"], "--from"),
])
def test_vs_data_anomalies_refuses_bad_arguments_with_exit_2(small_store, args, message):
    result = CliRunner().invoke(app, ["data", "anomalies", str(small_store), *args])
    assert result.exit_code == 2
    assert message in result.stderr


def test_vs_data_anomalies_refuses_a_store_without_axis_signals(tmp_path):
    store = tmp_path / "store"
    with ParquetStoreWriter(store) as w:
        w.begin([SignalInfo("wave.sine", "")], rate_hz=RATE_HZ)
        w.write(SampleBlock(T0_US + np.arange(5000, dtype=np.int64) * 1000,
                            {"wave.sine": np.sin(np.arange(5000) / 100)}))
    result = CliRunner().invoke(app, ["data", "anomalies", str(store)])
    assert result.exit_code == 2
    assert "axis.<az|el>.position" in result.stderr


def test_vs_data_anomalies_on_a_steady_store_prints_no_anomaly(small_store):
    result = CliRunner().invoke(app, ["data", "anomalies", str(small_store), "--json"])
    assert result.exit_code == 0, result.output
    assert result.stdout.strip() == "[]"
