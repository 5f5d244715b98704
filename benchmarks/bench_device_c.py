"""The C device (astcom_device, -O2) beside the Python endpoint: CPU per streamed value,
and the C device's 10 kHz tick lateness while streaming beside the same loop idle.

Both devices run the example controller at 10 kHz with 16 traced f64 signals
(extra.s00..s15) and serve ASTCom over loopback TCP, each in its own process; 4 clients
in this process stream all 16 signals at every tick (4 x 160 000 values/s). Each device's
process CPU (the scheduler's nanosecond count in /proc) is measured over a window with
its loop alone, then in the same process over one of the same length while streaming; the
streaming cost is the difference, divided by the values/s the clients received. For the C
device the figure is its communication thread's (where streams are built and sent; its
tick thread's own run-to-run variation, a percent or two, would otherwise drown it); its
whole process is shown beside it.

The C device also measures its own tick lateness (how late each 10 kHz tick starts,
histogram in µs; the first --warmup seconds left out) in both windows: idle, then
streaming. It is terminated at the end of each window, while its clients still stream.

Run: .venv/bin/python benchmarks/bench_device_c.py [--seconds 10] [--clients 4]
Goals (issue 31): C CPU per 10 000 streamed values/s <= 1/5 of the Python endpoint's
(same run); the C tick lateness p99 while streaming 16 x 10 kHz to 4 TCP clients, shown
beside the idle loop's (no goal value: the figure is reported).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
C_DEVICE = ROOT / "astcom_device" / "build" / "host" / "astcom-example"
LOOP_RATE_HZ = 10_000.0
N_SIGNALS = 16
NAMES = [f"extra.s{i:02d}" for i in range(N_SIGNALS)]
PASSWORD = "bench"
PYTHON_DEVICE = f"""
import asyncio
from astcom_client.example_device import serve_example
asyncio.run(serve_example(["tcp://127.0.0.1:0"], loop_rate_hz={LOOP_RATE_HZ},
                          passwords={{"operator": "{PASSWORD}"}}, n_extra_signals={N_SIGNALS}))
"""


def cpu_s(pid: int, thread: int | None = None) -> float:
    """CPU seconds the process (all its threads) or one of its threads has run so far, from
    the scheduler's nanosecond count (/proc/.../schedstat): /proc's stat ticks (10 ms) are
    too coarse for a streaming cost of a fraction of a percent."""
    threads = [thread] if thread is not None else [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    total_ns = 0
    for tid in threads:
        with contextlib.suppress(FileNotFoundError):  # a thread that has just ended
            total_ns += int(Path(f"/proc/{pid}/task/{tid}/schedstat").read_text().split()[0])
    return total_ns / 1e9


class Device:
    """A device process that prints its tcp:// URL."""

    def __init__(self, args: list[str]) -> None:
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=ROOT)
        line = self.proc.stdout.readline()
        match = re.search(r"(tcp://\S+)", line)
        if not match:
            self.proc.kill()
            raise RuntimeError(f"the device did not start: {line} {self.proc.stderr.read()}")
        self.url = match[1]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        self.proc.communicate(timeout=30)


def cpu_mark(pid: int) -> tuple[float, float, float]:
    """(monotonic time, process CPU s, main thread CPU s)."""
    return time.monotonic(), cpu_s(pid), cpu_s(pid, pid)


def rates(a: tuple, b: tuple) -> dict:
    wall = b[0] - a[0]
    return {"cpu": (b[1] - a[1]) / wall, "main_cpu": (b[2] - a[2]) / wall, "wall_s": wall}


async def measure(device: Device, seconds: float, warmup_s: float, clients: int) -> dict:
    """In one device process: its CPU over `seconds` with its loop alone, then (when
    `clients`) over `seconds` while they stream every signal at every tick."""
    from astcom_client import Client

    pid = device.proc.pid
    await asyncio.sleep(warmup_s)
    a = cpu_mark(pid)
    await asyncio.sleep(seconds)
    out = {"idle": rates(a, cpu_mark(pid))}
    if not clients:
        await asyncio.to_thread(device.stop)
        return out
    conns, streams = [], []
    for i in range(clients):
        client = await Client.connect(device.url, password=PASSWORD, name=f"bench{i}",
                                      queue_packets=65_536)
        stream = await client.stream(NAMES, rate_hz=LOOP_RATE_HZ)
        stream.on_packet(lambda packet: None)  # count only (the Stream keeps totals)
        conns.append(client)
        streams.append(stream)
    await asyncio.sleep(warmup_s)
    samples0, a = [s.samples for s in streams], cpu_mark(pid)
    await asyncio.sleep(seconds)
    samples1, b = [s.samples for s in streams], cpu_mark(pid)
    out["busy"] = rates(a, b)
    out["busy"].update(
        values_per_s=sum(y - x for x, y in zip(samples0, samples1, strict=True)) * N_SIGNALS
        / (b[0] - a[0]),
        lost=sum(s.lost for s in streams), dropped=(await conns[0].stats())["dropped_samples"])
    # the device stops first (its lateness window ends while it still streams)
    await asyncio.to_thread(device.stop)
    for client in conns:
        await client.close()
    return out


