"""Panel: 4 signals streamed at 10 kHz from the mount emulator into the page's plot.

The emulator runs in real time in its own process; `vs panel`'s server hands the built page
to headless chromium (panel/bench/stream.bench.mjs), which connects, streams the signals into
the Plot tab and measures its frame times with requestAnimationFrame. Meanwhile this process
streams the same message with the Python client as the reference count of the same stream.

Run: .venv/bin/python benchmarks/bench_panel_stream.py [--seconds 60] [--rate 10000]
Goal (issue 8): zero lost samples in the page, frame time p95 <= 50 ms.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from astcom_client import Client
from virtualstar.panel import PanelConfig, PanelServer

ROOT = Path(__file__).resolve().parents[1]
PASSWORD = "bench-panel"
SIGNALS = ["axis.az.error", "axis.el.error", "axis.az.current", "axis.el.current"]


def start_emulator() -> tuple[subprocess.Popen, str]:
    """Start the real-time emulator on a free port; return the process and its URL."""
    proc = subprocess.Popen(
        [sys.executable, "-c", "from mount_emulator.cli import main; main()", "--port", "0",
         "--seed", "1", "--password", PASSWORD],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    assert proc.stdout is not None
    for line in proc.stdout:
        match = re.search(r"(ws://\S+)", line)
        if match:
            return proc, match.group(1)
    raise RuntimeError("the emulator did not print its URL")


async def wait_ready(url: str) -> None:
    for _ in range(120):
        try:
            async with await Client.connect(url, password=PASSWORD) as c:
                await c.read(["mount.tick"])
                return
        except (ConnectionError, TimeoutError):
            await asyncio.sleep(0.5)
    raise RuntimeError(f"{url} never answered")


async def run(url: str, panel_url: str, args: argparse.Namespace) -> tuple[dict, dict]:
    ref = {"samples": 0, "lost": 0}
    async with await Client.connect(url, password=PASSWORD, role="observer") as client:
        stream = await client.stream(args.signals, rate_hz=args.rate)

        async def count() -> None:
            async for packet in stream:
                ref["samples"] += packet.n
                ref["lost"] += packet.lost

        t0 = time.monotonic()
        counter = asyncio.create_task(count())
        with tempfile.TemporaryDirectory() as tmp:
            result_path = Path(tmp) / "result.json"
            env = {**os.environ, "PANEL_URL": panel_url, "ASTCOM_URL": url,
                   "ASTCOM_PASSWORD": PASSWORD, "SIGNALS": ",".join(args.signals),
                   "RATE_HZ": str(args.rate), "SECONDS": str(args.seconds),
                   "RESULT": str(result_path)}
            proc = await asyncio.create_subprocess_exec(
                shutil.which("node") or "node", "bench/stream.bench.mjs", cwd=ROOT / "panel",
                env=env, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT)
            out, _ = await proc.communicate()
            page = json.loads(result_path.read_text()) if result_path.exists() else {}
            page.setdefault("log", out.decode(errors="replace"))
        counter.cancel()
        ref["wall_s"] = time.monotonic() - t0
        await stream.stop()
        stats = await client.stats()
    ref["stats_dropped_samples"] = stats["dropped_samples"]
    return page, ref


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="measured streaming time")
    parser.add_argument("--rate", type=float, default=10_000.0, help="stream rate (Hz)")
    parser.add_argument("--signals", nargs="+", default=SIGNALS, help="emulator signals")
    args = parser.parse_args()
    if not Path("/usr/bin/chromium").exists():
        sys.exit("bench_panel_stream: /usr/bin/chromium is missing: run bash setup/30-panel.sh")
    emulator, url = start_emulator()
    try:
        asyncio.run(wait_ready(url))
        with PanelServer(PanelConfig(port=0)) as server:
            page, ref = asyncio.run(run(url, server.start(), args))
    finally:
        emulator.terminate()
        emulator.wait(timeout=10)
    if not page.get("ok"):
        sys.exit(f"bench_panel_stream: the page failed:\n{page.get('error')}\n{page.get('log')}")
    expected = args.rate * page["wall_s"]
    print(f"panel stream: {len(args.signals)} signals at {page['rate_hz']:g} Hz for {page['wall_s']:.1f} s "
          f"(mount emulator in real time, headless chromium, Plot tab shown)")
    print(f"{'':28}{'samples':>10}{'per s':>10}{'lost':>8}")
    print(f"{'page (JS client, plot)':28}{page['samples']:>10}{page['samples'] / page['wall_s']:>10.0f}"
          f"{page['lost_total']:>8}")
    print(f"{'reference (Python client)':28}{ref['samples']:>10}{ref['samples'] / ref['wall_s']:>10.0f}"
          f"{ref['lost']:>8}   (its own window: {ref['wall_s']:.1f} s, page start-up included)")
    print(f"{'expected in the window':28}{expected:>10.0f}{args.rate:>10.0f}")
    print(f"endpoint STATS dropped_samples (all clients): {ref['stats_dropped_samples']}")
    print(f"page frame time: p50 {page['frame_p50_ms']:.1f} ms, p95 {page['frame_p95_ms']:.1f} ms, "
          f"max {page['frame_max_ms']:.1f} ms over {page['frames']} frames; "
          f"{page['plot_updates']} plot redraws of {page['plot_points']} points per series")
    goal = page["lost_total"] == 0 and page["frame_p95_ms"] <= 50
    print(f"goal (0 lost, p95 <= 50 ms): {'met' if goal else 'NOT met'}")


if __name__ == "__main__":
    main()
