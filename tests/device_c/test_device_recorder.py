"""The recorder takes 16 signals at 10 kHz from the C device (its -O2 build, in real time)
with no sample lost: every tick of the recording is in the Parquet store, at its mount
time, with the value the device computed (its extra.sNN are sin(2*pi*5 Hz*t + N))."""

from __future__ import annotations

import asyncio
import json

import numpy as np
from astcom_helpers import PASSWORDS
from device_impls import DeviceProcess, device_args

from astcom_client import Client
from virtualstar.recorder import ParquetStoreReader, ParquetStoreWriter, Recorder, client_connector

LOOP_RATE_HZ = 10_000.0
NAMES = [f"extra.s{i:02d}" for i in range(16)]
RECORD_S = 1.5
# 2 s of ticks in the device's ring: the device's own loop may be starved a while by a
# loaded host without a row being overwritten before it is sent
RING_TICKS = 20_000


async def record(url: str, store) -> tuple[object, int, int]:
    """Record NAMES for RECORD_S; return (summary, start_t_us of tick 0, last tick wanted)."""
    writer = ParquetStoreWriter(store)
    recorder = Recorder(client_connector(url, password=PASSWORDS["observer"]), NAMES,
                        LOOP_RATE_HZ, writer, source="C example device")
    task = asyncio.create_task(recorder.run())
    await asyncio.wait_for(recorder.started.wait(), 30)
    await asyncio.sleep(RECORD_S)
    async with await Client.connect(url, password=PASSWORDS["observer"]) as client:
        ping = await client.ping()
    start_t_us = ping["tick_t_us"] - ping["tick"] * 100
    # the recorder drains what the device has sent so far, however late it reads
    await asyncio.wait_for(recorder.wait_for_tick(ping["tick"]), 120)
    recorder.stop()
    return await asyncio.wait_for(task, 60), start_t_us, ping["tick"]


def test_the_recorder_keeps_every_sample_of_16_signals_at_10_khz(host_device, tmp_path):
    stats_path = tmp_path / "device-stats.json"
    proc = DeviceProcess(["--tcp", "127.0.0.1:0", "--stats", str(stats_path),
                          "--ring-ticks", str(RING_TICKS),
                          *device_args(loop_rate_hz=LOOP_RATE_HZ, n_extra_signals=16)],
                         build="host")
    try:
        url = proc.wait_line(r"(tcp://\S+)")[1]
        summary, start_t_us, last_tick = asyncio.run(record(url, tmp_path / "store"))
    finally:
        proc.stop()
    device = json.loads(stats_path.read_text())
    assert summary.lost == 0 and summary.gaps == [] and summary.reconnects == 0
    assert device["dropped_samples"] == 0 and device["ring_lost_samples"] == 0
    block = ParquetStoreReader(tmp_path / "store").window(0, 2**62)
    ticks = (block.t_us - start_t_us) // 100
    assert np.all((block.t_us - start_t_us) % 100 == 0)
    # every tick the device made from the first recorded one to the last one asked for (a
    # starved host makes fewer than RECORD_S * 10 000: that is the device's lateness)
    assert ticks[-1] >= last_tick and len(ticks) >= 1000
    steps = np.diff(ticks)
    # consecutive ticks; only a host that held the device over 2 s behind may skip (counted)
    assert np.all(steps >= 1) and np.sum(steps - 1) <= device["skipped_ticks"]
    assert summary.samples == len(ticks)
    phase = 2 * np.pi * 5.0 * ticks / LOOP_RATE_HZ
    for i, name in enumerate(NAMES):
        np.testing.assert_allclose(block.columns[name], np.sin(phase + i), rtol=0, atol=1e-12)
