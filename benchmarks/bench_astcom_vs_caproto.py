"""Streaming cost per value: ASTCom beside EPICS Channel Access (caproto) in the same run.

Both servers make 16 signals at 10 kHz and send them to one client on loopback for the same
time; each runs in a process of its own that measures its own CPU time, first with no
client, then streaming:

* ASTCom: the example device (16 traced signals, 10 kHz loop) streaming every tick of
  every signal (`samples_per_packet` samples per packet, exact ticks and times, loss
  accounting);
* caproto: an IOC whose one waveform PV of 16 × 200 doubles is written every 20 ms, the
  values computed like the device's (numpy sines), monitored by a caproto client.

The figure is the server's CPU, in % of one core per 10 000 values/s, total and the part
that streaming adds. Issue 17's goal: ASTCom's streaming cost per value at or below caproto's.
caproto is a benchmark extra (`pip install caproto`); it runs on 127.0.0.1 only
(EPICS_CA_AUTO_ADDR_LIST=NO, EPICS_CAS_INTF_ADDR_LIST=127.0.0.1, a free port).

Run: .venv/bin/python benchmarks/bench_astcom_vs_caproto.py [--seconds 20] [--baseline 5]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import os
import socket
import time
from multiprocessing.connection import Connection

import numpy as np

LOOP_RATE_HZ = 10_000
SIGNALS = 16
PACKET_S = 0.02
PER_PACKET = round(LOOP_RATE_HZ * PACKET_S)  # 200 samples of each signal per 20 ms


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _loopback_ca(port: int) -> None:
    os.environ.update({"EPICS_CA_AUTO_ADDR_LIST": "NO", "EPICS_CA_ADDR_LIST": "127.0.0.1",
                       "EPICS_CAS_INTF_ADDR_LIST": "127.0.0.1",
                       "EPICS_CAS_AUTO_BEACON_ADDR_LIST": "NO",
                       "EPICS_CAS_BEACON_ADDR_LIST": "127.0.0.1",
                       "EPICS_CAS_BEACON_PORT": str(port + 1),
                       "EPICS_CA_SERVER_PORT": str(port), "EPICS_CA_REPEATER_PORT": str(port + 1),
                       "EPICS_CA_MAX_ARRAY_BYTES": str(1 << 24)})


async def _answer_marks(pipe: Connection, progress) -> None:
    """Answer "mark" with (cpu_s, wall_s, progress()) until "quit"."""
    while True:
        await asyncio.sleep(0.02)
        if not pipe.poll():
            continue
        if pipe.recv() == "quit":
            return
        pipe.send((time.process_time(), time.monotonic(), progress()))


def serve_caproto(pipe: Connection, port: int) -> None:
    """A caproto IOC: BENCH:wave, 16 × 200 doubles written every 20 ms (10 kHz × 16)."""
    _loopback_ca(port)
    # a sink for the server's beacons on loopback (no repeater runs here): a beacon sent to a
    # closed port is refused, which caproto reports as an error every beacon period
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", port + 1))
    from caproto.asyncio.server import start_server
    from caproto.server import PVGroup, pvproperty

    class Bench(PVGroup):
        wave = pvproperty(value=np.zeros(SIGNALS * PER_PACKET), dtype=float,
                          max_length=SIGNALS * PER_PACKET, name="wave")

    async def main() -> None:
        ioc = Bench(prefix="BENCH:")
        server = asyncio.create_task(start_server(ioc.pvdb, interfaces=["127.0.0.1"],
                                                  log_pv_names=False))
        ticks = 0
        offsets = np.arange(SIGNALS)[:, None]

        async def produce() -> None:
            nonlocal ticks
            t0 = time.monotonic()
            while True:
                due = int((time.monotonic() - t0) / PACKET_S)
                while ticks // PER_PACKET < due:
                    phase = 2 * np.pi * 5.0 * (ticks + np.arange(PER_PACKET)) / LOOP_RATE_HZ
                    await ioc.wave.write(np.sin(phase + offsets).ravel())
                    ticks += PER_PACKET
                await asyncio.sleep(PACKET_S / 4)

        producer = asyncio.create_task(produce())
        pipe.send("ready")
        await _answer_marks(pipe, lambda: ticks)
        producer.cancel()
        server.cancel()

    asyncio.run(main())
    sink.close()


async def _measure(pipe: Connection, subscribe, baseline_s: float, seconds: float) -> dict:
    loop = asyncio.get_running_loop()

    async def mark() -> tuple[float, float, int]:
        pipe.send("mark")
        return await loop.run_in_executor(None, pipe.recv)

    await asyncio.sleep(1.0)
    a = await mark()
    await asyncio.sleep(baseline_s)
    b = await mark()
    received, stop = await subscribe()
    await asyncio.sleep(1.0)
    first = received()
    c = await mark()
    await asyncio.sleep(seconds)
    d = await mark()
    values = received() - first
    await stop()
    return {"a": a, "b": b, "c": c, "d": d, "values": values}


def _caproto_client(port: int):
    _loopback_ca(port)

    async def subscribe():
        from caproto.asyncio.client import Context

        ctx = Context()
        (pv,) = await ctx.get_pvs("BENCH:wave", timeout=10)
        count = [0]

        def on_update(sub, response) -> None:
            count[0] += len(response.data)

        sub = pv.subscribe()
        sub.add_callback(on_update)  # caproto keeps callbacks by weak reference: so do we

        async def stop() -> None:
            await sub.clear()
            await ctx.disconnect()
            del stop.keep

        stop.keep = on_update
        return (lambda: count[0]), stop

    return subscribe


def _astcom_client(url: str, names: list[str]):
    async def subscribe():
        from astcom_client import Client

        client = await Client.connect(url, password="bench")
        stream = await client.stream(names, rate_hz=LOOP_RATE_HZ)
        stream.on_packet(lambda packet: None)

        async def stop() -> None:
            await stream.stop()
            await client.close()

        return (lambda: stream.samples * len(names)), stop

    return subscribe


def _report(name: str, r: dict) -> tuple[float, float]:
    (cpu_a, wall_a), (cpu_b, wall_b) = r["a"][:2], r["b"][:2]
    (cpu_c, wall_c), (cpu_d, wall_d) = r["c"][:2], r["d"][:2]
    base = (cpu_b - cpu_a) / (wall_b - wall_a)
    busy = (cpu_d - cpu_c) / (wall_d - wall_c)
    rate = r["values"] / (wall_d - wall_c)
    per_total = 100 * busy / (rate / 1e4)
    per_stream = 100 * (busy - base) / (rate / 1e4)
    print(f"{name:16} {rate:12.0f} {100 * base:10.2f} {100 * busy:10.2f} "
          f"{per_total:14.3f} {per_stream:16.3f}")
    return per_total, per_stream


def main() -> None:
    try:
        import caproto  # noqa: F401
    except ImportError:
        raise SystemExit("caproto is not installed: .venv/bin/pip install -e '.[bench]'") from None
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="streaming time measured")
    parser.add_argument("--baseline", type=float, default=5.0,
                        help="seconds of the server producing values with no client")
    parser.add_argument("--block-ms", type=float, nargs="+", default=[2.0, 20.0],
                        help="ASTCom device block(s) of ticks, ms: 2 is the example device's "
                             "own; 20 batches like the IOC's 20-ms waveform")
    args = parser.parse_args()
    from bench_astcom_stream import serve as serve_astcom  # the same device as bench_astcom_stream

    ctx = mp.get_context("spawn")
    results = {}
    for block_ms in args.block_ms:
        here, there = ctx.Pipe()
        server = ctx.Process(target=serve_astcom, args=(there, float(LOOP_RATE_HZ), SIGNALS - 4,
                                                        block_ms / 1000), daemon=True)
        server.start()
        try:
            url, names = here.recv()
            results[f"ASTCom {block_ms:g} ms"] = asyncio.run(
                _measure(here, _astcom_client(url, names), args.baseline, args.seconds))
            here.send("quit")
        finally:
            server.join(15)
    port = _free_port()
    here, there = ctx.Pipe()
    server = ctx.Process(target=serve_caproto, args=(there, port), daemon=True)
    server.start()
    try:
        assert here.recv() == "ready"
        results["caproto"] = asyncio.run(_measure(here, _caproto_client(port), args.baseline,
                                                  args.seconds))
        here.send("quit")
    finally:
        server.join(15)
        if server.is_alive():
            server.terminate()
    print(f"{SIGNALS} signals at {LOOP_RATE_HZ} Hz to one client over loopback, "
          f"{args.seconds:g} s each; server CPU in % of one core")
    print(f"{'server':16} {'values/s':>12} {'idle %':>10} {'streaming %':>10} "
          f"{'% per 10k/s':>14} {'added per 10k/s':>16}")
    ours = {name: _report(name, r) for name, r in results.items() if name != "caproto"}
    theirs = _report("caproto", results["caproto"])
    for name, (total, part) in ours.items():
        print(f"{name} / caproto per value: total {total / theirs[0]:.2f}x, streaming part "
              f"{part / max(theirs[1], 1e-9):.2f}x (goal: at or below 1.00x)")


if __name__ == "__main__":
    main()
