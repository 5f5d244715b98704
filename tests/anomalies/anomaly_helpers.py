"""Recordings of the emulator with faults injected at known times, for the anomaly tests."""

from __future__ import annotations

import asyncio
import fcntl
import json
import os
import time
import warnings
from collections.abc import Callable
from pathlib import Path

from virtualstar.anomalies.scoring import InjectedFault
from virtualstar.recorder.experiment import (
    Injection,
    SineBranch,
    SineExperiment,
    SineResult,
    run_sine_experiment,
)

MINUTES = 30.0  # the clean recording: a 15-minute reference, then 15 minutes scored
AT_S = 960.0  # injections 16 minutes in: after the 15-minute reference stretch
# The faults' recordings end 10 minutes after the injections: the slowest to be found, the
# rattling part's growing vibration, is flagged 6 minutes after its injection. A case whose
# faults are all found sooner stops sooner (STOP_MINUTES): the rest would only cost CPU.
FAULT_MINUTES = 26.0
# A recording takes ~8 s of CPU alone and a VSS night ~15 s: a few minutes on a loaded host.
# A waiting worker builds its own copy after this long rather than wait on (the modules
# that wait allow 1800 s: a wait, then a build of their own, fit in it).
MADE_ONCE_WAIT_S = 600.0
MADE_ONCE_TIMEOUT_S = 1800  # pytest-timeout of a module whose fixture may wait and build


def made_once(tmp_path_factory, name: str, build: Callable[[Path], object], *,
              wait_s: float = MADE_ONCE_WAIT_S):
    """`build(directory)`'s JSON value, built once per test session even when pytest-xdist
    spreads the tests that need it over several workers (`--dist loadscope` sends modules
    that share a recording to different workers): the workers share the session's base
    directory, and the first to take the lock builds while the others wait for it.

    The wait cannot hang: `build` runs in this process (no subprocess holds the lock, and
    the kernel releases a flock when its holder dies, however it dies), and a worker that
    has not had the lock within `wait_s` builds its own copy in its own directory (a
    recording is deterministic, so the copy is the same; it only costs the CPU again)."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's directory, above each worker's own
    directory = root / "made-once" / name
    directory.mkdir(parents=True, exist_ok=True)
    done = directory / "value.json"
    with open(directory / "lock", "w") as lock:
        if not _lock_within(lock, wait_s):
            own = tmp_path_factory.mktemp(f"{name}-own")
            warnings.warn(f"made_once({name!r}): the lock was still held after {wait_s:.0f} s; "
                          "building a private copy", stacklevel=2)
            return json.loads(json.dumps(build(own)))
        try:
            if not done.exists():
                (directory / "data").mkdir(exist_ok=True)
                value = json.dumps(build(directory / "data"))
                partial = directory / "value.json.partial"
                partial.write_text(value)
                partial.replace(done)  # whole or absent, whatever stops the builder
            return json.loads(done.read_text())
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _lock_within(lock, wait_s: float) -> bool:
    """Take `lock` exclusively, polling; False if it is still held after `wait_s`."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.2)


def record(out: Path, injections: tuple[Injection, ...], *, minutes: float = MINUTES,
           extra: tuple[str, ...] = ("axis.az.temperature",),
           detect: bool = False, branches: tuple[SineBranch, ...] = ()) -> SineResult:
    """Record the sine experiment with `injections` (and `branches` forked off it).
    `detect` runs the detectors live: what they find is logged in the store's events."""
    exp = SineExperiment(hours=minutes / 60, extra_names=extra, injections=injections)
    return asyncio.run(run_sine_experiment(exp, out, plots=False, detect=detect,
                                           branches=branches))


# name: (injections, expected faults as (kind, axis, from s, to s or None = the end)).
# A recording takes ~8 s of CPU (the emulator's 10 kHz physics most of it), so faults share
# one where each is of another kind than the others (a flag says which it found): the three
# growths of different kinds together, the glitches and the winding fault (both sudden) one
# after the other, and the friction alone (its current is the winding fault's kind). All
# three are forked off the clean recording at AT_S (until then they are the clean
# recording) and stopped at STOP_MINUTES; the friction's variant runs the detectors live,
# switched on at the fork (test_live_anomalies.py reads its log).
CASES = {
    "clock drift, heat runaway and a loosened part rattling louder": (
        (Injection(AT_S, "time.inject_drift_growth", 12.0),
         Injection(AT_S, "axis.az.inject_heat_growth", 40.0),
         Injection(AT_S, "axis.az.inject_resonance_growth", 2.0)),
        (("clock", "", AT_S, None), ("temperature", "az", AT_S, None),
         ("vibration", "az", AT_S, None))),
    "encoder glitches then a winding fault": (
        (Injection(AT_S, "axis.az.inject_encoder_glitch_counts", 200.0),
         Injection(AT_S, "axis.az.inject_encoder_glitches", 2.0),
         Injection(AT_S + 60, "axis.az.inject_encoder_glitches", 0.0),
         Injection(AT_S + 240, "axis.az.inject_winding_fault", 0.2)),
        (("spike", "az", AT_S, AT_S + 60), ("current", "az", AT_S + 240, None))),
    "friction rising": (
        (Injection(AT_S, "axis.az.inject_friction_growth", 6.0),),
        (("current", "az", AT_S, None),)),
}
LIVE_CASE = "friction rising"  # its variant runs the detectors live
# Where a case's recording stops (minutes), at least twice the time its slowest fault takes
# to be flagged after its injection and 4 minutes after its last injection: the winding
# fault is flagged 28 s after it (4 min after the glitches), the friction 80 s after it.
STOP_MINUTES = {name: FAULT_MINUTES for name in CASES} | {
    "encoder glitches then a winding fault": (AT_S + 240.0) / 60.0 + 4.0,
    "friction rising": AT_S / 60.0 + 4.0,
}


def faults(spec, t0_us: int, end_us: int) -> list[InjectedFault]:
    return [InjectedFault(kind, axis, t0_us + round(a * 1e6),
                          end_us if b is None else t0_us + round(b * 1e6))
            for kind, axis, a, b in spec]
