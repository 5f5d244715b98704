"""Recordings of the emulator with faults injected at known times, for the anomaly tests."""

from __future__ import annotations

import asyncio
import fcntl
import json
import os
from collections.abc import Callable
from pathlib import Path

from virtualstar.anomalies.scoring import InjectedFault
from virtualstar.recorder.experiment import Injection, SineExperiment, run_sine_experiment

MINUTES = 30.0
AT_S = 960.0  # injections 16 minutes in: after the 15-minute reference stretch


def made_once(tmp_path_factory, name: str, build: Callable[[Path], object]):
    """`build(directory)`'s JSON value, built once per test session even when pytest-xdist
    spreads the tests that need it over several workers (`-n 2` without `--dist
    loadscope` sends a module's tests to both): the workers share the session's base
    directory, and the first to take the lock builds while the others wait for it."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's directory, above each worker's own
    directory = root / "made-once" / name
    directory.mkdir(parents=True, exist_ok=True)
    done = directory / "value.json"
    with open(directory / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not done.exists():
                (directory / "data").mkdir(exist_ok=True)
                done.write_text(json.dumps(build(directory / "data")))
            return json.loads(done.read_text())
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def record(out: Path, injections: tuple[Injection, ...], *, minutes: float = MINUTES,
           extra: tuple[str, ...] = ("axis.az.temperature",)) -> tuple[Path, int]:
    """Record the sine experiment with `injections`; return (store, trajectory start µs)."""
    exp = SineExperiment(hours=minutes / 60, extra_names=extra, injections=injections)
    result = asyncio.run(run_sine_experiment(exp, out, plots=False))
    return result.store, result.trajectory_t0_us


# name: (injections, expected faults as (kind, axis, from s, to s or None = the end))
CASES = {
    "clock drift and heat runaway": (
        (Injection(AT_S, "time.inject_drift_growth", 12.0),
         Injection(AT_S, "axis.az.inject_heat_growth", 40.0)),
        (("clock", "", AT_S, None), ("temperature", "az", AT_S, None))),
    "encoder glitches then a winding fault": (
        (Injection(AT_S, "axis.az.inject_encoder_glitch_counts", 200.0),
         Injection(AT_S, "axis.az.inject_encoder_glitches", 2.0),
         Injection(AT_S + 60, "axis.az.inject_encoder_glitches", 0.0),
         Injection(AT_S + 240, "axis.az.inject_winding_fault", 0.2)),
        (("spike", "az", AT_S, AT_S + 60), ("current", "az", AT_S + 240, None))),
    "friction rising": (
        (Injection(AT_S, "axis.az.inject_friction_growth", 6.0),),
        (("current", "az", AT_S, None),)),
    "a loosened part rattling louder": (
        (Injection(AT_S, "axis.az.inject_resonance_growth", 2.0),),
        (("vibration", "az", AT_S, None),)),
}


def faults(spec, t0_us: int, end_us: int) -> list[InjectedFault]:
    return [InjectedFault(kind, axis, t0_us + round(a * 1e6),
                          end_us if b is None else t0_us + round(b * 1e6))
            for kind, axis, a, b in spec]
