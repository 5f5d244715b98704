"""The detectors while a recording is made: an anomaly becomes one event in the log."""

from __future__ import annotations

import asyncio

from anomaly_helpers import AT_S

from virtualstar.anomalies.live import LiveAnomalies
from virtualstar.recorder.experiment import Injection, SineExperiment, run_sine_experiment
from virtualstar.recorder.parquet_store import ParquetStoreReader


def test_a_live_recording_logs_each_anomaly_once_after_the_injection(tmp_path):
    # 20 minutes: the winding fault is flagged within a window of its injection at 16 min
    exp = SineExperiment(hours=20 / 60, injections=(
        Injection(AT_S, "axis.az.inject_winding_fault", 0.25),))
    result = asyncio.run(run_sine_experiment(exp, tmp_path, plots=False, detect=True))
    events = [e for e in ParquetStoreReader(result.store).events() if e.kind == "anomaly"]
    injected_us = result.trajectory_t0_us + round(AT_S * 1e6)
    assert [e.fields["anomaly_kind"] for e in events] == ["current"]
    assert events[0].source == "recorder" and events[0].level == "warning"
    assert events[0].t_us >= injected_us  # raised while recording, after the fault
    assert events[0].fields["axis"] == "az" and events[0].fields["score"] >= 1.0


def test_live_detection_on_a_clean_recording_reports_nothing(clean_recording):
    store, _ = clean_recording
    reader = ParquetStoreReader(store)
    names = [s.name for s in reader.signals()]
    found = []
    live = LiveAnomalies(names, 1000.0, found.append)
    live.feed_events(reader.events())
    for block in reader.iter_blocks(batch_rows=7_777):  # odd sizes: segments span blocks
        live.feed(block)
    live.finish()
    assert found == [] and live.active and live.detection.fitted
