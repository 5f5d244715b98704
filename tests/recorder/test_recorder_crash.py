"""A `vs record` process killed with SIGKILL loses at most its last flush interval.

The device is ours, in this process, in simulated time: it publishes exactly the ticks the
test asks for, then stands still, so what the recorder received is known. The recorder is a
real subprocess writing a Parquet store; the test waits (however long a loaded host takes)
until the store's journal holds the last tick, kills it, and reads the store back.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import forkserver
import numpy as np
import pytest
from typer.testing import CliRunner

from astcom_client import Endpoint, EndpointConfig
from astcom_client.example_device import ExampleDevice
from virtualstar.cli.main import app
from virtualstar.recorder.parquet_journal import JOURNAL_SUFFIX, read_journal
from virtualstar.recorder.parquet_store import HOUR_US, ParquetStoreReader

runner = CliRunner()
DEVICE_HZ = 1000
TOP_OF_HOUR_US = 1_772_402_400_000_000  # 2026-03-01T22:00:00Z
PATIENCE_S = 120.0  # a safety net for a loaded host, never a measured time


class ThreadedDevice:
    """The example device behind a TCP endpoint, on its own event loop in a thread."""

    def __init__(self, start_us: int) -> None:
        self.device = ExampleDevice(loop_rate_hz=DEVICE_HZ, start_t_us=start_us)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.endpoint = self._call(self._make_endpoint())
        self.url = self._call(self.endpoint.serve("tcp://127.0.0.1:0"))

    async def _make_endpoint(self) -> Endpoint:
        return Endpoint(self.device.collection, EndpointConfig(loop_rate_hz=DEVICE_HZ))

    def _call(self, coro):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(30)

    def streaming(self) -> bool:
        async def ask() -> bool:
            return len(self.endpoint.wanted_trace_columns) > 0
        return self._call(ask())

    def advance_s(self, seconds: float) -> int:
        """Publish `seconds` of ticks in 1-s packets; return the last tick's time (µs)."""
        async def run() -> None:
            for _ in range(round(seconds)):
                self.device.advance(self.endpoint, DEVICE_HZ)
                await asyncio.sleep(0)
        self._call(run())
        return self.device.t_us_of(self.device.tick - 1)

    def close(self) -> None:
        self._call(self.endpoint.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


def _durable_last_t_us(store: Path) -> int | None:
    """The last sample time a reader could recover now: finished hours and journals."""
    last = None
    for journal in (store / "samples").glob("*" + JOURNAL_SUFFIX):
        for batch in read_journal(journal):
            if batch.num_rows:
                t = int(batch.column(0)[-1].as_py())
                last = t if last is None else max(last, t)
    for f in (store / "samples").glob("*.parquet"):
        import pyarrow.parquet as pq

        md = pq.ParquetFile(f).metadata
        t = int(md.row_group(md.num_row_groups - 1).column(0).statistics.max)
        last = t if last is None else max(last, t)
    return last


def _wait_until(condition, what: str, details=lambda: "") -> None:
    deadline = time.monotonic() + PATIENCE_S
    while not condition():
        assert time.monotonic() < deadline, f"gave up waiting for {what} {details()}"
        time.sleep(0.05)


def _why_not(proc: subprocess.Popen, device: ThreadedDevice, store: Path, last_t_us: int) -> str:
    """What a failed wait saw (it once failed beside a loaded suite, with nothing to go on)."""
    stats = device._call(_endpoint_stats(device.endpoint))
    state = "running" if proc.poll() is None else f"exited {proc.returncode}: {proc.stderr.read()[-2000:]}"
    return (f"(durable last {_durable_last_t_us(store)}, wanted {last_t_us}; recorder {state}; "
            f"endpoint dropped {stats['dropped_samples']} samples, queues {stats['queue_depths']}; "
            f"store files {sorted(p.name for p in (store / 'samples').glob('*'))})")


async def _endpoint_stats(endpoint: Endpoint) -> dict:
    return endpoint.service.stats()


def _start_recorder(url: str, store: Path, rate_hz: float) -> subprocess.Popen:
    return forkserver.popen(
        [sys.executable, "-c", "from virtualstar.cli.main import main; main()", "record", url,
         "counter", "wave.sine", "--rate", f"{rate_hz:g}", "--store", f"parquet:{store}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize(("rate_hz", "start_us", "seconds"), [
    (1000, TOP_OF_HOUR_US - 30 * 60_000_000, 20),   # mid-hour, 1 kHz
    (10, TOP_OF_HOUR_US - 30 * 60_000_000, 20),     # mid-hour, 10 Hz
    (1000, TOP_OF_HOUR_US - 10_000_000, 15),        # seconds after the top of an hour
    (10, TOP_OF_HOUR_US - 10_000_000, 15),
], ids=["mid-hour-1kHz", "mid-hour-10Hz", "after-top-of-hour-1kHz", "after-top-of-hour-10Hz"])
def test_a_killed_recorder_loses_nothing_it_held_longer_than_a_flush(tmp_path, rate_hz,
                                                                    start_us, seconds):
    device = ThreadedDevice(start_us)
    store = tmp_path / "store"
    proc = _start_recorder(device.url, store, rate_hz)
    try:
        _wait_until(device.streaming, "the recorder's stream")
        last_t_us = device.advance_s(seconds)
        _wait_until(lambda: (_durable_last_t_us(store) or 0) >= last_t_us - 1e6 / rate_hz,
                    "the journal to hold the last tick",
                    lambda: _why_not(proc, device, store, last_t_us))
        crossed = last_t_us // HOUR_US != start_us // HOUR_US
        if crossed:  # the hour closed on its clock, before any crash or recovery
            finished = sorted(p.name for p in (store / "samples").glob("*.parquet"))
            assert finished and finished[0].startswith("20260301T21Z"), finished
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(30)

        info = runner.invoke(app, ["data", "info", str(store), "--json"])
        assert info.exit_code == 0, info.output
        assert "recovered" in info.stderr and "recorder died" in info.stderr
        doc = json.loads(info.stdout)
        assert doc["writer_pid"] is None
        assert doc["last_t_us"] >= last_t_us - 1e6 / rate_hz  # nothing held > 1 flush lost
        crash = [g for g in doc["gaps"] if g["reason"] == "recorder died"]
        assert len(crash) == 1 and crash[0]["after_t_us"] == doc["last_t_us"]
        reader = ParquetStoreReader(store)
        t = reader.window(doc["first_t_us"], doc["last_t_us"] + 1).t_us
        period_us = round(1e6 / rate_hz)
        assert np.all(np.diff(t) == period_us)  # no hole anywhere, across the hour too
        for args in (["query", str(store), "--decimate", "20", "--json"],
                     ["export", str(store), "--csv", str(tmp_path / "out.csv")],
                     ["plot", str(store), "--out", str(tmp_path / "plots")]):
            res = runner.invoke(app, ["data", *args])
            assert res.exit_code == 0, (args, res.output)
        envelope = json.loads(runner.invoke(app, ["data", "query", str(store), "--decimate",
                                                  str(seconds), "--json"]).stdout)
        assert sum(envelope["n"]) == len(t)  # the overview covers every recovered sample

        # a new recording into the same store works
        again = _start_recorder(device.url, store, rate_hz)
        _wait_until(device.streaming, "the second recorder's stream")
        again_last_t_us = device.advance_s(3)
        # the stop comes once the samples are in: a Ctrl-C stops at once, and samples still
        # in flight to a loaded recorder are not part of its recording
        _wait_until(lambda: (_durable_last_t_us(store) or 0) >= again_last_t_us - 1e6 / rate_hz,
                    "the second recording's journal to hold its last tick",
                    lambda: _why_not(again, device, store, again_last_t_us))
        again.send_signal(signal.SIGINT)
        _, err = again.communicate(timeout=60)
        assert again.returncode == 0, err
        assert ParquetStoreReader(store).count() > len(t)
    finally:
        if proc.poll() is None:
            proc.kill()
        device.close()


def test_a_second_recorder_into_a_live_store_is_refused_with_the_pid(tmp_path):
    device = ThreadedDevice(TOP_OF_HOUR_US)
    store = tmp_path / "store"
    proc = _start_recorder(device.url, store, 100)
    try:
        _wait_until(device.streaming, "the recorder's stream")
        res = runner.invoke(app, ["record", device.url, "counter", "--store", f"parquet:{store}",
                                  "--duration", "1"])
        assert res.exit_code != 0
        assert f"PID {proc.pid}" in res.output and "another recorder" in res.output
        recover = runner.invoke(app, ["data", "recover", str(store)])
        assert recover.exit_code == 1 and "live recorder" in recover.output
    finally:
        proc.kill()
        proc.wait(30)
        device.close()


def _spooled_last_t_us(spool: Path) -> int | None:
    last = None
    for f in spool.rglob("batch-*.lp"):
        for line in f.read_text().splitlines():
            if line.startswith("signals,"):
                t = int(line.rsplit(" ", 1)[1])
                last = t if last is None else max(last, t)
    return last


def test_a_killed_recorder_into_an_unreachable_influxdb_loses_nothing_it_spooled(tmp_path,
                                                                                influx):
    from virtualstar.recorder.influx_store import (
        InfluxConnection,
        InfluxStoreReader,
        spool_key,
    )

    influx.stop()  # the database is down from the start
    device = ThreadedDevice(TOP_OF_HOUR_US - 30 * 60_000_000)
    spool = tmp_path / "spool"
    args = [sys.executable, "-c", "from virtualstar.cli.main import main; main()", "record",
            device.url, "counter", "wave.sine", "--rate", "1000",
            "--store", f"influx:{influx.url}/crashdb", "--spool", str(spool)]
    proc = forkserver.popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_until(device.streaming, "the recorder's stream")
        last_t_us = device.advance_s(8)
        _wait_until(lambda: (_spooled_last_t_us(spool) or 0) >= last_t_us - 1000,
                    "the spool to hold the last tick")
        os.kill(proc.pid, signal.SIGKILL)
        _, err = proc.communicate(timeout=30)
        assert "does not answer" in err and str(spool) in err  # said on the terminal
        assert [p.name for p in spool.iterdir()] == [spool_key(influx.url, "crashdb")]

        influx.start()
        again = forkserver.popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_until(device.streaming, "the second recorder's stream")
        device.advance_s(2)
        again.send_signal(signal.SIGINT)
        _, err = again.communicate(timeout=60)
        assert again.returncode == 0, err
        reader = InfluxStoreReader(InfluxConnection.from_env(influx.url, "crashdb"))
        crash = [g for g in reader.gaps() if g.reason == "recorder died"]
        assert len(crash) == 1 and crash[0].after_t_us == last_t_us
        first_t_us, _ = reader.time_range()
        t = reader.window(first_t_us, last_t_us + 1, ["counter"]).t_us
        assert t[-1] == last_t_us and np.all(np.diff(t) == 1000)  # every sample before the kill
        assert not list((spool / spool_key(influx.url, "crashdb")).glob("batch-*.lp"))
    finally:
        if proc.poll() is None:
            proc.kill()
        device.close()


def test_the_influx_spool_is_keyed_by_server_and_database(tmp_path):
    from virtualstar.recorder.influx_store import spool_key

    keys = {spool_key("http://127.0.0.1:8086", "night"), spool_key("http://127.0.0.1:8087", "night"),
            spool_key("http://10.0.0.5:8086", "night"), spool_key("http://127.0.0.1:8086", "day")}
    assert len(keys) == 4
