"""The pieces of `vs data anomalies` on synthetic signals whose answer is known."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from virtualstar.anomalies import detect_anomalies
from virtualstar.anomalies.current_model import fit_current_model
from virtualstar.anomalies.reference import ReferenceRefused
from virtualstar.anomalies.segments import SEGMENT_SAMPLES, reduce_blocks
from virtualstar.anomalies.windows import WindowCutter, class_window_starts
from virtualstar.cli.main import app
from virtualstar.recorder.parquet_store import ParquetStoreReader, ParquetStoreWriter
from virtualstar.recorder.samples import SampleBlock, SignalInfo

T0_US = 1_772_395_200_000_000
RATE_HZ = 1000.0
AXES = {"az": {"position": "axis.az.position", "current": "axis.az.current",
               "error_arcsec": "axis.az.error_arcsec"}}
DEG = math.pi / 180


def _block(seconds: float, *, error=None, current=None, position=None, t_us=None
           ) -> SampleBlock:
    t = T0_US + np.arange(round(seconds * RATE_HZ), dtype=np.int64) * 1000 if t_us is None \
        else t_us
    n = len(t)
    ts = (t - T0_US) * 1e-6
    pos = 1e-4 * ts if position is None else position(ts)  # a steady slow drive
    cur = np.full(n, 0.25) if current is None else current(ts)
    err = np.zeros(n) if error is None else error(ts)
    return SampleBlock(t, {"axis.az.position": pos, "axis.az.current": cur,
                           "axis.az.error_arcsec": err})


def _store(path, block: SampleBlock, names=("axis.az.position", "axis.az.current",
                                             "axis.az.error_arcsec")):
    with ParquetStoreWriter(path) as w:
        w.begin([SignalInfo(n, "") for n in names], rate_hz=RATE_HZ)
        w.write(SampleBlock(block.t_us, {n: block.columns[n] for n in names}))
    return path


def _detect(path, **kwargs):
    reader = ParquetStoreReader(path)
    a, b = reader.time_range()
    return detect_anomalies(reader, a, b + 1, **kwargs)


def test_segments_put_a_tone_in_its_octave_band_and_fit_rate_and_acceleration():
    seg = reduce_blocks(iter([_block(10.0, error=lambda t: np.sin(2 * np.pi * 40.0 * t),
                                     position=lambda t: 1e-4 * t + 0.5 * 3e-3 * t * t)]),
                        AXES, RATE_HZ)
    assert len(seg) == 10_000 // SEGMENT_SAMPLES
    bands = seg.features["az.error_band_power"]
    loudest = int(np.argmax(np.median(bands, axis=0)))
    assert seg.band_edges_hz[loudest] <= 40.0 < seg.band_edges_hz[loudest + 1]
    t_mid = (seg.t_mid_us - T0_US) * 1e-6
    assert seg.features["az.velocity_rad_s"] == pytest.approx(1e-4 + 3e-3 * t_mid, rel=1e-6)
    assert seg.features["az.acceleration_rad_s2"] == pytest.approx(3e-3, rel=1e-6)


def test_segments_survive_any_block_boundaries():
    whole = _block(7.3)
    cut = [whole.slice(a, b) for a, b in ((0, 1000), (1000, 1001), (1001, 5000), (5000, 7300))]
    one = reduce_blocks(iter([whole]), AXES, RATE_HZ)
    many = reduce_blocks(iter(cut), AXES, RATE_HZ)
    assert np.array_equal(one.t_first_us, many.t_first_us)
    for k, v in one.features.items():
        assert np.allclose(v, many.features[k], equal_nan=True), k


def test_the_current_model_recovers_a_known_motor_its_friction_knee_and_cogging():
    rng = np.random.default_rng(3)
    n = 8_000
    p = np.linspace(-1.0, 2.0, n)  # three radians of travel
    v = 2e-4 * np.sin(np.linspace(0, 40, n)) + 5e-5  # through the knee, both ways
    a = np.gradient(v, 0.1)
    truth = 0.02 + 3.0 * v + 0.2 * np.clip(v / 1e-4, -1, 1) + 0.03 * np.sin(50.0 * p + 0.4)
    i = truth + rng.normal(0, 1e-3, n)
    model = fit_current_model(p, v, a, i, np.arange(n) < n // 2, gravity=False)
    assert model.cogging_periods == 50
    assert model.friction.shape == "clip"
    assert model.friction.knee_rad_s == pytest.approx(1e-4, rel=0.15)
    # fitted on the first half: the second half (other positions) is explained as well
    assert np.std((i - model.predict(p, v, a))[n // 2:]) < 2e-3


def test_class_windows_never_mix_classes_and_come_out_the_same_in_any_chunks():
    rng = np.random.default_rng(7)
    cls = np.repeat(rng.integers(-1, 4, 60), rng.integers(1, 30, 60))
    starts = class_window_starts(cls, 8)
    ends = np.r_[starts[1:], len(cls)]
    assert all(len(set(cls[a:b])) == 1 and b - a <= 8 for a, b in zip(starts, ends, strict=True))
    cutter, seen, at = WindowCutter(8), [], 0
    for size in rng.integers(1, 40, 100):
        chunk = cls[at:at + size]
        at += len(chunk)
        arrays, st, closed = cutter.push({"cls": chunk, "i": np.arange(at - len(chunk), at)},
                                         final=at >= len(cls))
        seen += [int(arrays["i"][k]) for k in st[:closed]]
        if at >= len(cls):
            break
    assert seen == starts.tolist()


def test_the_clock_detector_finds_a_rate_change_and_ignores_utc_sync_steps(tmp_path):
    n = 2100 * 1000
    step_us = np.full(n - 1, 1000.0 * (1 + 2e-6))  # a crystal 2 ppm fast ...
    sync = np.arange(11_000, n - 1, 11_000)  # ... set back to UTC every 11 s (TimeS)
    step_us[sync] -= 22.0
    change = 1500 * 1000
    step_us[change:] *= 1 + 3e-6  # from 25 minutes on it runs 3 ppm faster still
    t = T0_US + np.r_[0, np.cumsum(step_us)].round().astype(np.int64)
    report = _detect(_store(tmp_path / "s", _block(0, t_us=t)))
    clock = [a for a in report.anomalies if a.kind == "clock"]
    assert len(clock) == 1 and report.anomalies == clock, report.as_list()
    assert abs(clock[0].start_us - (T0_US + change * 1000)) <= 60_000_000
    ppm = float(clock[0].detail.split("rate ")[1].split(" ppm")[0])
    assert ppm == pytest.approx(3.0, abs=0.05)


def test_the_spike_detector_finds_a_one_sample_jump(tmp_path):
    def error(ts):
        e = 0.02 * np.sin(2 * np.pi * 0.3 * ts)
        e[round(1500.5 * RATE_HZ)] += 1.0
        return e

    report = _detect(_store(tmp_path / "s", _block(1800.0, error=error)))
    assert [a.kind for a in report.anomalies] == ["spike"]
    assert report.anomalies[0].start_us <= T0_US + 1_500_500_000 < report.anomalies[0].end_us


def _slews_after(seconds_tracking: float, total_s: float):
    """Position: a slow drive, then back-and-forth 20° slews at 3°/s² (triangle profiles)."""
    def position(ts):
        p = 1e-4 * ts
        later = ts >= seconds_tracking
        u = np.mod(ts - seconds_tracking, 30.0)  # a slew every 30 s: 5.2 s there, rest, back
        half = math.sqrt(10 * DEG / (3 * DEG))
        x = np.where(u < half, 0.5 * 3 * DEG * u ** 2,
                     np.where(u < 2 * half, 20 * DEG - 0.5 * 3 * DEG * (2 * half - u) ** 2,
                              20 * DEG))
        leg = np.floor((ts - seconds_tracking) / 30.0).astype(int) % 2
        return np.where(later, 1e-4 * seconds_tracking + np.where(leg == 0, x, 20 * DEG - x), p)
    return position


def test_a_reference_of_one_motion_phase_is_refused_when_the_night_holds_others(tmp_path):
    # ten minutes of tracking, then five of slews: a third of the night in another phase
    # (the refusal's bound is a fifth)
    store = _store(tmp_path / "s", _block(900.0, position=_slews_after(600.0, 900.0)))
    with pytest.raises(ReferenceRefused, match="one motion phase only"):
        _detect(store, reference=[(T0_US, T0_US + 600_000_000)])
    with pytest.raises(ReferenceRefused, match="300 s or more"):
        _detect(store, reference=[(T0_US, T0_US + 120_000_000)])


@pytest.fixture(scope="module")
def small_store(tmp_path_factory):
    """A steady 20-minute store, written once: the CLI only reads it."""
    return _store(tmp_path_factory.mktemp("small") / "store",
                  _block(1200.0, current=lambda t: 0.25 + 0.001 * np.sin(t)))


@pytest.mark.parametrize(("args", "message"), [
    (["--threshold", "0"], "--threshold"),
    (["--cogging-periods", "-1"], "--cogging-periods"),
    (["--settle-s", "-1"], "--settle-s"),
    (["--reference-from", "+100", "--reference-to", "+50"], "empty reference"),
    (["--reference", "+100"], "FROM..TO"),
    (["--reference", "+500..+100"], "empty reference"),
    (["--reference", "+1000..+1100"], "300 s or more"),
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


def test_vs_data_anomalies_on_a_steady_store_finds_nothing_and_says_what_it_could_not_check(
        small_store):
    result = CliRunner().invoke(app, ["data", "anomalies", str(small_store), "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["anomalies"] == []
    assert {(c["detector"], c["reason"]) for c in doc["not_run"]} == {
        ("vibration", "the tracking error is silent in every band on the reference"),
        ("temperature", "needs axis.az.temperature; the store has none")}


def test_a_store_without_current_names_the_detector_that_did_not_run(tmp_path):
    rng = np.random.default_rng(5)
    store = _store(tmp_path / "s", _block(1200.0, error=lambda t: rng.normal(0, 0.02, len(t))),
                   names=("axis.az.position", "axis.az.error_arcsec"))
    result = CliRunner().invoke(app, ["data", "anomalies", str(store), "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert {"detector": "current", "axis": "az",
            "reason": "needs axis.az.position and axis.az.current; the store has no "
                      "axis.az.current"} in doc["not_run"]
    ran = {c["detector"] for c in doc["checks"] if c["ran"]}
    assert {"vibration", "spike", "clock"} <= ran and "current" not in ran
    text = CliRunner().invoke(app, ["data", "anomalies", str(store)])
    assert text.exit_code == 0
    assert "current az: did not run — needs axis.az.position and axis.az.current" in text.stdout