def run_c(seconds: float, warmup_s: float, clients: int, stats: Path, rt: int = 0) -> dict:
    """The C device; its tick lateness counted over the last window (idle or streaming)."""
    counted_after = warmup_s + (seconds + warmup_s if clients else 0.0)
    device = Device([str(C_DEVICE), "--tcp", "127.0.0.1:0", "--rate", f"{LOOP_RATE_HZ:g}",
                     "--extra", str(N_SIGNALS), "--password", PASSWORD, "--stats", str(stats),
                     "--warmup", f"{counted_after:g}", "--rt-priority", str(rt)])
    try:
        out = asyncio.run(measure(device, seconds, warmup_s, clients))
    finally:
        device.stop()
    out["loop"] = json.loads(stats.read_text())
    return out


def run_python(seconds: float, warmup_s: float, clients: int) -> dict:
    device = Device([sys.executable, "-c", PYTHON_DEVICE])
    try:
        return asyncio.run(measure(device, seconds, warmup_s, clients))
    finally:
        device.stop()


def per_10k(run: dict, key: str = "cpu") -> float:
    """Streaming CPU (fraction of a core) per 10 000 values/s received."""
    return (run["busy"][key] - run["idle"][key]) / (run["busy"]["values_per_s"] / 10_000.0)


def rt_permitted() -> bool:
    return subprocess.run(["chrt", "-f", "1", "true"], capture_output=True).returncode == 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="each measured window")
    parser.add_argument("--warmup", type=float, default=2.0, help="seconds before each window")
    parser.add_argument("--clients", type=int, default=4)
    args = parser.parse_args()
    build = subprocess.run(["make", "-s", "-C", str(ROOT / "astcom_device"), "host"],
                           capture_output=True, text=True)
    if build.returncode:
        sys.exit(f"building the C device failed:\n{build.stdout}{build.stderr}")
    rt = 50 if rt_permitted() else 0
    with tempfile.TemporaryDirectory() as tmp:
        c_idle = run_c(args.seconds, args.warmup, 0, Path(tmp) / "idle.json")
        c = run_c(args.seconds, args.warmup, args.clients, Path(tmp) / "busy.json")
        py = run_python(args.seconds, args.warmup, args.clients)
        if rt:
            rt_idle = run_c(args.seconds, args.warmup, 0, Path(tmp) / "rt-idle.json", rt)
            rt_busy = run_c(args.seconds, args.warmup, args.clients, Path(tmp) / "rt-busy.json", rt)
    load = os.getloadavg()[0]
    print(f"{N_SIGNALS} f64 signals at {LOOP_RATE_HZ:g} Hz to {args.clients} TCP clients, "
          f"{args.seconds:g} s windows, loop alone then streaming in the same process "
          f"(load average {load:.1f} on {os.cpu_count()} CPUs)")
    for name, run in (("C device (-O2)", c), ("Python endpoint", py)):
        idle, busy = run["idle"], run["busy"]
        print(f"  {name:16s}: loop alone {100 * idle['cpu']:5.2f} % of a core, streaming "
              f"{100 * busy['cpu']:5.2f} %, {busy['values_per_s'] / 1e3:7.1f} k values/s "
              f"received, lost {busy['lost']}, dropped {busy['dropped']}")
    print(f"  C device's communication thread: loop alone {100 * c['idle']['main_cpu']:.2f} %, "
          f"streaming {100 * c['busy']['main_cpu']:.2f} % (its tick thread does the same work "
          "either way)")
    # the C device streams from its communication thread (the main one)
    c_cost, c_whole, py_cost = per_10k(c, "main_cpu"), per_10k(c), per_10k(py)
    ratio = c_cost / py_cost if py_cost > 0 else float("nan")
    print(f"CPU per 10 000 streamed values/s: C {100 * c_cost:.4f} % of a core (its whole "
          f"process: {100 * c_whole:.4f} %), Python {100 * py_cost:.4f} %; C/Python = "
          f"{ratio:.3f} (whole process: {c_whole / py_cost:.3f}; goal <= 1/5 = 0.2: "
          f"{'met' if ratio <= 0.2 else 'NOT met'})")
    rows = [("idle loop", c_idle["loop"]), ("streaming 16x10 kHz", c["loop"])]
    if rt:
        rows += [(f"idle, SCHED_FIFO {rt}", rt_idle["loop"]),
                 (f"streaming, SCHED_FIFO {rt}", rt_busy["loop"])]
    print("C tick lateness (µs)            p50    p99  p99.9       max   skipped ticks")
    for name, loop in rows:
        print(f"  {name:28s} {loop['late_p50_us']:5.0f} {loop['late_p99_us']:6.0f} "
              f"{loop['late_p999_us']:6.0f} {loop['late_max_us']:9.1f}   {loop['skipped_ticks']}")
    print(f"tick lateness p99 while streaming: {c['loop']['late_p99_us']:.0f} µs "
          f"(idle loop: {c_idle['loop']['late_p99_us']:.0f} µs, same run)"
          + (f"; with the tick thread SCHED_FIFO: {rt_busy['loop']['late_p99_us']:.0f} µs "
             f"(idle {rt_idle['loop']['late_p99_us']:.0f} µs)" if rt else ""))


if __name__ == "__main__":
    main()
