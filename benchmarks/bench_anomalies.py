"""Benchmark: `vs data anomalies` on VSS nights — precision and recall per kind of fault, on
nights used for tuning and on nights that were not (goal ≥ 0.9 both, 0 flags on clean
nights), and the run time on a 12-hour night store (goal ≤ 60 s).

Nights: `vs run --emulator --record` (here its library call, run_plan_on_emulator)
runs a generated program through the VSS on the embedded emulator in lockstep, recorded
at 1 kHz (position, current, error_arcsec, temperature of both axes) with the
emulator's and the VSS's events. A program (one per pattern, from a seed) holds 8 bright
stars of 2.5–12-minute blocks, a block 1.5–3° from the zenith, a block at 12–24°
elevation and every satellite of catalogs/data/visual.tle (July 2021 elements); its
40-minute window at the default site starts 4–8 minutes before a satellite pass, so the
automatic 15-minute reference holds slews, sidereal tracking and a pass. Each pattern
is run clean (a clean night) and once per kind of fault, each time with one fault,
injected after the reference: in the middle of a slew, three minutes into a satellite
pass, or at a random moment of a sidereal track (cycled), at one of four sizes from
about the detection limit to three times it (cycled over the patterns).

Scoring (virtualstar.anomalies.scoring): a flag is true only when it overlaps the
fault's window (the injection to the end of the night; a glitch burst's 60 s) by its
kind and axis, beginning at most one detector window before the injection; a fault is
found when a true flag exists. Every flag on a clean night is false.

Tuning set: the patterns the detectors were developed and their limits set on
(TUNING_SEEDS; 11–15, 21–25, 31–35, 36–40 and then 41–45 were check sets, but each was
seen before a later change to the detectors, so they count as tuning now); the other set
(CHECK_SEEDS, 46–50) was recorded before those changes and scored only to report, after the
detectors were final. The 12-hour store is one more pattern
(720 minutes, seed 100); its run time is printed beside reading every sample of the
store once with pyarrow (the I/O floor), in the same run.

    .venv/bin/python benchmarks/bench_anomalies.py [--patterns 5] [--sets tuning,check,night]
        [--night DIR] [--keep DIR]
    .venv/bin/python benchmarks/bench_anomalies.py --rescore DIR   # kept stores, scored again
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from catalogs import bright_stars, load_tle_file, sample_tle_path
from virtualstar.anomalies import DetectorConfig, detect_anomalies
from virtualstar.anomalies.live import LiveAnomalies
from virtualstar.anomalies.phases import MotionPhase, PhaseConfig, PhaseLabeller
from virtualstar.anomalies.report import read_segments
from virtualstar.anomalies.scoring import InjectedFault, matches
from virtualstar.astro import (
    EarthOrientation,
    IcrsStar,
    Satellite,
    UtcTimes,
    load_site,
    observe_mount_times,
)
from virtualstar.astro.events import satellite_passes
from virtualstar.planning import PlanRequest, load_program, plan_program
from virtualstar.planning.emulated import TimedWrite, run_plan_on_emulator
from virtualstar.planning.recording import RunRecording
from virtualstar.recorder.parquet_store import ParquetStoreReader, utc_text

GOAL_PRECISION = 0.9
GOAL_RECALL = 0.9
GOAL_NIGHT_S = 60.0
TUNING_SEEDS = (1, 2, 3, 4, 5, 11, 12, 13, 14, 15, 21, 22, 23, 24, 25, 31, 32, 33, 34, 35,
                36, 37, 38, 39, 40, 41, 42, 43, 44, 45)
CHECK_SEEDS = (46, 47, 48, 49, 50)
NIGHT_SEED = 100
NIGHT_MINUTES = 40.0
SIGNALS = tuple(f"axis.{ax}.{s}" for ax in ("az", "el")
                for s in ("position", "current", "error_arcsec", "temperature"))
GLITCH_BURST_S = 60.0
SETTLE_BINS_S = (0, 1, 2, 3, 5, 7, 10, 15, 20, 30, 60)
WHERE = ("slew", "pass", "tracking")
CFG = DetectorConfig()
# a flag may begin up to one of its detector's windows before the injection
EARLY_S = {"current": CFG.current_window_s, "vibration": CFG.vibration_window_s,
           "spike": 1.0, "temperature": CFG.temperature_window_s,
           "clock": CFG.clock_window_s}

# kind flagged, parameter ({ax}: the axis), four sizes from about the detection limit in
# the ten minutes or more a fault has after the reference, to about three times it
DEGRADATIONS = [
    ("current", "axis.{ax}.inject_winding_fault", (0.06, 0.09, 0.13, 0.2), "of kt lost"),
    ("current", "axis.{ax}.inject_friction_growth", (1.5, 2.5, 3.5, 5.0), "N·m/h"),
    ("vibration", "axis.{ax}.inject_resonance_growth", (3.0, 4.5, 6.0, 9.0), "N·m/h"),
    ("spike", "axis.{ax}.inject_encoder_glitch_counts", (30.0, 50.0, 80.0, 150.0),
     "counts, 2/s for 60 s"),
    ("temperature", "axis.{ax}.inject_heat_growth", (12.0, 18.0, 25.0, 40.0), "W/h"),
    ("clock", "time.inject_drift_growth", (4.0, 6.0, 8.0, 12.0), "ppm/h"),
]


def _us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


@dataclass
class Sky:
    site: object
    eop: EarthOrientation
    tle: Path


def _passes(sky: Sky, start_us: int, hours: float) -> list[tuple[int, str]]:
    out = []
    a = UtcTimes.from_unix_us(np.array([start_us], np.int64))
    b = UtcTimes.from_unix_us(np.array([start_us + round(hours * 3600e6)], np.int64))
    for rec in load_tle_file(sky.tle):
        sat = Satellite.from_record(rec)
        for p in satellite_passes(sat, sky.site, a, b, min_el_deg=25, eop=sky.eop):
            if p.rise is not None:
                out.append((int(p.rise.utc.to_unix_us()[0]), rec.name.strip()))
    return sorted(out)


def _elevations(sky: Sky, star, t_us: np.ndarray) -> np.ndarray:
    return np.degrees(observe_mount_times(IcrsStar.from_catalog(star), t_us, sky.site,
                                          sky.eop).el_rad)


def program_text(sky: Sky, rng: random.Random, start_us: int, end_us: int) -> str:
    """A program for the window (see the module docstring)."""
    long = end_us - start_us > 4 * 3600e6
    t = np.linspace(start_us, end_us, 7).astype(np.int64)
    stars = [s for s in bright_stars() if s.vmag < 2.6 and s.name]
    els = {s.name: _elevations(sky, s, t) for s in stars}
    high = sorted(n for n, e in els.items() if (e.max() > 40 if long else e.min() > 30))
    rng.shuffle(high)
    high = high[:30 if long else 8]
    low = sorted(n for n, e in els.items() if 12 < e[len(e) // 2] < 24 and n not in high)
    lines = ["[program]", 'name = "benchmark night"', "[defaults]",
             f"sun_max_el_deg = {90 if long else 0}", "min_el_deg = 20", "moon_min_sep_deg = 0"]
    for name in high:
        lines += ["[[target]]", f'star = "{name}"',
                  f"duration_s = {rng.choice([150, 240, 300, 420, 600, 720])}",
                  f"priority = {rng.choice([1, 2, 3])}"]
        if long:
            lines += ["repeats = 3", "cadence_s = 7200"]
    if low:
        lines += ["[[target]]", f'star = "{rng.choice(low)}"',
                  f"duration_s = {rng.choice([180, 300, 420])}", "min_el_deg = 10",
                  "priority = 4"]
    # a point that culminates 1.5–3° from the zenith during the window
    mid = (start_us + end_us) // 2 + rng.randint(-600, 600) * 1_000_000
    dec = sky.site.lat_deg - rng.uniform(1.5, 3.0) * rng.choice([-1, 1])
    ras = np.arange(0.0, 360.0, 0.5)
    el = [float(observe_mount_times(IcrsStar(ra, dec), np.array([mid]), sky.site,
                                    sky.eop).el_rad[0]) for ra in ras]
    lines += ["[[target]]", 'name = "near zenith"',
              f'radec = "{ras[int(np.argmax(el))]:.3f} {dec:.3f}"',
              f"duration_s = {rng.choice([240, 360])}", "min_el_deg = 60", "priority = 4"]
    for rec in load_tle_file(sky.tle):
        name = rec.name.strip()
        lines += ["[[target]]", f'name = "{name}"', 'tle_file = "visual.tle"',
                  f'sat = "{name}"', "priority = 6", f"repeats = {20 if long else 3}",
                  "min_el_deg = 25"]
    return "\n".join(lines) + "\n"


def make_plan(sky: Sky, seed: int, minutes: float, workdir: Path) -> dict:
    """The plan of pattern `seed`: a July 2021 night, starting 4–8 min before a pass, whose
    blocks fill it (a window the program cannot fill — twilight, few stars up — is drawn
    again: the run ends with its last block)."""
    rng = random.Random(seed)
    workdir.mkdir(parents=True, exist_ok=True)
    shutil.copy(sky.tle, workdir / "visual.tle")
    for _ in range(20):
        day = f"2021-07-{rng.randint(15, 30):02d}"
        rises = [t for t, _ in _passes(sky, _us(day + "T19:30:00Z"), 8.0)]
        start = rng.choice(rises) - rng.randint(240, 480) * 1_000_000
        start = start // 60_000_000 * 60_000_000
        end = start + round(minutes * 60e6)
        (workdir / "program.toml").write_text(program_text(sky, rng, start, end))
        plan = plan_program(PlanRequest(load_program(workdir / "program.toml"), start, end,
                                        sky.site), sky.eop).as_dict()
        if plan["blocks"] and plan["blocks"][-1]["end_us"] >= start + 0.85 * (end - start):
            return plan
    raise RuntimeError(f"pattern {seed}: no window in 20 draws that the program fills")


def record(plan: dict, store: Path, writes=()) -> float:
    """Run the plan on the embedded emulator, recorded into `store`; return wall seconds."""
    t0 = time.perf_counter()
    run_plan_on_emulator(plan, record=RunRecording(SIGNALS, 1000.0, (f"parquet:{store}",)),
                         writes=list(writes))
    return time.perf_counter() - t0


def _detect(store: Path):
    reader = ParquetStoreReader(store)
    a, b = reader.time_range()
    return detect_anomalies(reader, a, b + 1), b + 1


def _moments(store: Path, ref_end_us: int, end_us: int, rng: random.Random) -> dict[str, int]:
    """Injection moments after the reference (mount µs): the middle of a slew, three minutes
    into a satellite track, a moment of a sidereal track; read from the clean night's
    events. Each leaves at least 8 minutes of night after it."""
    events = sorted(ParquetStoreReader(store).events(), key=lambda e: e.t_us)
    latest = end_us - 480_000_000
    slews, tracks, start = [], [], None
    for e in events:
        if e.source == "emulator" and e.kind == "state":
            if e.fields.get("new") == "SLEWING":
                start = e.t_us
            elif start is not None:
                slews.append((start + e.t_us) // 2)
                start = None
    for e in events:
        if e.source == "vss" and e.kind == "phase" and e.fields.get("phase") == "tracking":
            tracks.append((e.t_us, e.fields.get("operation_kind")))
    out = {}
    slew = [t for t in slews if ref_end_us + 30e6 < t < latest]
    if slew:
        out["slew"] = rng.choice(slew)
    sat = [t + 180_000_000 for t, kind in tracks if kind == "track_satellite"
           and ref_end_us < t + 180_000_000 < latest]
    if sat:
        out["pass"] = sat[0]
    star = [t for t, kind in tracks if kind == "track" and ref_end_us + 30e6 < t < latest]
    if star:
        out["tracking"] = rng.choice(star) + 60_000_000
    return out


@dataclass
class Case:
    label: str
    kind: str
    axis: str
    writes: list[TimedWrite]
    fault: InjectedFault | None


def cases_of(pattern_index: int, moments: dict[str, int], end_us: int,
             rng: random.Random) -> list[Case]:
    """One faulty night per kind of degradation, sizes and places cycled."""
    out = []
    for k, (kind, param, sizes, unit) in enumerate(DEGRADATIONS):
        size = sizes[(pattern_index + k) % len(sizes)]
        places = [w for w in WHERE if w in moments]
        if not places:
            continue
        where = places[(pattern_index + k) % len(places)]
        at = moments[where]
        ax = "" if kind == "clock" else rng.choice(("az", "el"))
        name = param.format(ax=ax)
        writes = [TimedWrite(at, name, size)]
        until = end_us
        if kind == "spike":
            rate = f"axis.{ax}.inject_encoder_glitches"
            writes += [TimedWrite(at, rate, 2.0),
                       TimedWrite(at + round(GLITCH_BURST_S * 1e6), rate, 0.0)]
            until = at + round(GLITCH_BURST_S * 1e6)
        out.append(Case(f"{name}={size:g} {unit} during a {where}", kind, ax, writes,
                        InjectedFault(kind, ax, at, until)))
    return out


@dataclass
class Tally:
    """Per kind: faults, found; flags, true flags."""

    faults: dict[str, int]
    found: dict[str, int]
    flags: dict[str, int]
    true: dict[str, int]
    clean_nights: int = 0
    clean_flags: int = 0
    settling: dict[int, list[float]] = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        self.settling = {} if self.settling is None else self.settling

    @classmethod
    def empty(cls) -> Tally:
        kinds = [k for k, *_ in DEGRADATIONS]
        return cls(*({k: 0 for k in kinds} for _ in range(4)))

    def add(self, anomalies, fault: InjectedFault | None) -> tuple[int, int]:
        """Count one night; return (flags, true flags)."""
        true = 0
        for a in anomalies:
            self.flags[a.kind] = self.flags.get(a.kind, 0) + 1
            ok = fault is not None and matches(a, fault, round(EARLY_S[a.kind] * 1e6))
            self.true[a.kind] = self.true.get(a.kind, 0) + int(ok)
            true += int(ok)
        if fault is None:
            self.clean_nights += 1
            self.clean_flags += len(anomalies)
        else:
            self.faults[fault.kind] += 1
            self.found[fault.kind] += int(any(
                matches(a, fault, round(EARLY_S[fault.kind] * 1e6)) for a in anomalies))
        return len(anomalies), true

    def totals(self) -> tuple[float, float, int, int, int, int]:
        f, fd = sum(self.faults.values()), sum(self.found.values())
        n, t = sum(self.flags.values()), sum(self.true.values())
        return (t / n if n else 1.0), (fd / f if f else 1.0), t, n, fd, f


def settling(store: Path, into: dict[int, list[float]]) -> None:
    """Add, per bin of seconds since a slew ended, the loudest error band's power above its
    usual level while tracking (log10, per axis, median over the bin's segments): what the
    settle time must leave out (anomalies.phases.PhaseConfig.settle_s)."""
    reader = ParquetStoreReader(store)
    a, b = reader.time_range()
    seg, axes, _ = read_segments(reader, a, b + 1)
    phase = PhaseLabeller(axes, reader.events(), config=PhaseConfig(settle_s=0.0)).label(seg)
    slew = phase == MotionPhase.SLEWING
    since = np.full(len(seg), np.inf)
    for e in np.flatnonzero(slew[:-1] & ~slew[1:]) + 1:
        nxt = np.flatnonzero(slew[e:])
        stop = e + (int(nxt[0]) if len(nxt) else len(seg) - e)
        since[e:stop] = (seg.t_first_us[e:stop] - seg.t_first_us[e]) * 1e-6
    calm = (phase == MotionPhase.TRACKING) | (phase == MotionPhase.REST)
    for ax in axes:
        logp = np.log10(seg.features[f"{ax}.error_band_power"][:, 1:] + 1e-30)
        usual = np.median(logp[calm & (since > 60)], axis=0)
        for k in range(len(SETTLE_BINS_S) - 1):
            rows = calm & (since >= SETTLE_BINS_S[k]) & (since < SETTLE_BINS_S[k + 1])
            if rows.any():
                into.setdefault(k, []).append(float(np.max(np.median(logp[rows], axis=0)
                                                           - usual)))


def print_settling(profile: dict[int, list[float]]) -> None:
    print("\nafter a slew ends (tracking or at rest; loudest error band above its usual power, "
          "median over the clean nights' slews and axes):")
    for k, values in sorted(profile.items()):
        print(f"  {SETTLE_BINS_S[k]:>3}–{SETTLE_BINS_S[k + 1]:<3} s  "
              f"×{10 ** np.median(values):>10,.1f}   (worst ×{10 ** max(values):,.1f})")


def run_set(name: str, seeds, sky: Sky, work: Path, keep: Path | None) -> Tally:
    tally = Tally.empty()
    print(f"\n== {name} nights (seeds {', '.join(map(str, seeds))})")
    print(f"{'night':<66} {'flags':>5} {'true':>5}  first true flag after injection")
    for i, seed in enumerate(seeds):
        plan = make_plan(sky, seed, NIGHT_MINUTES, work / f"plan-{seed}")
        clean = work / f"{seed}-clean"
        wall = record(plan, clean)
        report, end_us = _detect(clean)
        n, _ = tally.add(report.anomalies, None)
        settling(clean, tally.settling)
        ref_end = report.reference.stretches[-1][1]
        blocks = ", ".join(b["target"] for b in plan["blocks"])
        print(f"{f'seed {seed} clean ({blocks})'[:66]:<66} {n:>5} {0:>5}  "
              f"(recorded in {wall:.0f} s)")
        for a in report.anomalies:
            print(f"      false: {a.kind} {a.axis} {utc_text(a.start_us)[11:19]} {a.detail}")
        rng = random.Random(seed * 1000 + 7)
        for case in cases_of(i, _moments(clean, ref_end, end_us, rng), end_us, rng):
            store = work / f"{seed}-{case.label.split('=')[0]}"
            record(plan, store, case.writes)
            report, _ = _detect(store)
            n, t = tally.add(report.anomalies, case.fault)
            hits = [a for a in report.anomalies
                    if matches(a, case.fault, round(EARLY_S[case.kind] * 1e6))]
            delay = (f"{(min(a.start_us for a in hits) - case.fault.start_us) / 1e6:+.0f} s"
                     if hits else "missed")
            print(f"{f'seed {seed}: {case.label}'[:66]:<66} {n:>5} {t:>5}  {delay}")
            for a in report.anomalies:
                if a not in hits:
                    print(f"      false: {a.kind} {a.axis} {utc_text(a.start_us)[11:19]} "
                          f"{a.detail}")
            _keep_or_drop(store, keep, case)
        _keep_or_drop(clean, keep)
    return tally


def _keep_or_drop(store: Path, keep: Path | None, case: Case | None = None) -> None:
    if keep is not None:
        (store / "bench-case.json").write_text(json.dumps(
            {"label": case.label, **case.fault.__dict__} if case else {"label": "clean"}))
        keep.mkdir(parents=True, exist_ok=True)
        shutil.move(str(store), keep / store.name)
    else:
        shutil.rmtree(store, ignore_errors=True)


def rescore(directory: Path) -> dict[str, Tally]:
    """Score the stores of an earlier --keep run again with the detectors as they are now:
    {"tuning", "check", "other"} tallies, by the seed that begins each store's name."""
    tallies = {name: Tally.empty() for name in ("tuning", "check", "other")}
    for case_file in sorted(directory.glob("*/bench-case.json")):
        doc = json.loads(case_file.read_text())
        fault = None if doc["label"] == "clean" else InjectedFault(
            doc["kind"], doc["axis"], doc["start_us"], doc["end_us"])
        seed = case_file.parent.name.split("-")[0]
        name = ("tuning" if seed in map(str, TUNING_SEEDS) else
                "check" if seed in map(str, CHECK_SEEDS) else "other")
        report, _ = _detect(case_file.parent)
        n, t = tallies[name].add(report.anomalies, fault)
        print(f"{case_file.parent.name + ': ' + doc['label']:<66} {n:>5} {t:>5}", flush=True)
        for a in report.anomalies:
            if fault is None or not matches(a, fault, round(EARLY_S[a.kind] * 1e6)):
                print(f"      false: {a.kind} {a.axis} {utc_text(a.start_us)[11:19]} {a.detail}")
    return tallies


def print_tally(name: str, tally: Tally) -> None:
    precision, recall, t, n, fd, f = tally.totals()
    print(f"\n{name}: precision {precision:.3f} ({t} true of {n} flags), recall {recall:.3f} "
          f"({fd} of {f} faults); clean nights: {tally.clean_flags} flags on "
          f"{tally.clean_nights}")
    print(f"  {'kind':<12} {'precision':>10} {'recall':>8}")
    for kind in tally.faults:
        flags, true = tally.flags.get(kind, 0), tally.true.get(kind, 0)
        p = f"{true / flags:.3f}" if flags else "-"
        r = f"{tally.found[kind] / tally.faults[kind]:.3f}" if tally.faults[kind] else "-"
        print(f"  {kind:<12} {p:>10} {r:>8}   ({true}/{flags} flags, "
              f"{tally.found[kind]}/{tally.faults[kind]} faults)")
    if tally.settling:
        print_settling(tally.settling)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patterns", type=int, default=len(CHECK_SEEDS),
                        help="patterns per set (each: one clean and six faulty nights)")
    parser.add_argument("--night", type=Path, default=None,
                        help="an existing 12-hour store (parquet directory) to time instead")
    parser.add_argument("--keep", type=Path, default=None, help="keep the stores here")
    parser.add_argument("--sets", default="tuning,check,night",
                        help="what to run: tuning, check, night (comma-separated)")
    parser.add_argument("--check-seeds", default=",".join(map(str, CHECK_SEEDS)),
                        help="the check set's patterns (comma-separated seeds; seeds never "
                             "scored before make a set not used for tuning)")
    parser.add_argument("--rescore", type=Path, default=None,
                        help="score the stores a --keep run left in this directory again "
                             "(after a change to the detectors) instead of recording")
    args = parser.parse_args()
    if args.rescore is not None:
        for name, tally in rescore(args.rescore).items():
            if tally.clean_nights or sum(tally.faults.values()):
                print_tally(f"{name} stores in {args.rescore}"
                            + (" (not used for tuning)" if name == "check" else ""), tally)
        return
    sets = set(args.sets.split(","))
    sky = Sky(load_site(), EarthOrientation.from_astropy_iers_data(), sample_tle_path("visual"))
    work = Path(tempfile.mkdtemp(prefix="bench-anomalies-"))
    results = {}
    try:
        check_seeds = tuple(int(x) for x in args.check_seeds.split(","))
        for name, seeds in (("tuning", TUNING_SEEDS), ("check", check_seeds)):
            if name in sets:
                results[name] = run_set(name, seeds[:args.patterns], sky, work, args.keep)
        if "night" in sets:
            results["night"] = time_night(args.night, sky, work, args.keep)
        print()
        for name in ("tuning", "check"):
            if name in results:
                print_tally(f"{name} nights" + (" (not used for tuning)" if name == "check"
                                                 else ""), results[name])
        if "night" in results:
            took, read_s, rows, hours, report, build_s, live = results["night"]
            print(f"\n{'':<34} {'ours':>8} {'goal':>6}   reference (same run)")
            print(f"{f'{hours:.1f}-h night store, {rows / 1e6:.1f} M rows':<34} {took:>6.1f} s "
                  f"{GOAL_NIGHT_S:>4.0f} s   reading every sample once with pyarrow: "
                  f"{read_s:.1f} s; read+reduce {report.timings_s['read_and_reduce']:.1f} s, "
                  f"detect {report.timings_s['detect']:.1f} s; {len(report.anomalies)} flags "
                  "on this clean night" + (f"; recorded in {build_s:.0f} s" if build_s else ""))
            for a in report.anomalies:
                print(f"      false: {a.kind} {a.axis} {utc_text(a.start_us)} {a.detail}")
            print(f"{'live, CPU per mount-minute':<34} {live[0] * 1e3:>6.1f} ms in the first hour "
                  f"after the reference, {live[1] * 1e3:.1f} ms in the last; {live[2]} anomalies "
                  "reported")
    finally:
        shutil.rmtree(work, ignore_errors=True)


