"""`vs data anomalies` on the sine experiment's recordings (the mount tracks a sine, no VSS):
every injected fault found in its window by its kind and axis, nothing flagged on a clean
recording or before the injection."""

from __future__ import annotations

import json

import pytest
from anomaly_helpers import CASES, MADE_ONCE_TIMEOUT_S, faults
from typer.testing import CliRunner

from virtualstar.anomalies import detect_anomalies
from virtualstar.anomalies.scoring import score_detections
from virtualstar.cli.main import app
from virtualstar.recorder.parquet_store import ParquetStoreReader

# a fixture's setup (a recording, or the wait for another worker's) counts toward the
# first test's timeout
pytestmark = pytest.mark.timeout(MADE_ONCE_TIMEOUT_S)
CONTRACT = {"start_utc", "end_utc", "signals", "kind", "score"}
WINDOW_US = 60_000_000  # a flag may start up to one detector window before the injection


def _detect(store):
    reader = ParquetStoreReader(store)
    a, b = reader.time_range()
    return detect_anomalies(reader, a, b + 1), b + 1


def test_a_clean_recording_raises_no_anomaly(clean_recording):
    store, _ = clean_recording
    report, _ = _detect(store)
    assert report.anomalies == []
    assert {t.name for t in report.traces} >= {"az current", "az vibration", "az spike",
                                               "az temperature", "clock"}


def test_each_injected_fault_is_found_in_its_window_and_nothing_before(faulty_recording):
    name, store, t0 = faulty_recording
    report, end = _detect(store)
    expected = faults(CASES[name][1], t0, end)
    scores = score_detections(report.anomalies, expected, early_us=WINDOW_US)
    assert scores.found == scores.faults, (name, report.as_list())
    assert scores.true_anomalies == scores.anomalies, (name, report.as_list())
    for fault in expected:
        hit = [a for a in report.anomalies if a.kind == fault.kind and a.axis == fault.axis]
        assert all(a.start_us >= fault.start_us - WINDOW_US for a in hit)


def test_vs_data_anomalies_json_follows_the_contract(faulty_recording, tmp_path):
    name, store, _ = faulty_recording
    png = tmp_path / "scores.png"
    result = CliRunner().invoke(app, ["data", "anomalies", str(store), "--json", "--plot",
                                      str(png)])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)["anomalies"]
    assert doc and all(set(item) >= CONTRACT for item in doc)
    assert all(item["score"] >= 1.0 for item in doc)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
