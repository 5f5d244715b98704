"""Real time: CPU share of one core used by the emulator at 10 kHz, idle and streaming.

Goal (issue 3): <= 15 % of one core with and without streaming 16 signals at 10 kHz
to one client. The emulator runs as the real `mount-emulator` process; its CPU
time is read from /proc. Printed beside a reference measured in the same run: a
bare asyncio process waking on the same 2 ms period (the floor of any Python
loop), and the tick rate the emulator kept against the wall clock.

    .venv/bin/python benchmarks/bench_emulator_realtime.py
"""

from __future__ import annotations

import asyncio
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from astcom_client import Client

SECONDS = 5.0
BIN = Path(sys.executable).parent
SIGNALS = [f"axis.{a}.{s}" for a in ("az", "el") for s in (
    "position", "velocity", "error_arcsec", "current", "reference", "torque", "temperature",
    "load_error_arcsec")]
IDLE_LOOP = "import asyncio\nasync def m():\n    while True: await asyncio.sleep(0.002)\nasyncio.run(m())"


def cpu_seconds(pid: int) -> float:
    """Return user + system CPU seconds of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def share(pid: int, seconds: float) -> float:
    c0, t0 = cpu_seconds(pid), time.monotonic()
    time.sleep(seconds)
    return (cpu_seconds(pid) - c0) / (time.monotonic() - t0)


async def streaming_share(pid: int, url: str) -> tuple[float, int, int, float]:
    async with await Client.connect(url) as client:
        t_start = (await client.read(["mount.tick"]))["mount.tick"]
        stream = await client.stream(SIGNALS, rate_hz=10_000)
        samples = lost = 0
        c0, w0 = cpu_seconds(pid), time.monotonic()
        async for packet in stream:
            samples += len(packet.t_us)
            lost += packet.lost
            if time.monotonic() - w0 >= SECONDS:
                break
        cpu = (cpu_seconds(pid) - c0) / (time.monotonic() - w0)
        await stream.stop()
        t_end = (await client.read(["mount.tick"]))["mount.tick"]
        rate = (t_end - t_start) / (time.monotonic() - w0 + 1e-9)
        return cpu, samples, lost, rate


def main() -> None:
    proc = subprocess.Popen([str(BIN / "mount-emulator"), "--port", "0", "--seed", "1"],
                            stdout=subprocess.PIPE, text=True)
    idle = subprocess.Popen([sys.executable, "-c", IDLE_LOOP])
    try:
        url = re.search(r"ws://\S+", proc.stdout.readline()).group(0)
        time.sleep(2.0)  # past start-up (imports, loading the compiled step)
        quiet = share(proc.pid, SECONDS)
        floor = share(idle.pid, SECONDS)
        busy, samples, lost, rate = asyncio.run(streaming_share(proc.pid, url))
    finally:
        for p in (proc, idle):
            p.terminate()
            p.wait(timeout=10)
    print("mount emulator, real time at 10 kHz (CPU share of one core, goal <= 15 %)")
    print(f"  no client                          {quiet * 100:6.1f} %")
    print(f"  streaming {len(SIGNALS)} signals at 10 kHz      {busy * 100:6.1f} %   "
          f"({samples} samples in {SECONDS:g} s, {lost} lost, loop kept {rate:,.0f} ticks/s)")
    print(f"  reference: bare asyncio loop, 2 ms {floor * 100:6.1f} %")


if __name__ == "__main__":
    main()
