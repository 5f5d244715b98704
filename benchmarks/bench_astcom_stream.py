"""Stream: 16 signals at 10 kHz to 4 clients; lost samples and the endpoint's CPU.

The endpoint (the example device at 10 kHz with 16 traced signals) runs in its own
process, which measures its own CPU time (time.process_time) first with the device loop
alone, then while streaming every signal at the full loop rate to 4 clients running in
this process.

Run: .venv/bin/python benchmarks/bench_astcom_stream.py [--seconds 60] [--clients 4]
Goal (issue 2): zero lost samples; endpoint streaming cost <= 20 % of one core.
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import time
from multiprocessing.connection import Connection

LOOP_RATE_HZ = 10_000.0
PASSWORD = "bench"


def serve(pipe: Connection, loop_rate_hz: float, n_extra: int, block_s: float = 0.002) -> None:
    """Run the device and its endpoint; answer "mark" with (cpu_s, wall_s, tick, dropped)."""
    from astcom_client import Endpoint, EndpointConfig
    from astcom_client.example_device import ExampleDevice

    async def main() -> None:
        device = ExampleDevice(loop_rate_hz=loop_rate_hz, n_extra_signals=n_extra)
        endpoint = Endpoint(device.collection, EndpointConfig(
            loop_rate_hz=loop_rate_hz, passwords={"operator": PASSWORD}))
        url = await endpoint.serve("ws://127.0.0.1:0")
        loop_task = asyncio.create_task(device.run(endpoint, block_s=block_s))
        pipe.send((url, [v.name for v in device.collection
                         if getattr(v, "trace_column", None) is not None]))
        while True:
            await asyncio.sleep(0.05)
            if not pipe.poll():
                continue
            command = pipe.recv()
            if command == "quit":
                break
            pipe.send((time.process_time(), time.monotonic(), device.tick,
                       endpoint.stats()["dropped_samples"]))
        loop_task.cancel()
        await endpoint.close()

    asyncio.run(main())


async def measure(pipe: Connection, url: str, names: list[str], args: argparse.Namespace) -> dict:
    from astcom_client import Client

    loop = asyncio.get_running_loop()

    async def mark() -> tuple[float, float, int, int]:
        pipe.send("mark")
        return await loop.run_in_executor(None, pipe.recv)

    await asyncio.sleep(1.0)  # warm up
    a = await mark()
    await asyncio.sleep(args.baseline)
    b = await mark()
    clients = [await Client.connect(url, password=PASSWORD, name=f"bench{i}")
               for i in range(args.clients)]
    streams = []
    for client in clients:
        stream = await client.stream(names, rate_hz=LOOP_RATE_HZ)
        stream.on_packet(lambda packet: None)  # count only (the Stream keeps totals)
        streams.append(stream)
    await asyncio.sleep(1.0)
    start_samples = [s.samples for s in streams]
    c = await mark()
    await asyncio.sleep(args.seconds)
    d = await mark()
    end_samples = [s.samples for s in streams]
    lost = [s.lost for s in streams]
    for stream in streams:
        await stream.stop()
    stats = await clients[0].stats()
    for client in clients:
        await client.close()
    return {"a": a, "b": b, "c": c, "d": d, "lost": lost, "stats": stats,
            "samples": [e - s for s, e in zip(start_samples, end_samples, strict=True)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="streaming time measured")
    parser.add_argument("--baseline", type=float, default=10.0,
                        help="seconds of device loop alone, measured first")
    parser.add_argument("--clients", type=int, default=4)
    parser.add_argument("--signals", type=int, default=16, help="traced signals streamed (>= 4)")
    args = parser.parse_args()

    ctx = mp.get_context("spawn")
    here, there = ctx.Pipe()
    server = ctx.Process(target=serve, args=(there, LOOP_RATE_HZ, args.signals - 4), daemon=True)
    server.start()
    try:
        url, names = here.recv()
        r = asyncio.run(measure(here, url, names, args))
        here.send("quit")
    finally:
        server.join(15)
        if server.is_alive():
            server.terminate()
    (cpu_a, wall_a, _, _), (cpu_b, wall_b, _, _) = r["a"], r["b"]
    (cpu_c, wall_c, tick_c, drop_c), (cpu_d, wall_d, tick_d, drop_d) = r["c"], r["d"]
    base = (cpu_b - cpu_a) / (wall_b - wall_a)
    busy = (cpu_d - cpu_c) / (wall_d - wall_c)
    ticks_rate = (tick_d - tick_c) / (wall_d - wall_c)
    print(f"{len(names)} signals at {LOOP_RATE_HZ:g} Hz to {args.clients} clients for "
          f"{wall_d - wall_c:.1f} s (device kept {ticks_rate:.0f} ticks/s)")
    print(f"samples received per client: {r['samples']} "
          f"(expected about {tick_d - tick_c} each)")
    print(f"lost samples seen by clients: {r['lost']}; endpoint dropped: {r['stats']['dropped_samples']}"
          f" (during the window: {drop_d - drop_c})")
    print(f"endpoint process CPU: device loop alone {100 * base:.1f} % of a core, "
          f"with streaming {100 * busy:.1f} %; streaming cost {100 * (busy - base):.1f} %")
    lost_total = sum(r["lost"]) + r["stats"]["dropped_samples"]
    print(f"goal zero lost: {'met' if lost_total == 0 else 'NOT met'}; goal streaming cost "
          f"<= 20 %: {'met' if busy - base <= 0.20 else 'NOT met'}")


if __name__ == "__main__":
    main()
