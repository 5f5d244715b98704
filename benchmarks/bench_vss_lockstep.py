"""Lockstep simulated time: the demo three times (identical figures?), and an hour of tracking.

1. `vs demo` (slew to Vega, 30 s sidereal, the ISS pass of 2024-05-18 19:51 over
   Poznań) run three times in this process: wall time of each run, and whether
   every phase figure (slew time, RMS and peak, on the encoders and on the sky) is
   identical across the runs — lockstep promises the same result on any host.
2. One hour of sidereal tracking of Vega in lockstep (the real VSS feeding the
   embedded emulator, error stream, TimeS and all): wall time (goal ≤ 15 s on the
   project's 2-core machine), beside the emulator's bare simulated rate measured in
   the same run (its compiled step alone, tracking a trajectory, no VSS), scaled to
   the same hour.

    python benchmarks/bench_vss_lockstep.py [--hours 1.0] [--demo-runs 3]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from virtualstar.astro import UtcTimes, load_site
from virtualstar.demo import DemoConfig, run_demo
from virtualstar.launcher import embedded_vss
from virtualstar.lockstep import LockstepClock, run_lockstep

START = "2024-05-18T19:40:00Z"


def demo_runs(n: int) -> None:
    figures, walls = [], []
    for _ in range(n):
        with tempfile.TemporaryDirectory() as out:
            result = run_demo(DemoConfig(out_dir=Path(out)))
        walls.append(result.wall_s)
        figures.append(json.dumps([p.as_dict() for p in result.phases], sort_keys=True))
    same = all(f == figures[0] for f in figures)
    print(f"vs demo in lockstep, {n} runs: wall {', '.join(f'{w:.1f}' for w in walls)} s; "
          f"phase figures {'identical' if same else 'DIFFERENT'} across the runs")
    for p in json.loads(figures[0]):
        slew = f", slew {p['slew_time_s']:.2f} s" if p["slew_time_s"] else ""
        print(f"  {p['name']:<32} {p['duration_s']:7.1f} s{slew}: on target RMS "
              f"{p['on_target_rms_arcsec']:.4f}″ peak {p['on_target_peak_arcsec']:.3f}″; "
              f"following RMS {p['rms_arcsec']:.4f}″ peak {p['peak_arcsec']:.3f}″; on the sky "
              f"RMS {p['on_sky_rms_arcsec']:.4f}″ peak {p['on_sky_peak_arcsec']:.3f}″ "
              f"(clock offset ≤ {p['clock_offset_us']} µs)")


def hour_of_tracking(hours: float) -> tuple[float, float, dict]:
    clock = LockstepClock(int(UtcTimes.from_iso([START]).to_unix_us()[0]))
    out: dict = {}

    async def main() -> None:
        async with embedded_vss(clock=clock, site=load_site()) as vss:
            vs = vss.client()
            await vs.request("slew", {"star": "Vega"})
            t0, c0, m0 = time.perf_counter(), time.process_time(), clock.now_us
            op = await vs.request("track", {"star": "Vega", "duration_s": hours * 3600.0,
                                            "wait": True})
            out["wall_s"] = time.perf_counter() - t0
            out["cpu_s"] = time.process_time() - c0
            out["mount_s"] = (clock.now_us - m0) / 1e6
            out["op"] = op

    run_lockstep(main(), clock)
    return out["wall_s"], out["mount_s"], out["op"]["info"], out["cpu_s"]


def bare_emulator_s_per_mount_s(seconds: float = 60.0) -> tuple[float, float]:
    """Wall and CPU seconds per mount second of the compiled step alone, tracking."""
    from mount_emulator.model import MountModel

    m = MountModel(start_us=1_716_061_200_000_000)
    m.power_on()
    m.run(1000)
    t0 = m.mount_time_us + 10_000
    n = int(seconds * 20) + 40
    t = t0 + np.arange(n, dtype=np.int64) * 50_000
    s = (t - t[0]) * 1e-6
    m.traj_push(t, 7e-5 * s, 0.35 + 3e-5 * s)
    m.traj_start()
    m.run(5000)
    ticks = int(seconds * 10_000)
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(ticks // 2000):
        m.run(2000)
    mount_s = ticks // 2000 * 2000 / 10_000
    return (time.perf_counter() - start) / mount_s, (time.process_time() - cpu) / mount_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--demo-runs", type=int, default=3)
    args = ap.parse_args()
    demo_runs(args.demo_runs)
    wall, mount_s, info, cpu = hour_of_tracking(args.hours)
    bare_wall, bare_cpu = (x * mount_s for x in bare_emulator_s_per_mount_s())
    print(f"{mount_s / 3600:.2f} h of sidereal tracking (Vega) in lockstep: {wall:.1f} s wall "
          f"({mount_s / wall:.0f}× real time; goal ≤ {15 * args.hours:g} s), on target RMS "
          f"{info['tracking_rms_arcsec']:.4f}″ (following {info['following_rms_arcsec']:.4f}″), "
          f"on the sky {info['on_sky_rms_arcsec']:.4f}″, "
          f"feeder late gaps {info['feeder']['late_gaps']}; {cpu:.1f} s of CPU (the process's, "
          "all threads: the figure to read on a loaded host)")
    print(f"  reference: the emulator's step alone for the same mount time {bare_wall:.1f} s "
          f"wall ({mount_s / bare_wall:.0f}× real time), {bare_cpu:.1f} s CPU; the VSS adds "
          f"{wall - bare_wall:.1f} s wall, {cpu - bare_cpu:.1f} s CPU "
          f"({(cpu - bare_cpu) / mount_s * 1e3:.2f} ms per mount second)")


if __name__ == "__main__":
    main()
