"""The detectors while a recording is made: an anomaly becomes one event in the log."""

from __future__ import annotations

import pytest
from anomaly_helpers import CASES, LIVE_CASE, MADE_ONCE_TIMEOUT_S

from virtualstar.anomalies.live import LiveAnomalies
from virtualstar.forking import HeldWriter
from virtualstar.recorder.parquet_store import ParquetStoreReader

# a fixture's setup (a recording, or the wait for another worker's) counts toward the
# first test's timeout
pytestmark = pytest.mark.timeout(MADE_ONCE_TIMEOUT_S)


def test_a_live_recording_logs_each_anomaly_once_after_the_injection(live_recording):
    # the friction case (conftest.py): recorded with the detectors running live, and its
    # fault flagged within a window of its injection at 16 min
    store, t0_us = live_recording
    injections, expected = CASES[LIVE_CASE]
    assert [(kind, axis) for kind, axis, *_ in expected] == [("current", "az")]
    events = [e for e in ParquetStoreReader(store).events() if e.kind == "anomaly"]
    injected_us = injections[0].at_us(t0_us)
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


def test_detectors_switched_on_mid_recording_catch_up_to_what_they_find_from_the_start(
        live_recording):
    # LIVE_CASE's variant switches its detectors on at its fork and first replays the
    # recording held until then (HeldWriter.replay): fed so, they must find what
    # detectors fed from the start find. The friction store, fed as a recorder feeds it
    # (blocks, and the events stored by then), to detectors running from the start and to
    # a HeldWriter that detectors switched on at the injection catch up on.
    store, t0_us = live_recording
    switch_us = CASES[LIVE_CASE][0][0].at_us(t0_us)
    reader = ParquetStoreReader(store)
    names = [s.name for s in reader.signals()]
    events = sorted(reader.events(), key=lambda e: e.t_us)
    whole = LiveAnomalies(names, 1000.0, lambda a: None)
    held = HeldWriter(lambda: None)
    held.begin([])
    late: LiveAnomalies | None = None
    k = 0
    for block in reader.iter_blocks(batch_rows=7_777):
        end = int(block.t_us[-1])
        first = k
        while k < len(events) and events[k].t_us <= end:
            k += 1
        for feed in ([whole] + ([late] if late else [])):
            feed.feed_events(events[first:k])
            feed.feed(block)
        if late is None:
            held.write_events(events[first:k])
            held.write(block)
            if end >= switch_us:
                late = LiveAnomalies(names, 1000.0, lambda a: None)
                held.replay(late.feed, late.feed_events)
    for feed in (whole, late):
        feed.feed_events(events[k:])
        feed.finish()

    def key(live):
        return [(a.kind, a.axis, a.start_us, a.end_us, a.score) for a in live.reported]

    assert late is not None and key(whole) and key(late) == key(whole)
    assert late.reference.stretches == whole.reference.stretches
