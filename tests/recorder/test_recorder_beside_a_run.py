"""Recording beside a run on a server: the recorder's own thread, against a real endpoint."""

from __future__ import annotations

import time

import numpy as np
import pytest

from virtualstar.planning.recording import RunRecording, ThreadedRecording
from virtualstar.recorder import ParquetStoreReader, RecorderError


def test_a_threaded_recording_stores_every_sample_while_the_caller_blocks(device_url, tmp_path):
    store = tmp_path / "store"
    rec = ThreadedRecording(RunRecording(("counter",), 200.0, (f"parquet:{store}",)), device_url)
    rec.start()
    # the caller's thread is busy elsewhere (the blocking API call) while samples arrive;
    # the deadline only bounds a broken recorder, however slow the host
    deadline = time.monotonic() + 60.0
    while rec.recorder.sink.samples < 200 and time.monotonic() < deadline:
        time.sleep(0.05)
    summary = rec.stop()
    assert "error" not in summary and summary["lost"] == 0 and summary["samples"] >= 200
    block = ParquetStoreReader(store).window(summary["first_t_us"], summary["last_t_us"] + 1)  # [from, to)
    assert len(block) == summary["samples"]
    # the device's counter counts its ticks: at 200 Hz of a 1 kHz loop, 5 apart, none skipped
    assert set(np.diff(block.columns["counter"]).tolist()) == {5}


def test_a_recording_that_cannot_start_raises_in_the_callers_thread(device_url, tmp_path):
    rec = ThreadedRecording(RunRecording(("no.such.signal",), 10.0,
                                         (f"parquet:{tmp_path / 'store'}",)), device_url)
    with pytest.raises(RecorderError, match="no signal no.such.signal"):
        rec.start()
    rec.stop()
