"""The InfluxDB store against a real influxd: exact round trip, envelopes, and an outage
in the middle of a recording that loses nothing."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from recorder_helpers import START_US
from test_recorder_stores import SIGNALS, _envelope_by_masks, _synthetic

from astcom_client import Endpoint, EndpointConfig
from astcom_client.example_device import ExampleDevice
from virtualstar.recorder import InfluxError, ParquetStoreReader, ParquetStoreWriter, Recorder
from virtualstar.recorder.influx_store import (
    InfluxConnection,
    InfluxStoreReader,
    InfluxStoreWriter,
    line_protocol,
)
from virtualstar.recorder.samples import Gap, SampleBlock
from virtualstar.recorder.stores import TeeWriter, open_reader
from virtualstar.recorder.subscriber import client_connector


def test_line_protocol_escapes_names_and_writes_exact_floats_and_integers():
    block = SampleBlock(np.array([5, 6], dtype=np.int64),
                        {"a b,c=d": np.array([0.1, np.nan]), "n": np.array([3, -4])})
    lines = line_protocol("signals", {"session": "x y"}, block)
    assert lines == [r"signals,session=x\ y a\ b\,c\=d=0.1,n=3i 5", "signals,session=x\\ y n=-4i 6"]


def test_influx_store_round_trips_samples_timestamps_and_gaps_exactly(influx, tmp_path):
    conn = InfluxConnection(influx.url, "rt")
    writer = InfluxStoreWriter(conn, spool_dir=tmp_path / "spool", batch_lines=3000)
    block = _synthetic(12_000)
    block.columns["axis.az.current"][:4] = [1.5e-300, -0.0, 1e300, 2.2250738585072014e-308]
    writer.begin(SIGNALS, source="test", rate_hz=1000.0)
    for part in np.array_split(np.arange(len(block)), 5):
        writer.write(block.slice(int(part[0]), int(part[-1]) + 1))
    gap = Gap(START_US + 1000, START_US + 5000, 3, "dropped")
    writer.write_gap(gap)
    writer.close()
    assert writer.lines_spooled == 0 and not writer.spooled_files()
    reader = open_reader(f"influx:{influx.url}/rt")
    assert isinstance(reader, InfluxStoreReader)
    back = reader.window(int(block.t_us[0]), int(block.t_us[-1]) + 1)
    np.testing.assert_array_equal(back.t_us, block.t_us)
    for name, values in block.columns.items():
        assert back.columns[name].dtype == values.dtype
        np.testing.assert_array_equal(back.columns[name], values)
    assert reader.count() == len(block)
    assert reader.time_range() == (block.t_us[0], block.t_us[-1])
    assert {s.name: s.unit for s in reader.signals()} == {s.name: s.unit for s in SIGNALS}
    got = reader.gaps()
    assert [(g.after_t_us, g.before_t_us, g.lost_samples, g.reason) for g in got] == \
           [(gap.after_t_us, gap.before_t_us, 3, "dropped")]
    a, b = int(block.t_us[0]), int(block.t_us[-1]) + 1
    env = reader.envelope(a, b, ["axis.az.position"], buckets=7)
    expected = _envelope_by_masks(block.t_us, block.columns["axis.az.position"], a, env.bucket_us)
    assert [(int(t), int(n), lo, hi) for t, n, lo, hi in zip(
        env.t_us, env.n, env.mins["axis.az.position"], env.maxs["axis.az.position"],
        strict=True)] == expected


def test_influx_outage_during_a_recording_loses_no_sample(influx, tmp_path):
    async def main():
        device = ExampleDevice(loop_rate_hz=1000.0)
        endpoint = Endpoint(device.collection, EndpointConfig(loop_rate_hz=1000.0))
        url = await endpoint.serve("tcp://127.0.0.1:0")
        loop_task = asyncio.create_task(device.run(endpoint))
        influx_writer = InfluxStoreWriter(InfluxConnection(influx.url, "night"),
                                          spool_dir=tmp_path / "spool", batch_lines=400)
        tee = TeeWriter([ParquetStoreWriter(tmp_path / "pq"), influx_writer])
        rec = Recorder(client_connector(url), ["counter", "wave.sine"], 1000.0, tee)
        task = asyncio.create_task(rec.run())
        await asyncio.sleep(0.8)
        await asyncio.to_thread(influx.stop)  # the database goes down mid-recording
        await asyncio.sleep(1.0)
        spooled_while_down = influx_writer.spooled_batches
        await asyncio.to_thread(influx.start)
        await asyncio.sleep(1.0)
        rec.stop()
        summary = await task
        loop_task.cancel()
        await asyncio.gather(loop_task, return_exceptions=True)
        await endpoint.close()
        return summary, influx_writer, spooled_while_down

    summary, influx_writer, spooled_while_down = asyncio.run(main())
    assert spooled_while_down > 0  # the outage really happened during the recording
    assert not influx_writer.spooled_files()  # ... and the spool was written back
    assert summary.lost == 0 and summary.samples > 2000
    truth = ParquetStoreReader(tmp_path / "pq").window(0, 2**62)
    assert len(truth) == summary.samples
    np.testing.assert_array_equal(np.diff(truth.columns["counter"]), 1)
    back = InfluxStoreReader(InfluxConnection(influx.url, "night")).window(0, 2**62)
    np.testing.assert_array_equal(back.t_us, truth.t_us)
    np.testing.assert_array_equal(back.columns["counter"], truth.columns["counter"])
    np.testing.assert_array_equal(back.columns["wave.sine"], truth.columns["wave.sine"])


def test_a_database_that_never_answers_keeps_the_batches_on_disk_for_later(influx, tmp_path):
    url = influx.url
    influx.stop()
    conn = InfluxConnection(url, "later", timeout_s=1.0)
    w = InfluxStoreWriter(conn, spool_dir=tmp_path / "spool", batch_lines=100, close_drain_s=0.2)
    w.begin(SIGNALS)
    block = _synthetic(1000)
    w.write(block)
    w.close()
    spooled = w.spooled_files()
    assert sum(int(p.stem.rsplit("-", 1)[1]) for p in spooled) == len(block) + len(SIGNALS)
    with pytest.raises(InfluxError, match="cannot reach InfluxDB"):
        InfluxStoreReader(conn).count()
    influx.start()
    w2 = InfluxStoreWriter(conn, spool_dir=tmp_path / "spool")  # the next recording drains it
    w2.begin(SIGNALS)
    w2.close()
    assert not w2.spooled_files()
    back = InfluxStoreReader(conn).window(0, 2**62)
    np.testing.assert_array_equal(back.t_us, block.t_us)


def test_influx_store_keeps_events_even_two_at_one_microsecond(influx, tmp_path):
    from astcom_client.events import EventLog

    log = EventLog("emulator")
    log.add(START_US, "warning", "param", 'axis.az.inject_winding_fault: 0 → 0.2 "quoted"',
            name="axis.az.inject_winding_fault", old=0.0, new=0.2)
    log.add(START_US, "error", "fault", "az axis faulted: following error", axis="az", bits=8)
    log.add(START_US + 5, "info", "state", "mount HOLDING → FAULT")
    writer = InfluxStoreWriter(InfluxConnection(influx.url, "ev"), spool_dir=tmp_path / "spool")
    writer.begin(SIGNALS, source="test", rate_hz=1000.0)
    writer.write(_synthetic(10))
    writer.write_events(log.since(0))
    writer.close()
    back = open_reader(f"influx:{influx.url}/ev").events()
    assert [e.as_dict() for e in back] == [e.as_dict() for e in log.since(0)]
