"""Benchmark: `vs data anomalies` — precision and recall over faults injected into emulator
recordings at known times and sizes (goal ≥ 0.9 both over ≥ 20 cases), and the run time
on the 12-hour night store (goal ≤ 60 s).

Cases: each of six degradations (docs/mount-emulator.md, "Fault injection") at four
sizes, on the azimuth or the elevation sine experiment (`vs experiment sine`, simulated
time, recorded at 1 kHz through the ASTCom stream path), injected at a seeded random
time after the 15-minute reference stretch; plus clean recordings of both axes. A fault
is found when an anomaly of its kind overlaps its window (injection to the end, or to
the end of a glitch burst); an anomaly is true when it overlaps a fault's window
(starting up to one 60-s window early). Precision = true anomalies / anomalies (clean
recordings count: any flag there is false); recall = faults found / faults.

The night store is the one `benchmarks/bench_recorder_night.py` measures (the sine
experiment, 12 h, 3 signals at 1 kHz: 43 M rows); its run time is printed beside reading
every sample of the store once with pyarrow (the I/O floor) in the same run.

    .venv/bin/python benchmarks/bench_anomalies.py [--minutes 30] [--hours 12] [--night DIR]
"""

from __future__ import annotations

import argparse
import asyncio
import random
import shutil
import tempfile
import time
from pathlib import Path

from virtualstar.anomalies import detect_anomalies
from virtualstar.anomalies.scoring import InjectedFault, Scores, score_detections
from virtualstar.recorder.experiment import Injection, SineExperiment, run_sine_experiment
from virtualstar.recorder.parquet_store import ParquetStoreReader

GOAL_PRECISION = 0.9
GOAL_RECALL = 0.9
GOAL_NIGHT_S = 60.0
EARLY_US = 60_000_000
GLITCH_BURST_S = 60.0

# kind flagged, parameter (axis filled in), sizes, unit
DEGRADATIONS = [
    ("current", "axis.{ax}.inject_winding_fault", (0.15, 0.2, 0.25, 0.3), "of kt lost"),
    ("current", "axis.{ax}.inject_friction_growth", (3.0, 4.0, 6.0, 8.0), "N·m/h"),
    ("vibration", "axis.{ax}.inject_resonance_growth", (1.0, 2.0, 3.0, 5.0), "N·m/h"),
    ("spike", "axis.{ax}.inject_encoder_glitch_counts", (100.0, 200.0, 300.0, 500.0),
     "counts, 2/s for 60 s"),
    ("temperature", "axis.{ax}.inject_heat_growth", (20.0, 30.0, 40.0, 60.0), "W/h"),
    ("clock", "time.inject_drift_growth", (5.0, 8.0, 10.0, 15.0), "ppm/h"),
]


def _cases(minutes: float, seed: int) -> list[tuple[str, str, str, float, float]]:
    """Return (label, kind, axis, parameter, size, at_s) of every case."""
    rng = random.Random(seed)
    out = []
    for kind, param, sizes, unit in DEGRADATIONS:
        for i, size in enumerate(sizes):
            ax = "az" if i % 2 == 0 else "el"
            at_s = rng.uniform(15 * 60 + 30, minutes * 60 * 0.75)
            out.append((f"{param.format(ax=ax)}={size:g} {unit}", kind, ax,
                        param.format(ax=ax), size, at_s))
    return out


def _injections(kind: str, param: str, size: float, at_s: float, ax: str) -> tuple:
    if kind == "spike":
        rate = f"axis.{ax}.inject_encoder_glitches"
        return (Injection(at_s, param, size), Injection(at_s, rate, 2.0),
                Injection(at_s + GLITCH_BURST_S, rate, 0.0))
    return (Injection(at_s, param, size),)


def _run(out: Path, axis: str, minutes: float, injections: tuple) -> tuple[Path, int, float]:
    exp = SineExperiment(axis=axis, hours=minutes / 60, injections=injections,
                         extra_names=(f"axis.{axis}.temperature",))
    start = time.perf_counter()
    result = asyncio.run(run_sine_experiment(exp, out, plots=False))
    return result.store, result.trajectory_t0_us, time.perf_counter() - start


