"""Short VSS nights for the anomaly tests: a program run by the VSS on the embedded emulator
in lockstep (`vs run --emulator --record` as a library call), recorded at 1 kHz, with the
emulator's and the VSS's events in the store.

The night (2021-07-21, 01:20–01:48 UTC at the default site, 28 minutes of mount time, of
which the mount stands powered off for the first two): 2-minute blocks of three stars
(Rasalhague at 20° elevation) and of a point 1.8° from the zenith, two satellite passes (ERS-1, culminating at 30°, inside
the automatic 15-minute reference; AJISAI at 78°, after it, cut by the window's end about
4.5 minutes after its fault) and the slews between them. The window ends where the
program's blocks would go on the same (a later end only adds blocks after it), and every
fault of the tests is flagged within two minutes of its injection. Fault injections are
timed from the clean run: in the middle of the first slew after the reference, and three
minutes into the satellite pass after it (the runs are deterministic, so the faulty night
moves exactly as the clean one until the fault begins). The faulty nights are therefore
forked off the clean one (`run_plan_on_emulator(branches=)`) instead of being simulated
again from the start: variants wait at FORK_US, the earliest the automatic reference can
end, and at every minute after it (STANDBY_US), and each faulty night runs in the last
one before its fault; each is
stopped FOUND_WITHIN_S after its fault (twice the two minutes its faults need): the rest
of the night would only cost CPU (a night is ~13 s of it).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

from catalogs import sample_tle_path
from virtualstar.anomalies import DetectorConfig, detect_anomalies
from virtualstar.anomalies.reference import ReferenceConfig
from virtualstar.astro import UtcTimes, load_site
from virtualstar.planning import PlanRequest, load_program, plan_program
from virtualstar.planning.emulated import Branches, TimedWrite, run_plan_on_emulator
from virtualstar.planning.recording import RunRecording
from virtualstar.recorder.parquet_store import ParquetStoreReader

SIGNALS = tuple(f"axis.{ax}.{s}" for ax in ("az", "el")
                for s in ("position", "current", "error_arcsec", "temperature"))
RATE_HZ = 1000.0
FOUND_WITHIN_S = 240.0  # a faulty night runs on this long after its fault, then stops
WINDOW = ("2021-07-21T01:20:00Z", "2021-07-21T01:48:00Z")
PROGRAM = """
[program]
name = "anomaly test night"
[defaults]
duration_s = 120
min_el_deg = 20
sun_max_el_deg = -6
[[target]]
name = "ERS-1"
tle_file = "visual.tle"
sat = "ERS-1"
priority = 5
[[target]]
name = "AJISAI"
tle_file = "visual.tle"
sat = "AJISAI (EGS)"
priority = 5
min_el_deg = 25
[[target]]
star = "Rasalhague"
priority = 4
min_el_deg = 10
[[target]]
star = "Vega"
priority = 3
[[target]]
star = "Deneb"
priority = 3
[[target]]
name = "near zenith"
radec = "337.75 50.9"
priority = 3
min_el_deg = 70
[[target]]
star = "Altair"
priority = 2
"""

# (kind a detector reports, axis, emulator parameters written at the injection (name,
# value, seconds after it)): large enough to be found within minutes; the benchmark goes
# down to the detection limits.
DEGRADATIONS = {
    "winding fault": ("current", "az", (("axis.az.inject_winding_fault", 0.25, 0.0),)),
    "friction rising": ("current", "el", (("axis.el.inject_friction_growth", 10.0, 0.0),)),
    "rattling part": ("vibration", "az", (("axis.az.inject_resonance_growth", 10.0, 0.0),)),
    "encoder glitches": ("spike", "el", (("axis.el.inject_encoder_glitch_counts", 300.0, 0.0),
                                         ("axis.el.inject_encoder_glitches", 2.0, 0.0),
                                         ("axis.el.inject_encoder_glitches", 0.0, 60.0))),
    "heat runaway": ("temperature", "az", (("axis.az.inject_heat_growth", 100.0, 0.0),)),
    "clock drift": ("clock", "", (("time.inject_drift_growth", 30.0, 0.0),)),
}


def utc_us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


# The faulty nights fork off the clean one here: the mount is powered on at the window's
# start and the automatic reference is its first 15 minutes of usable time at the least,
# so every fault (after the reference) comes later.
FORK_US = utc_us(WINDOW[0]) + round(ReferenceConfig().length_s * 1e6)
# The fault moments are read from the clean night once it has ended; a variant waits at
# every minute after FORK_US until the last moment (the pass: 6.4 minutes after it), and
# each faulty night runs in the one forked last before its fault (a minute of simulation
# again at most, instead of up to seven).
STANDBY_US = tuple(FORK_US + k * 60_000_000 for k in range(1, 8))


def make_plan(workdir: Path) -> dict:
    """Plan the test night (the program's TLE file is copied beside it)."""
    workdir.mkdir(parents=True, exist_ok=True)
    shutil.copy(sample_tle_path("visual"), workdir / "visual.tle")
    (workdir / "program.toml").write_text(PROGRAM)
    plan = plan_program(PlanRequest(load_program(workdir / "program.toml"),
                                    utc_us(WINDOW[0]), utc_us(WINDOW[1]), load_site()))
    doc = plan.as_dict()
    (workdir / "plan.json").write_text(json.dumps(doc))
    return doc


def record_night(plan: dict, store: Path, writes: list[TimedWrite] = (),
                 until_us: int | None = None, branches: Branches | None = None) -> dict:
    """Run the plan on the embedded emulator, recording SIGNALS at 1 kHz into `store`
    (stopped at mount time `until_us`, if given; `branches` forked off it)."""
    recording = RunRecording(SIGNALS, RATE_HZ, (f"parquet:{store}",))
    return run_plan_on_emulator(plan, record=recording, writes=list(writes),
                                until_us=until_us, branches=branches)


@dataclass(frozen=True)
class Moments:
    """When to inject, read from a clean night: mount µs."""

    reference_end_us: int
    slew_us: int  # the middle of the first slew after the reference
    pass_us: int  # three minutes into the first satellite track after the reference


def _intervals(events, source: str, kind: str, field: str, value: str):
    """(start, end) µs of the stretches where `field` of `source`'s `kind` events is `value`."""
    out, start = [], None
    for e in sorted((e for e in events if e.source == source and e.kind == kind),
                    key=lambda e: e.t_us):
        now = e.fields.get(field) == value
        if now and start is None:
            start = e.t_us
        elif not now and start is not None:
            out.append((start, e.t_us))
            start = None
    return out


def moments(clean_store: Path, config: DetectorConfig | None = None, *,
            report=None) -> Moments:
    """`report`: the clean store's offline report, if the caller has it already."""
    reader = ParquetStoreReader(clean_store)
    if report is None:
        a, b = reader.time_range()
        report = detect_anomalies(reader, a, b + 1, config=config)
    ref_end = report.reference.stretches[-1][1]
    events = reader.events()
    slews = [(s, e) for s, e in _intervals(events, "emulator", "state", "new", "SLEWING")
             if s > ref_end + 30_000_000]
    passes = [e.t_us for e in sorted(events, key=lambda e: e.t_us)
              if e.source == "vss" and e.kind == "phase" and e.t_us > ref_end
              and e.fields.get("operation_kind") == "track_satellite"
              and e.fields.get("phase") == "tracking"]
    return Moments(ref_end, (slews[0][0] + slews[0][1]) // 2, passes[0] + 180_000_000)


def injections(at_us: int) -> list[TimedWrite]:
    """Every degradation of DEGRADATIONS, begun at `at_us` (one night holds all six: each
    is of another kind or axis, so a flag says which it found)."""
    return [TimedWrite(at_us + round(delay_s * 1e6), name, value)
            for _, _, writes in DEGRADATIONS.values() for name, value, delay_s in writes]