def time_night(path: Path | None, sky: Sky, work: Path, keep: Path | None):
    build_s = 0.0
    if path is None:
        path = work / "night-12h"
        plan = make_plan(sky, NIGHT_SEED, 720.0, work / "plan-night")
        build_s = record(plan, path)
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            shutil.move(str(path), keep / path.name)
            path = keep / path.name
    reader = ParquetStoreReader(path)
    start = time.perf_counter()
    rows = sum(len(b) for b in reader.iter_blocks(batch_rows=1 << 20))
    read_s = time.perf_counter() - start
    start = time.perf_counter()
    report, _ = _detect(path)
    took = time.perf_counter() - start
    hours = (report.to_t_us - report.from_t_us) / 3.6e9
    return took, read_s, rows, hours, report, build_s, live_costs(reader)


def live_costs(reader) -> tuple[float, float, int]:
    """Feed the store to live detection a mount-minute at a time: the median CPU seconds a
    minute costs in the first hour after the reference and in the last hour, and how many
    anomalies it reported."""
    live = LiveAnomalies([s.name for s in reader.signals()], 1000.0, lambda a: None)
    live.feed_events(reader.events())  # labels use only the events up to their segment
    costs = []
    for block in reader.iter_blocks(batch_rows=60_000):
        start = time.process_time()
        live.feed(block)
        costs.append((live.reference is not None, time.process_time() - start))
    live.finish()
    after = [c for fitted, c in costs if fitted][1:]  # the first holds the reference's fit
    return float(np.median(after[:60])), float(np.median(after[-60:])), len(live.reported)


if __name__ == "__main__":
    main()
