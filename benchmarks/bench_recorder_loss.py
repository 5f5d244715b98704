"""Benchmark: does `vs record` keep every sample at 1 kHz × 16 signals and 10 kHz × 4?

The example device runs in real time in a separate process, serving ASTCom over a
loopback WebSocket. In this process the Recorder (Parquet store) and, as the reference,
a bare ASTCom client that only counts samples subscribe to the same signals at the same
time. The device's `counter` signal is the tick number, so the samples really missing
from the store are counted independently of what the recorder reports.

    .venv/bin/python benchmarks/bench_recorder_loss.py [--seconds 10] [--influx http://127.0.0.1:8086]

With --influx the recorder writes to that InfluxDB (database vs_bench_loss) instead of
Parquet, and the samples really missing are counted from what InfluxDB returns.
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import subprocess
import sys
import tempfile
import time

import numpy as np

from astcom_client import Client
from virtualstar.recorder import (
    InfluxConnection,
    InfluxStoreReader,
    InfluxStoreWriter,
    ParquetStoreReader,
    ParquetStoreWriter,
    Recorder,
)
from virtualstar.recorder.subscriber import client_connector

CASES = [(1000.0, 16), (10_000.0, 4)]  # (loop and record rate Hz, signals)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _serve(rate_hz: float, n_extra: int, seconds: float) -> tuple[subprocess.Popen, str]:
    port = _free_port()
    url = f"ws://127.0.0.1:{port}"
    code = ("import asyncio; from astcom_client.example_device import serve_example; "
            f"asyncio.run(serve_example([{url!r}], loop_rate_hz={rate_hz}, "
            f"n_extra_signals={n_extra}, duration_s={seconds + 20}))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc, url
        except OSError:
            if time.monotonic() > deadline or proc.poll() is not None:
                raise SystemExit("the example device did not start") from None
            time.sleep(0.05)


async def _reference(url: str, names: list[str], rate_hz: float, seconds: float) -> tuple[int, int]:
    async with await Client.connect(url, queue_packets=65_536) as c:
        stream = await c.stream(names, rate_hz=rate_hz)
        count = [0, 0]

        def on_packet(p) -> None:
            count[0] += p.n
            count[1] += p.lost

        stream.on_packet(on_packet)
        await asyncio.sleep(seconds)
        await stream.stop()
        return count[0], count[1]


async def _case(url: str, names: list[str], rate_hz: float, seconds: float, writer):
    rec = Recorder(client_connector(url), names, rate_hz, writer)
    ref = asyncio.create_task(_reference(url, names, rate_hz, seconds))
    summary = await rec.run(seconds)
    return summary, await ref


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="recording length per case")
    parser.add_argument("--influx", default=None, help="record into this InfluxDB 1.x instead")
    args = parser.parse_args()
    print(f"{'case':<16} {'recorded':>10} {'lost (reported)':>16} {'missing (counter)':>18} "
          f"{'reference client':>17} {'ref lost':>9}  goal")
    worst = 0
    for rate_hz, n_signals in CASES:
        proc, url = _serve(rate_hz, n_signals - 4, args.seconds)
        try:
            names = ["counter", "wave.sine", "wave.cosine", "pair.diff"] + [
                f"extra.s{i:02d}" for i in range(n_signals - 4)]
            with tempfile.TemporaryDirectory() as tmp:
                if args.influx:
                    conn = InfluxConnection(args.influx, "vs_bench_loss")
                    conn.query('DROP DATABASE "vs_bench_loss"', write=True)
                    writer, reader = InfluxStoreWriter(conn, spool_dir=tmp), InfluxStoreReader(conn)
                else:
                    writer, reader = ParquetStoreWriter(tmp), None
                summary, (ref_n, ref_lost) = asyncio.run(
                    _case(url, names, rate_hz, args.seconds, writer))
                reader = reader or ParquetStoreReader(tmp)
                counter = reader.window(0, 2**62, ["counter"]).columns["counter"]
                missing = int(counter[-1] - counter[0] + 1 - len(np.unique(counter)))
        finally:
            proc.terminate()
            proc.wait(10)
        worst = max(worst, summary.lost, missing)
        label = f"{rate_hz / 1000:g} kHz × {n_signals}"
        print(f"{label:<16} {summary.samples:>10} {summary.lost:>16} {missing:>18} "
              f"{ref_n:>17} {ref_lost:>9}  0 lost")
    store = f"InfluxDB {args.influx}" if args.influx else "Parquet"
    print(f"result: {'zero loss' if worst == 0 else f'LOSS: {worst} samples'} "
          f"({args.seconds:g} s per case into {store}, device in real time over ws://127.0.0.1)")


if __name__ == "__main__":
    main()
