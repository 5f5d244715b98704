"""Benchmark: a whole 10-hour night run end to end on the emulator in lockstep (`vs run`).

    .venv/bin/python benchmarks/bench_run_night.py [--hours 10]

The night and the program are those of bench_plan_vs_astroplan.py (SAAO Sutherland,
2024-05-17 17:40 to 2024-05-18 03:40 UTC, 40 bright stars and 6 satellite passes near
the bundled elements' epoch): planned with `plan_program`, then run through the VSS API
(`run_plan`) on the embedded emulator in lockstep simulated time, as fast as the CPU
allows (`vs run PLAN --emulator --speed max`). --hours shortens the window (a quick look).

Printed: the wall time beside the goal (≤ 3 min on the project's 2-core machine) and beside
the reference measured in the same run: the emulator's compiled 10 kHz step alone for
the same mount time (bench_vss_lockstep's measure), the floor of any lockstep night; then
every block's outcome, delay, slew time and errors: on target (the boresight against the
target's true place, RMS and peak), the planned deviation's peak, the encoders' following
error (RMS and peak). The CPU seconds are printed too: the figure to read on a loaded host.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_plan_vs_astroplan import (  # noqa: E402 - the same night as the planning benchmark
    END,
    SITE,
    START,
    pick_stars,
    target_table,
    write_program,
)
from bench_vss_lockstep import bare_emulator_s_per_mount_s  # noqa: E402

from virtualstar.astro import EarthOrientation, UtcTimes  # noqa: E402
from virtualstar.planning import PlanRequest, load_program, plan_program  # noqa: E402
from virtualstar.planning.emulated import EMULATOR_LEAD_S, run_plan_on_emulator  # noqa: E402

GOAL_WALL_S = 180.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=10.0)
    args = parser.parse_args()
    eop = EarthOrientation.from_astropy_iers_data()
    t0, t1 = (int(x) for x in UtcTimes.from_iso([START, END]).to_unix_us())
    t1 = min(t1, t0 + int(args.hours * 3.6e9))
    with tempfile.TemporaryDirectory() as folder:
        program = load_program(write_program(Path(folder), target_table(pick_stars(40, eop))))
        plan = plan_program(PlanRequest(program, t0, t1, SITE), eop)
    mount_s = (t1 - t0) / 1e6 + EMULATOR_LEAD_S
    print(f"{SITE.name}, {UtcTimes.from_unix_us(t0).iso(0)[0]} .. "
          f"{UtcTimes.from_unix_us(t1).iso(0)[0]}: {len(plan.blocks)} blocks planned "
          f"({sum(b.kind == 'satellite' for b in plan.blocks)} satellite passes), "
          f"{plan.weighted_hours:.2f} priority-weighted hours")
    wall0, cpu0 = time.perf_counter(), time.process_time()
    result = run_plan_on_emulator(plan.as_dict(), site=SITE)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    bare_wall, bare_cpu = (x * mount_s for x in bare_emulator_s_per_mount_s())
    s = result["summary"]
    print(f"\nrun: {result['state']}, {s['done']} done, {s['degraded']} degraded, {s['late']} late, "
          f"{s['missed']} missed, {s['faulted']} faulted, {len(result['replans'])} re-plans; "
          f"{s['priority_weighted_hours']:.2f} priority-weighted hours on target")
    print(f"wall time {wall:.1f} s for {mount_s / 3600:.2f} h of mount time "
          f"({mount_s / wall:.0f}× real time); goal ≤ {GOAL_WALL_S:.0f} s: "
          f"{'MET' if wall <= GOAL_WALL_S else 'NOT MET'}; {cpu:.1f} s of CPU")
    print(f"  reference: the emulator's step alone for the same mount time {bare_wall:.1f} s "
          f"wall, {bare_cpu:.1f} s CPU; the VSS and the run add {cpu - bare_cpu:.1f} s CPU "
          f"({(cpu - bare_cpu) / mount_s * 1e3:.2f} ms per mount second)")
    print(f"\n{'start UTC':9} {'block':28} {'outcome':8} {'late s':>6} {'slew s':>6} "
          f"{'on RMS″':>9} {'on peak″':>9} {'plan pk″':>9} {'fol RMS″':>9} {'fol peak″':>9}")
    for r in result["records"]:
        def f(v, fmt=".4f"):
            return "-" if v is None else format(v, fmt)

        print(f"{(r['start_utc'] or r['planned_start_utc'])[11:19]:9} "
              f"{r['target'] + ' #' + str(r['repeat']):28} {r['outcome']:8} "
              f"{f(r['delay_s'], '.1f'):>6} {f(r['slew_s'], '.1f'):>6} "
              f"{f(r['on_target_rms_arcsec']):>9} {f(r['on_target_peak_arcsec']):>9} "
              f"{f(r['planned_deviation_peak_arcsec']):>9} {f(r['encoder_rms_arcsec']):>9} "
              f"{f(r['encoder_peak_arcsec']):>9}")
    executed = s["done"] + s["late"] + s["degraded"]
    print(f"\nevery block executed: {'yes' if executed == len(result['records']) else 'no'} "
          f"({executed} of {len(result['records'])})")


if __name__ == "__main__":
    main()
