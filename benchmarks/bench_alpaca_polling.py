"""How often the VSS reads an Alpaca driver, and what that costs, at rest and moving.

    python benchmarks/bench_alpaca_polling.py [--phase-s 15]

On ASCOM's alpaca-simulators (setup/45-mount-simulators.sh), served as the backend tests
serve it, inside a private network namespace. The VSS's link to it (`RateMountLink` over
`AlpacaDriver`, in this process) is held in three states for `--phase-s` each: holding a
place (tracking off, at rest), tracking by the mount's own sidereal tracking (no rates:
a star held as the rate loop leaves it), and moving at a commanded MoveAxis rate (30″/s).
Each state is measured twice in the same run on the same simulator: with the paced reads
(`poll_pace`: fast while latency matters, `rest_poll_s` at rest) and — the reference —
with the fixed pace the VSS had before (`poll_s` always). Printed: reads a second (three
requests each), the simulator's CPU (its process, from /proc) and this process's (the
link's) CPU, as a share of one core.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "backends"))
sys.path.insert(0, str(ROOT))

TICK_S = os.sysconf("SC_CLK_TCK")
SETTLE_S = 3.0  # after a change of state: the hold of fast reads (2 s) and a margin


def cpu_s(pid: int) -> float:
    """utime + stime of a process, seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK_S


async def measure(link, sim_pid: int, phase_s: float) -> dict:
    reads, sim0, own0, t0 = link.stats.reads, cpu_s(sim_pid), time.process_time(), \
        time.monotonic()
    await asyncio.sleep(phase_s)
    wall = time.monotonic() - t0
    return {"reads_hz": (link.stats.reads - reads) / wall,
            "sim_cpu": (cpu_s(sim_pid) - sim0) / wall,
            "link_cpu": (time.process_time() - own0) / wall,
            "state": link.state_name()}


async def inner(phase_s: float) -> list[tuple[str, str, dict]]:
    from backend_scenario import Simulator

    from virtualstar.astro import EarthOrientation, Site
    from virtualstar.astro.constants import ARCSEC_PER_RAD
    from virtualstar.server.backends.alpaca import AlpacaDriver
    from virtualstar.server.backends.rate_mount import RateLinkConfig, RateMountLink

    out = Path(tempfile.mkdtemp(prefix="bench-alpaca-polling-"))
    sim = Simulator("alpaca", out)
    sim.start()
    site = Site(lat_deg=-30.0, lon_deg=70.0, height_m=1500.0)
    driver = AlpacaDriver(sim.url)
    link = RateMountLink(driver, RateLinkConfig(sim.url, site,
                                                EarthOrientation.from_astropy_iers_data()),
                         backend="alpaca")
    rows = []
    try:
        link.start()
        await link.wait_connected(120)
        await link.wait_report(0, 10)
        await link.call("power_on")  # the simulator starts parked
        for pace in ("paced", "fixed"):
            # the reference: the rest pace is the fast one (as before poll_pace)
            link.pace.rest_s = driver.rest_poll_s if pace == "paced" else driver.poll_s
            await link.call("stop")  # tracking off, no rates: holding
            await asyncio.sleep(SETTLE_S)
            rows.append(("holding (tracking off)", pace,
                         await measure(link, sim.proc.pid, phase_s)))
            await link.call("set_rates", 0.0, 0.0)  # tracking on, no rates
            await asyncio.sleep(SETTLE_S)
            rows.append(("tracking by the mount", pace,
                         await measure(link, sim.proc.pid, phase_s)))
            await link.call("set_rates", 30.0 / ARCSEC_PER_RAD, 0.0)
            await asyncio.sleep(SETTLE_S)
            rows.append(("moving at 30″/s (MoveAxis)", pace,
                         await measure(link, sim.proc.pid, phase_s)))
        await link.call("stop")
    finally:
        await link.stop()
        sim.stop()
    return rows


def report(rows) -> None:
    print(f"{'state':28} {'pace':7} {'reads/s':>8} {'requests/s':>11} {'simulator CPU':>14} "
          f"{'link CPU':>9}")
    for state, pace, m in rows:
        print(f"{state:28} {pace:7} {m['reads_hz']:8.1f} {3 * m['reads_hz']:11.1f} "
              f"{100 * m['sim_cpu']:13.1f}% {100 * m['link_cpu']:8.1f}%")
    by = {(s, p): m for s, p, m in rows}
    for state in dict.fromkeys(s for s, _p, _m in rows):
        a, b = by[(state, "paced")], by[(state, "fixed")]
        print(f"{state}: paced {a['reads_hz']:.1f} reads/s vs fixed {b['reads_hz']:.1f} "
              f"(×{a['reads_hz'] / max(b['reads_hz'], 1e-9):.2f}); simulator + link CPU "
              f"{100 * (a['sim_cpu'] + a['link_cpu']):.1f}% vs "
              f"{100 * (b['sim_cpu'] + b['link_cpu']):.1f}% of a core")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--phase-s", type=float, default=15.0, help="seconds measured per state")
    ap.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.inner:
        report(asyncio.run(inner(args.phase_s)))
        return
    try:
        import alpaca_simulators  # noqa: F401
    except ImportError:
        sys.exit("alpaca-simulators is not installed (setup/45-mount-simulators.sh)")
    # the simulator stays inside a private network namespace (as in the backend tests)
    # (a network namespace only: the simulator's CPU is read from /proc by its pid)
    cmd = ["unshare", "-n", "sh", "-c",
           'ip link set lo up && exec "$0" "$@"', sys.executable, __file__, "--inner",
           "--phase-s", str(args.phase_s)]
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) before the run", flush=True)
    sys.exit(subprocess.run(cmd).returncode)


if __name__ == "__main__":
    main()
