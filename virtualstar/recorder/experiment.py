"""The paper's validation run on the emulator, in simulated time: one axis follows a
drifting sinusoid for hours while the recorder takes position, motor current and
tracking error at 1 kHz through the real ASTCom stream path.

The emulator runs in this process (started through `virtualstar.launcher`, the one
module of virtualstar that imports `mount_emulator`); the experiment drives its
trajectory through ASTCom itself — ``mount.power_on``, ``traj.init``,
``traj.push_rates``, ``traj.start`` on a control connection — instead of through the
VirtualStar Server, and a second, in-memory ASTCom connection carries the stream to
the recorder. Simulated time runs as fast as the recorder keeps up: the loop computes a
block of ticks, publishes it, and waits until the recorder has received all but the
last few packets (so nothing is ever dropped, whatever the machine's load).

Variants of the run (`SineBranch`: the same sine with faults injected from a moment on)
are forked off it at that moment (virtualstar/forking.py) instead of being recorded again
from the start: until then they would be the same recording.

The commanded azimuth is ``az(t) = az0 + v·t − (v/ω)·sin(ω·t)``: its speed
``v·(1 − cos ω·t)`` starts at zero (no step at the start), never reverses, and averages
`v` (0.0095 rad/min in the paper: 6.8 rad in 12 h).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astcom_client import Client, Endpoint, EndpointConfig

from .exceptions import ExperimentError
from .parquet_store import ParquetStoreReader, ParquetStoreWriter
from .subscriber import Recorder, RecordingSummary

__all__ = ["Injection", "SineBranch", "SineExperiment", "SineResult", "commanded_position",
           "run_sine_experiment"]

DEFAULT_START_US = 1_772_395_200_000_000  # 2026-03-01T20:00:00Z, an evening in mount time
DRIFT_RAD_PER_MIN = 0.0095  # the paper's average axis speed
SIM_FLUSH_INTERVAL_S = 1.0  # simulated seconds per stream packet (see _embedded_emulator)
STEPPED_SPEED = 1e-12  # the emulator's own loop at this speed computes nothing: we step it
BLOCK_TICKS = 2_000  # ticks per emulator block (0.2 s simulated): its trace stays in cache
LAG_PACKETS = 3  # the emulator may run this many stream packets ahead of the recorder
POINT_INTERVAL_US = 100_000  # trajectory points every 0.1 s
PUSH_POINTS = 1000  # points per traj.push_rates call (100 s)
LEAD_US = 200_000_000  # keep the trajectory buffer this far ahead of mount time
START_DELAY_US = 200_000  # the first point lies this far after traj.start


@dataclass(frozen=True)
class Injection:
    """Write parameter `name` = `value` on the mount `at_s` seconds after the trajectory
    starts (a fault injection, docs/mount-emulator.md; exact to the tick)."""

    at_s: float
    name: str
    value: float

    def at_us(self, t0_us: int) -> int:
        return t0_us + round(self.at_s * 1e6)


@dataclass(frozen=True)
class SineBranch:
    """A variant of the run, forked off it (os.fork) `at_s` seconds after the trajectory
    starts: the same run (the same sine), plus its own `injections` (none before
    `at_s`), recorded into `out_dir`/store until `stop_s` (default: the run's end).
    `detect`: the variant runs the anomaly detectors live even where the run does not;
    they first catch up on what the run recorded until the fork (in the order it was
    written), then see the rest as it comes (an anomaly found while catching up, before
    any fault of the variant, would be logged at the fork's time)."""

    at_s: float
    injections: tuple[Injection, ...]
    out_dir: str
    stop_s: float | None = None
    detect: bool = False


@dataclass(frozen=True)
class SineExperiment:
    """Parameters of the run; angles in radians, times in seconds unless named otherwise."""

    axis: str = "az"
    hours: float = 12.0
    record_hz: float = 1000.0
    drift_rad_per_min: float = DRIFT_RAD_PER_MIN
    period_s: float = 600.0
    start_us: int = DEFAULT_START_US
    other_axis_deg: float = 45.0
    extra_names: tuple[str, ...] = ()  # recorded beside position, current and error
    injections: tuple[Injection, ...] = ()

    def __post_init__(self) -> None:
        if self.axis not in ("az", "el"):
            raise ValueError(f"axis {self.axis!r}: expected az or el")
        if not self.hours > 0:
            raise ValueError(f"hours must be > 0, got {self.hours}")
        if not 0 < self.record_hz <= 10_000:
            raise ValueError(f"record_hz must be in (0, 10000] (the 10 kHz loop), got {self.record_hz}")
        if not self.period_s > 0:
            raise ValueError(f"period_s must be > 0, got {self.period_s}")
        if self.axis == "el" and self.span_rad > math.radians(80):
            raise ValueError(f"elevation cannot travel {self.span_rad:.2f} rad (0..90°): shorten "
                             "--hours or use --axis az")

    @property
    def v_rad_s(self) -> float:
        return self.drift_rad_per_min / 60.0

    @property
    def duration_us(self) -> int:
        return round(self.hours * 3600e6)

    @property
    def span_rad(self) -> float:
        return self.v_rad_s * self.duration_us / 1e6

    @property
    def start_rad(self) -> float:
        """Return the axis start so the run is centred in the travel (az) or rises from 5° (el)."""
        return -self.span_rad / 2 if self.axis == "az" else math.radians(5.0)

    @property
    def names(self) -> list[str]:
        a = self.axis
        return [f"axis.{a}.position", f"axis.{a}.current", f"axis.{a}.error_arcsec",
                *self.extra_names]


def commanded_position(exp: SineExperiment, t_us: np.ndarray, t0_us: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the commanded (position rad, rate rad/s) at mount times `t_us`, started at `t0_us`."""
    t = np.maximum(np.asarray(t_us, dtype=np.int64) - t0_us, 0) / 1e6
    w = 2 * math.pi / exp.period_s
    v = exp.v_rad_s
    pos = exp.start_rad + v * t - (v / w) * np.sin(w * t)
    rate = v * (1 - np.cos(w * t))
    return pos, rate


@dataclass
class SineResult:
    """What the run produced: the store, the plots, the recording and the timing."""

    experiment: SineExperiment
    store: Path
    plots: list[Path]
    recording: RecordingSummary
    trajectory_t0_us: int
    wall_s: float
    sim_s: float
    ticks: int
    timings_s: dict[str, float] = field(default_factory=dict)
    branches: list[dict[str, object]] = field(default_factory=list)  # their as_dict()

    @property
    def speed(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else 0.0

    def as_dict(self) -> dict[str, object]:
        return {"axis": self.experiment.axis, "hours": self.experiment.hours,
                "record_hz": self.recording.rate_hz, "names": self.recording.names,
                "store": str(self.store), "plots": [str(p) for p in self.plots],
                "samples_per_signal": self.recording.samples, "lost": self.recording.lost,
                "gaps": len(self.recording.gaps), "ticks": self.ticks,
                "trajectory_t0_us": self.trajectory_t0_us, "sim_s": self.sim_s,
                "wall_s": round(self.wall_s, 3), "speed": round(self.speed, 1),
                "timings_s": {k: round(v, 3) for k, v in self.timings_s.items()},
                "branches": self.branches}


async def _embedded_emulator(exp: SineExperiment) -> tuple[Any, Endpoint]:
    """Start the emulator through `virtualstar.launcher` (the one module that imports it),
    stepped by us; return (EmbeddedEmulator, the endpoint it serves its URL with).

    The launcher starts the emulator's own loop; at `STEPPED_SPEED` × real time that loop
    computes no tick for years, so the experiment steps the mount with the documented
    `advance(n)` and paces it by the recorder. Its streams go through a second Endpoint
    on the same Collection that sends one packet per simulated second: at the default
    20 ms a 12-h run is 2.2 M packets and per-packet costs (encode, queue, decode) would
    double the run time; 43 k packets keep the same stream semantics (exact ticks, times).
    """
    from virtualstar.launcher import start_emulator

    az_deg = math.degrees(exp.start_rad) if exp.axis == "az" else 0.0
    el_deg = math.degrees(exp.start_rad) if exp.axis == "el" else exp.other_axis_deg
    emb = await start_emulator(speed=STEPPED_SPEED, start_us=exp.start_us, az_deg=az_deg,
                               el_deg=el_deg, seeing_arcsec=0.0, url="tcp://127.0.0.1:0")
    served = emb.emulator.endpoint
    emb.emulator.endpoint = Endpoint(emb.emulator.collection, EndpointConfig(
        loop_rate_hz=served.config.loop_rate_hz, name="mount-emulator (simulated time)",
        flush_interval_s=SIM_FLUSH_INTERVAL_S, max_frame_bytes=1 << 24, max_array_len=1_000_000))
    return emb, served


async def _push_until(control: Client, exp: SineExperiment, t0_us: int, pushed_to_us: int,
                      until_us: int) -> int:
    """Push points after `pushed_to_us` up to `until_us`; return the new last point time."""
    end_us = t0_us + exp.duration_us
    while pushed_to_us < min(until_us, end_us):
        first = pushed_to_us + POINT_INTERVAL_US
        t = first + np.arange(PUSH_POINTS, dtype=np.int64) * POINT_INTERVAL_US
        t = t[t <= end_us + POINT_INTERVAL_US]
        pos, rate = commanded_position(exp, t, t0_us)
        other = np.full(len(t), math.radians(exp.other_axis_deg))
        zero = np.zeros(len(t))
        args = (t, pos, other, rate, zero) if exp.axis == "az" else (t, other, pos, zero, rate)
        accepted = await control.invoke("traj.push_rates", *args)
        if accepted != len(t):
            raise ExperimentError(f"the mount accepted {accepted} of {len(t)} trajectory points "
                                  "(late or out of range); the run cannot follow the sine")
        pushed_to_us = int(t[-1])
    return pushed_to_us


async def run_sine_experiment(exp: SineExperiment, out_dir: str | Path, *,
                              on_progress: Callable[[float, float, float], None] | None = None,
                              plots: bool = True, detect: bool = False,
                              branches: Sequence[SineBranch] = ()) -> SineResult:
    """Run `exp` on an in-process emulator, record into `out_dir`/store, write the plots.

    `on_progress(sim_s, total_s, speed)` is called about once per simulated minute.
    `detect` runs the anomaly detectors live; what they find goes into the store's event
    log (virtualstar.anomalies.live). `branches` are variants forked off the run (they
    run in processes of their own, in parallel; the result's `branches` holds theirs).
    Raises ExperimentError when the mount faults or a sample is lost, here or in a branch.
    """
    from virtualstar.forking import ForkError, Forks

    for b in branches:
        if not 0 < b.at_s < (b.stop_s or exp.duration_us / 1e6) <= exp.duration_us / 1e6 or \
                any(j.at_s < b.at_s for j in b.injections):
            raise ExperimentError(f"a branch at {b.at_s} s must stop after it, within the run, "
                                  "and inject nothing before it")
    forks = Forks()
    with forks.guard():
        result = await _run(exp, out_dir, on_progress, plots, detect, branches, forks)
    if forks.in_child:
        forks.end_child(result=result.as_dict())
    if branches:
        try:
            result.branches = forks.wait()
        except ForkError as exc:
            raise ExperimentError(str(exc)) from None
        finally:
            forks.abandon()
    return result


async def _run(exp: SineExperiment, out_dir: str | Path,
               on_progress: Callable[[float, float, float], None] | None, plots: bool,
               detect: bool, branches: Sequence[SineBranch], forks) -> SineResult:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    store = out / "store"
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    emb, served = await _embedded_emulator(exp)
    emu = emb.emulator
    control = await Client.open(emu.endpoint.connect_in_memory(), name="experiment")
    if branches:  # a store that can be forked: held in memory, written whole at the end
        from virtualstar.forking import HeldWriter

        writer = HeldWriter(lambda: ParquetStoreWriter(store))
    else:
        writer = ParquetStoreWriter(store)

    async def connect() -> Client:
        return await Client.open(emu.endpoint.connect_in_memory(maxsize=256), name="recorder",
                                 queue_packets=4096)

    def live_detectors():
        from virtualstar.anomalies.live import LiveAnomalies

        live = LiveAnomalies(exp.names, exp.record_hz, lambda a: recorder.anomaly_found(a))
        return live.feed, live.feed_events, live.finish

    watch = watch_events = watch_end = None
    if detect:
        watch, watch_events, watch_end = live_detectors()
    recorder = Recorder(connect, exp.names, exp.record_hz, writer, watch=watch,
                        watch_events=watch_events, watch_end=watch_end,
                        source=f"in-process mount emulator, sine experiment on {exp.axis}")
    task: asyncio.Task | None = None
    try:
        await control.invoke("mount.power_on")
        emu.advance(BLOCK_TICKS // 10)
        await control.invoke("traj.init")
        now_us = (await control.read(["time.mount_us"]))["time.mount_us"]
        t0_us = int(now_us) + START_DELAY_US
        pushed = await _push_until(control, exp, t0_us, t0_us - POINT_INTERVAL_US,
                                   t0_us + LEAD_US)
        task = asyncio.create_task(recorder.run())
        while recorder.sink.session == "" and not task.done():
            await asyncio.sleep(0)
        await control.invoke("traj.start")
        total_ticks = (exp.duration_us + START_DELAY_US) // 100
        first_tick = emu.ticks_run
        done = 0
        packet_ticks = round(SIM_FLUSH_INTERVAL_S * 10_000)
        lag_ticks = LAG_PACKETS * packet_ticks + BLOCK_TICKS
        report_every = 60 * 10_000
        next_report = report_every
        loop_start = time.perf_counter()
        step_s = 0.0
        pending = sorted(exp.injections, key=lambda j: j.at_s)
        forking = sorted(branches, key=lambda b: b.at_s)
        while done < total_ticks:
            n = min(BLOCK_TICKS, total_ticks - done)
            while forking and round(forking[0].at_s * 1e6) + t0_us <= emb.mount_time_us:
                b = forking.pop(0)
                if forks.fork(asyncio.get_running_loop(), orders=b) is not None:
                    # this process is the variant from here on: its faults, store and end
                    forking = []
                    pending = sorted(b.injections, key=lambda j: j.at_s)
                    out = Path(b.out_dir)
                    out.mkdir(parents=True, exist_ok=True)
                    store = out / "store"
                    if b.stop_s is not None:
                        total_ticks = (round(b.stop_s * 1e6) + START_DELAY_US) // 100
                    if b.detect and not detect:
                        watch, watch_events, watch_end = live_detectors()
                        # the recorder's own events aside: a watcher sees the device's
                        writer.replay(watch, lambda events, feed=watch_events: feed(
                            [e for e in events if e.source != "recorder"]))
                        recorder.watch(watch, watch_events, watch_end)
                    n = min(BLOCK_TICKS, total_ticks - done)
            while pending and pending[0].at_us(t0_us) <= emb.mount_time_us:
                j = pending.pop(0)
                await control.write({j.name: j.value})
            # end the block on the tick the next injection or fork is due
            due = [j.at_us(t0_us) for j in pending[:1]] + \
                [round(b.at_s * 1e6) + t0_us for b in forking[:1]]
            if due:
                n = max(1, min(n, (min(due) - emb.mount_time_us) // 100))
            s0 = time.perf_counter()
            emu.advance(n)
            step_s += time.perf_counter() - s0
            done += n
            if task.done():
                break
            # a packet leaves the endpoint only when full: allow a few packets of lag
            lag_tick = first_tick + done - lag_ticks
            if lag_tick > 0:
                await recorder.wait_for_tick(lag_tick)
            else:
                await asyncio.sleep(0)
            if emb.mount_time_us + LEAD_US // 2 > pushed:
                pushed = await _push_until(control, exp, t0_us, pushed,
                                           emb.mount_time_us + LEAD_US)
            if done >= next_report:
                next_report += report_every
                if on_progress is not None:
                    wall = time.perf_counter() - loop_start
                    on_progress(done / 10_000, total_ticks / 10_000, done / 10_000 / max(wall, 1e-9))
        if forking:
            raise ExperimentError(f"the run ended before its branch at {forking[0].at_s} s")
        state = await control.read([f"axis.{exp.axis}.state_name", f"axis.{exp.axis}.fault_text",
                                    "traj.underruns", "traj.late"])
        # the endpoint sends a packet when it is full: run on until the last one is out
        emu.advance(round(SIM_FLUSH_INTERVAL_S * 10_000) + 10)
        await recorder.wait_for_tick(first_tick + done - 1)
        recorder.stop()
        summary = await task
        task = None
        timings["emulator_step"] = step_s
        timings["loop"] = time.perf_counter() - loop_start
    finally:
        if task is not None:
            recorder.stop()
            await asyncio.gather(task, return_exceptions=True)
        await control.close()
        await emb.stop()
        await served.close()
    if on_progress is not None:
        on_progress(done / 10_000, total_ticks / 10_000, done / 10_000 / max(timings["loop"], 1e-9))
    fault = state[f"axis.{exp.axis}.fault_text"]
    if fault and fault != "none":
        raise ExperimentError(f"the {exp.axis} axis faulted during the run: {fault} "
                              f"(state {state[f'axis.{exp.axis}.state_name']})")
    if summary.lost or summary.gaps:
        raise ExperimentError(f"the recorder lost {summary.lost} samples in {len(summary.gaps)} "
                              "gaps; the store is incomplete")
    if state["traj.underruns"]:
        raise ExperimentError(f"the trajectory buffer ran dry {state['traj.underruns']} times")
    wall = time.perf_counter() - t_start
    paths: list[Path] = []
    if plots:
        p0 = time.perf_counter()
        paths = write_plots(store, out, title=f"sine experiment, {exp.axis} axis, "
                                               f"{exp.hours:g} h at {summary.rate_hz:g} Hz")
        timings["plots"] = time.perf_counter() - p0
    return SineResult(exp, store, paths, summary, t0_us, wall, done / 10_000, done, timings)


def write_plots(store: str | Path, out_dir: str | Path, *, title: str = "",
                window_s: float = 2.0, buckets: int = 2000) -> list[Path]:
    """Write fig6_overview.png (whole store, envelope) and fig7_first_2s.png into `out_dir`."""
    from .plots import plot_envelope, plot_window  # matplotlib: only where a plot is drawn

    reader = ParquetStoreReader(store)
    signals = reader.signals()
    t0, t1 = reader.time_range()
    env = reader.envelope(t0, t1 + 1, None, buckets)
    out = Path(out_dir)
    fig6 = plot_envelope(env, signals, out / "fig6_overview.png",
                         title=f"Fig. 6 — whole run, min/max envelope. {title}")
    block = reader.window(t0, t0 + round(window_s * 1e6))
    fig7 = plot_window(block, signals, out / "fig7_first_2s.png",
                       title=f"Fig. 7 — first {window_s:g} s at full rate. {title}")
    return [fig6, fig7]