def _detect(store: Path):
    reader = ParquetStoreReader(store)
    a, b = reader.time_range()
    return detect_anomalies(reader, a, b + 1), b + 1


def _night(path: Path | None, hours: float, workdir: Path) -> tuple[Path, float]:
    if path is not None:
        return path, 0.0
    start = time.perf_counter()
    result = asyncio.run(run_sine_experiment(SineExperiment(hours=hours), workdir / "night",
                                             plots=False))
    return result.store, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="length of each case")
    parser.add_argument("--hours", type=float, default=12.0, help="the night store (paper: 12)")
    parser.add_argument("--night", type=Path, default=None,
                        help="an existing night store (parquet directory) to time instead")
    parser.add_argument("--seed", type=int, default=19)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-anomalies-"))
    try:
        total = Scores(0, 0, 0, 0)
        record_s = 0.0
        print(f"{'case':<62} {'found':>6} {'flags':>6} {'true':>5}  first flag after injection")
        for n, (label, kind, ax, param, size, at_s) in enumerate(_cases(args.minutes, args.seed)):
            store, t0, took = _run(work / f"case-{n}", ax, args.minutes,
                                   _injections(kind, param, size, at_s, ax))
            record_s += took
            report, end = _detect(store)
            until = t0 + round((at_s + GLITCH_BURST_S) * 1e6) if kind == "spike" else end
            fault = InjectedFault(kind, "" if kind == "clock" else ax,
                                  t0 + round(at_s * 1e6), until)
            s = score_detections(report.anomalies, [fault], early_us=EARLY_US)
            total = total + s
            hits = [a for a in report.anomalies if a.kind == fault.kind]
            delay = (f"{(min(a.start_us for a in hits) - fault.start_us) / 1e6:+.0f} s"
                     if hits else "-")
            print(f"{label:<62} {s.found:>6} {s.anomalies:>6} {s.true_anomalies:>5}  {delay}")
            shutil.rmtree(work / f"case-{n}", ignore_errors=True)
        for k, ax in enumerate(("az", "el", "az", "el")):
            store, _, took = _run(work / f"clean-{k}", ax, args.minutes, ())
            record_s += took
            report, _ = _detect(store)
            total = total + score_detections(report.anomalies, [])
            print(f"{'clean ' + ax:<62} {'-':>6} {len(report.anomalies):>6} {0:>5}")
            shutil.rmtree(work / f"clean-{k}", ignore_errors=True)

        night, build_s = _night(args.night, args.hours, work)
        reader = ParquetStoreReader(night)
        start = time.perf_counter()
        rows = sum(len(b) for b in reader.iter_blocks(batch_rows=1 << 20))
        read_s = time.perf_counter() - start
        start = time.perf_counter()
        report, _ = _detect(night)
        night_s = time.perf_counter() - start
        hours = (report.to_t_us - report.from_t_us) / 3.6e9

        print()
        print(f"{'':<30} {'ours':>10} {'goal':>8}   reference (same run)")
        print(f"{'precision':<30} {total.precision:>10.3f} {GOAL_PRECISION:>8}   "
              f"{total.true_anomalies} true of {total.anomalies} anomalies")
        print(f"{'recall':<30} {total.recall:>10.3f} {GOAL_RECALL:>8}   "
              f"{total.found} of {total.faults} injected faults found "
              f"({args.minutes:g}-min recordings, recorded in {record_s:.0f} s)")
        print(f"{f'night store ({hours:.1f} h, {rows / 1e6:.1f} M rows)':<30} "
              f"{night_s:>8.1f} s {GOAL_NIGHT_S:>6.0f} s   reading every sample once with "
              f"pyarrow: {read_s:.1f} s; {len(report.anomalies)} anomalies on this clean "
              f"night; read+reduce {report.timings_s['read_and_reduce']:.1f} s, detect "
              f"{report.timings_s['detect']:.1f} s"
              + (f"; building the store took {build_s:.0f} s" if build_s else ""))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
