"""The Recorder on real ASTCom streams: every sample with its time, exact gaps, restarts."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np
import pytest
from recorder_helpers import SimDevice, settle

from astcom_client import Endpoint, EndpointConfig
from astcom_client.example_device import ExampleDevice
from virtualstar.recorder import ParquetStoreReader, ParquetStoreWriter, Recorder, RecorderError
from virtualstar.recorder.subscriber import client_connector


async def _recording(dev: SimDevice, names, rate_hz, writer, body):
    rec = Recorder(dev.connect, names, rate_hz, writer)
    task = asyncio.create_task(rec.run())
    while rec.sink.session == "" and not task.done():
        await asyncio.sleep(0)
    await body(rec)
    rec.stop()
    return await task


async def _advance(dev: SimDevice, rec: Recorder, seconds: float, block: int = 500) -> None:
    ticks = round(seconds * dev.device.loop_rate_hz)
    for _ in range(ticks // block):
        dev.advance(block)
        await settle(5)
    k = max(1, round(dev.device.loop_rate_hz / rec.summary.rate_hz))
    await asyncio.wait_for(rec.wait_for_tick((dev.device.tick - 1) // k * k), 10.0)


@pytest.mark.parametrize("rate_hz", [1000.0, 250.0])
def test_recorder_stores_every_streamed_sample_with_its_mount_time(tmp_path, rate_hz):
    dev = SimDevice()
    writer = ParquetStoreWriter(tmp_path / "s", row_group_rows=4000)
    summary = asyncio.run(_recording(dev, ["counter", "wave.sine"], rate_hz, writer,
                                     lambda rec: _advance(dev, rec, 10.0)))
    block = ParquetStoreReader(tmp_path / "s").window(0, 2**62)
    k = round(1000 / rate_hz)
    ticks = np.arange(0, 10_000, k)
    np.testing.assert_array_equal(block.columns["counter"], ticks)  # counter = tick number
    np.testing.assert_array_equal(block.t_us, [dev.device.t_us_of(int(t)) for t in ticks])
    expected = np.sin(2 * math.pi * 5.0 * ticks / 1000.0)  # amplitude 1, 5 Hz
    np.testing.assert_allclose(block.columns["wave.sine"], expected, rtol=0, atol=1e-12)
    assert summary.samples == len(ticks) and summary.lost == 0 and summary.gaps == []
    assert summary.rate_hz == rate_hz


def test_dropped_packets_are_reported_as_gaps_of_exactly_the_missing_samples(tmp_path):
    dev = SimDevice(queue_packets=4, flush_interval_s=0.01)  # 10 samples per packet

    async def body(rec):  # small blocks (2 packets) pass; long bursts overflow the queue
        await _advance(dev, rec, 1.0, block=20)
        for _ in range(30):  # 3 s of ticks without letting the endpoint send: it drops
            dev.advance(100)
        await settle()
        await _advance(dev, rec, 1.0, block=20)
        for _ in range(7):
            dev.advance(100)
        await settle()
        await _advance(dev, rec, 0.5, block=20)

    writer = ParquetStoreWriter(tmp_path / "s")
    summary = asyncio.run(_recording(dev, ["counter"], 1000.0, writer, body))
    dropped = dev.endpoint.stats()["dropped_samples"]
    stored = ParquetStoreReader(tmp_path / "s").window(0, 2**62).columns["counter"]
    assert stored[0] == 0
    missing = np.setdiff1d(np.arange(dev.device.tick), stored)
    assert len(missing) > 0 and len(missing) == dropped == summary.lost
    runs = np.split(missing, np.flatnonzero(np.diff(missing) != 1) + 1)
    gaps = ParquetStoreReader(tmp_path / "s").gaps()
    assert len(gaps) == len(runs) == 2
    for gap, run in zip(gaps, runs, strict=True):
        assert gap.reason == "dropped"
        assert gap.lost_samples == len(run)
        assert gap.after_t_us == dev.device.t_us_of(int(run[0]) - 1)
        assert gap.before_t_us == dev.device.t_us_of(int(run[-1]) + 1)


def test_a_cut_connection_is_reconnected_and_its_hole_counted_exactly(tmp_path):
    dev = SimDevice()

    async def main():
        rec = Recorder(dev.connect, ["counter"], 1000.0, ParquetStoreWriter(tmp_path / "s"),
                       reconnect_delay_s=0.01)
        task = asyncio.create_task(rec.run())
        while rec.sink.session == "":
            await asyncio.sleep(0)
        await _advance(dev, rec, 1.0, block=100)
        await dev.transports[0].close()  # the network drops; the device keeps ticking
        while rec.summary.reconnects == 0:
            dev.advance(20)
            await asyncio.sleep(0.002)
        await _advance(dev, rec, 1.0, block=100)
        rec.stop()
        return await task

    summary = asyncio.run(main())
    reader = ParquetStoreReader(tmp_path / "s")
    stored = reader.window(0, 2**62).columns["counter"]
    missing = np.setdiff1d(np.arange(stored[0], stored[-1] + 1), stored)
    gaps = reader.gaps()
    assert summary.reconnects == 1 and len(gaps) == 1 and len(missing) > 0
    assert gaps[0].reason == "reconnect"
    assert gaps[0].lost_samples == len(missing) == summary.lost
    np.testing.assert_array_equal(missing, np.arange(missing[0], missing[-1] + 1))
    assert gaps[0].after_t_us == dev.device.t_us_of(int(missing[0]) - 1)
    assert gaps[0].before_t_us == dev.device.t_us_of(int(missing[-1]) + 1)


def test_recorder_reconnects_after_the_endpoint_restarts_and_records_the_hole(tmp_path):
    async def serve(port: int):
        device = ExampleDevice(loop_rate_hz=1000.0)
        endpoint = Endpoint(device.collection, EndpointConfig(loop_rate_hz=1000.0))
        url = await endpoint.serve(f"tcp://127.0.0.1:{port}")
        return device, endpoint, url, asyncio.create_task(device.run(endpoint))

    async def stop(endpoint, loop_task):
        loop_task.cancel()
        await asyncio.gather(loop_task, return_exceptions=True)
        await endpoint.close()

    async def main():
        dev1, ep1, url, loop1 = await serve(0)
        port = int(url.rsplit(":", 1)[1])
        rec = Recorder(client_connector(url), ["counter"], 1000.0,
                       ParquetStoreWriter(tmp_path / "s"), reconnect_delay_s=0.05)
        task = asyncio.create_task(rec.run())
        await asyncio.sleep(0.6)
        await stop(ep1, loop1)
        last_before = rec.sink.last_t_us
        await asyncio.sleep(0.3)
        dev2, ep2, _, loop2 = await serve(port)
        t = time.monotonic()
        while rec.summary.reconnects == 0 or rec.sink.last_t_us == last_before:
            assert time.monotonic() - t < 10, "the recorder did not reconnect"
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.3)
        rec.stop()
        summary = await task
        await stop(ep2, loop2)
        return summary, dev2

    summary, dev2 = asyncio.run(main())
    reader = ParquetStoreReader(tmp_path / "s")
    block = reader.window(0, 2**62)
    assert summary.reconnects >= 1
    restart = [g for g in reader.gaps() if g.reason == "restart"]
    assert len(restart) == 1
    gap = restart[0]
    i = int(np.searchsorted(block.t_us, gap.before_t_us))
    assert block.t_us[i - 1] == gap.after_t_us  # the hole lies exactly between two samples
    before, after = block.columns["counter"][:i], block.columns["counter"][i:]
    np.testing.assert_array_equal(np.diff(before), 1)  # each side is complete
    np.testing.assert_array_equal(np.diff(after), 1)
    assert gap.before_t_us == dev2.t_us_of(int(after[0]))
    assert gap.before_t_us - gap.after_t_us >= 300_000  # the endpoint was down 0.3 s


def test_recording_names_the_signals_an_endpoint_lacks_or_cannot_stream(tmp_path):
    dev = SimDevice()

    async def attempt(names):
        rec = Recorder(dev.connect, names, 100.0, ParquetStoreWriter(tmp_path / "s"))
        await rec.run(1.0)

    with pytest.raises(RecorderError, match="no signal nope.*astcom list"):
        asyncio.run(attempt(["counter", "nope"]))
    with pytest.raises(RecorderError, match="f64\\[3\\] cannot be recorded"):
        asyncio.run(attempt(["gains"]))
    with pytest.raises(RecorderError, match="repeat"):
        Recorder(dev.connect, ["counter", "counter"], 100.0, ParquetStoreWriter(tmp_path / "s"))
