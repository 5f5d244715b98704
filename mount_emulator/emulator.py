"""Serve a `MountModel` over ASTCom and run its 10 kHz loop in real or simulated time.

The loop is an asyncio task on the Endpoint's event loop (docs/architecture.md,
"Threading model"): it computes the ticks that are due in blocks with the
compiled step, fills only the trace columns some stream wants, publishes the
block, and yields. Requests are served between blocks, so writes land between
two ticks. Real time and simulated time share this code; only the number of
ticks due per wake-up differs (monotonic clock × speed, or a fixed block as
fast as possible).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from datetime import UTC, datetime

import numpy as np

from astcom_client import Endpoint, EndpointConfig
from astcom_client.endpoint import current_client
from astcom_client.events import EventLog
from mount_emulator import layout as L
from mount_emulator.config import EmulatorConfig
from mount_emulator.exceptions import ConfigError
from mount_emulator.geometry import GuideCamera
from mount_emulator.loop_health import LoopHealth
from mount_emulator.model import MountModel
from mount_emulator.registry import build_collection
from mount_emulator.states import EV_FAULT, EV_SYNC, EV_UNDERRUN, AxisState, fault_text

__all__ = ["LOOP_RATE_HZ", "MountEmulator"]

LOOP_RATE_HZ = 1_000_000 // L.TICK_US
MAX_BLOCK_TICKS = 1000  # a late real-time loop catches up in blocks of at most 0.1 s
FAST_BLOCK_TICKS = 2000  # --speed max computes this many ticks between yields
DRIVEN_BLOCK_TICKS = 2000  # run_until publishes to the streams at least every 0.2 s of mount time


class MountEmulator:
    """The emulated mount behind an ASTCom Endpoint.

    ``await MountEmulator(config).start("ws://127.0.0.1:0")`` returns the bound
    URL and runs the loop until ``await stop()``. ``advance(n)`` computes ticks
    directly (tests); ``start(..., run_loop=False)`` leaves the pacing to an
    external clock that calls ``run_until(t_us)`` (lockstep simulated time).

    In real time without a configured start (``start_us`` None, speed 1) the clocks
    are put on host UTC when the loop starts, not when the object is built: a
    compile or a slow start-up does not leave the mount behind UTC.
    """

    def __init__(self, config: EmulatorConfig | None = None) -> None:
        self.config = config = config or EmulatorConfig()
        start_us = config.start_us if config.start_us is not None else time.time_ns() // 1000
        params = L.default_params()
        for name, value in config.params.items():
            if name not in L.PARAM_INDEX:
                raise ConfigError(f"unknown parameter {name!r}")
            params[L.PARAM_INDEX[name]] = value
        self.model = MountModel(start_us=start_us, params=params,
                                az_rad=math.radians(config.az_deg),
                                el_rad=math.radians(config.el_deg),
                                traj_capacity=config.traj_capacity)
        self.camera = GuideCamera(config.geometry, seeing_arcsec=config.seeing_arcsec,
                                  seed=config.guide_seed)
        self.speed = float(config.speed)
        self.last_guide = (0.0, 0.0)
        self.health = LoopHealth()
        # connections and failed logins keep rings of their own: churn cannot flush the rest
        self.log = EventLog("emulator", kept_apart={"connection": 2000, "auth": 2000})
        self._last_states = self._states()
        self.collection, col_to_state = build_collection(self)
        self._col_to_state = np.zeros(self.collection.trace_width, dtype=np.int64)
        for col, idx in col_to_state.items():
            self._col_to_state[col] = idx
        self.endpoint = Endpoint(self.collection, EndpointConfig(
            loop_rate_hz=LOOP_RATE_HZ, passwords=config.passwords, name="mount-emulator",
            flush_interval_s=config.stream_flush_s))
        self.endpoint.on_client = self._client_event
        self.endpoint.on_auth_failure = self._auth_failure
        self._wanted_key: bytes | None = None
        self._src = np.zeros(0, dtype=np.int64)
        self._dst = np.zeros(0, dtype=np.int64)
        self._task: asyncio.Task[None] | None = None
        self.ticks_run = 0

    # ------------------------------------------------------------ commands
    def guide_measure(self, star_az_deg: float, star_el_deg: float) -> np.ndarray:
        """Return the star's offset from the optical axis (arcsec) at the current encoders."""
        dx, dy = self.camera.offset_arcsec(
            self.model.axis_slot(0, L.A_ENC), self.model.axis_slot(1, L.A_ENC),
            math.radians(star_az_deg), math.radians(star_el_deg))
        self.last_guide = (dx, dy)
        return np.array([dx, dy])

    def set_seeing(self, value: float) -> None:
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"guide.seeing_arcsec must be >= 0, got {value}")
        self.camera.seeing_arcsec = float(value)

    def health_reset(self) -> None:
        """Zero the loop-health counters (`loop.reset_health`)."""
        self.health.reset()

    # ------------------------------------------------------------ event log
    def log_event(self, level: str, kind: str, message: str, **fields: object) -> None:
        """Log an event at the current mount time (astcom_client.events; `log.since`).

        While an ASTCom request runs, its client's name and role go into the fields.
        """
        name, role, _ = current_client.get()
        if role:
            fields = {**fields, "client": name, "role": role}
            message = f"{message} by {name or 'a client'} ({role})"
        self.log.add(self.model.mount_time_us, level, kind, message, **fields)
        if kind == "fault_reset":
            # faults were cleared between blocks: one that trips again is a new fault
            self._last_states = self._states()

    def _client_event(self, what: str, name: str, role: str, client_id: int) -> None:
        self.log.add(self.model.mount_time_us, "info", "connection",
                     f"client {name or client_id} ({role}) {what}", client=name, role=role,
                     client_id=client_id, what=what)

    def _auth_failure(self, peer: str, failure) -> None:
        notes = [f"{failure.failures} in a row"]
        if failure.locked_s:
            notes.append(f"locked out for {failure.locked_s:g} s")
        if failure.refused:
            notes.append(f"{failure.refused} attempts refused unchecked since the last")
        self.log.add(self.model.mount_time_us, "warning", "auth",
                     f"wrong password from {peer} ({'; '.join(notes)})", client=peer,
                     failures=failure.failures, locked_s=failure.locked_s,
                     refused=failure.refused)

    def param_written(self, name: str, old: float, new: float) -> None:
        """Log a parameter write (old → new); a fault injection is a warning."""
        level = "warning" if "inject_" in name and new != 0 else "info"
        self.log_event(level, "param", f"{name}: {old:g} → {new:g}", name=name, old=old,
                       new=new)

    def _states(self) -> tuple[int, ...]:
        m = self.model
        return (int(m.state[L.G_MOUNT_STATE]),
                *(int(m.axis_slot(a, f)) for a in range(2) for f in (L.A_STATE, L.A_FAULTS)))

    def _log_block(self, events: int, armed_s: float) -> None:
        """Log what changed during a block: mount state, latched faults, syncs, underruns.

        They carry the mount time at the end of the block (at most 0.2 s after the tick
        they happened on), except a clock sync: the PPS edge it happened on.
        """
        now = self._states()
        before, self._last_states = self._last_states, now
        if events & EV_FAULT or now[2::2] != before[2::2]:
            for a, axis in enumerate(L.AXES):
                bits, old = now[2 + 2 * a], before[2 + 2 * a]
                if bits & ~old:
                    self.log_event("error", "fault", f"{axis} axis faulted: "
                                   f"{fault_text(bits & ~old)}", axis=axis, bits=bits & ~old)
        if now[0] != before[0]:
            self.log_event("info", "state", f"mount {AxisState(before[0]).name} → "
                           f"{AxisState(now[0]).name}", old=AxisState(before[0]).name,
                           new=AxisState(now[0]).name)
        if events & EV_SYNC and armed_s >= 0:
            err = float(self.model.state[L.G_PPS_ERR_US])
            self.log.add(int(armed_s) * 1_000_000, "info", "clock_sync",
                         f"mount clock set to {int(armed_s)} s on the PPS edge (it was "
                         f"{err:+.0f} µs off)", utc_second=int(armed_s), pps_error_us=err)
        if events & EV_UNDERRUN:
            self.log_event("warning", "underrun", "trajectory buffer ran dry while tracking",
                           underruns=int(self.model.state[L.G_TRAJ_UNDERRUNS]))

    def mount_time_iso(self) -> str:
        """Return the mount clock as ISO-8601 UTC text with microseconds."""
        t_us = self.model.mount_time_us
        return datetime.fromtimestamp(t_us // 1_000_000, UTC).replace(
            microsecond=t_us % 1_000_000).isoformat().replace("+00:00", "Z")

    # ------------------------------------------------------------ the loop
    def _trace_columns(self) -> tuple[np.ndarray, np.ndarray]:
        wanted = self.endpoint.wanted_trace_columns
        key = wanted.tobytes()
        if key != self._wanted_key:
            self._wanted_key = key
            self._dst = np.asarray(wanted, dtype=np.int64)
            self._src = self._col_to_state[self._dst]
        return self._src, self._dst

    def advance(self, n_ticks: int) -> int:
        """Compute ``n_ticks`` ticks, publish them to the streams; return the step's events."""
        model = self.model
        first_tick = int(model.state[L.G_TICK]) + 1
        first_t_us = model.mount_time_us + L.TICK_US
        src, dst = self._trace_columns()
        armed_s = model.state[L.G_PENDING_UTC_S]  # the second a PPS edge in this block sets
        if len(src):
            trace = np.empty((n_ticks, self.collection.trace_width))
            events = model.run(n_ticks, trace, src, dst)
        else:
            trace = None
            events = model.run(n_ticks)
        self.endpoint.publish(first_tick, first_t_us, n_ticks, trace)
        self.ticks_run += n_ticks
        self._log_block(events, armed_s)
        return events

    @property
    def true_time_us(self) -> int:
        """The emulator's UTC truth (what its PPS marks) at the last computed tick, µs."""
        return int(self.model.state[L.G_TRUE_US])

    def run_until(self, true_us: int) -> None:
        """Compute every tick up to true UTC `true_us` (an external clock paces the loop)."""
        due = (int(true_us) - self.true_time_us) // L.TICK_US
        while due > 0:
            n = min(due, DRIVEN_BLOCK_TICKS)
            self._timed_advance(n)
            due -= n

    def _timed_advance(self, n_ticks: int) -> None:
        start = time.perf_counter()
        self.advance(n_ticks)
        self.health.block_done((time.perf_counter() - start) * 1e6)

    async def _run(self) -> None:
        if self.speed <= 0:
            while True:
                self._timed_advance(FAST_BLOCK_TICKS)
                await asyncio.sleep(0)
        rate = LOOP_RATE_HZ * self.speed
        if self.config.start_us is None:
            # real time: true and mount time start on host UTC now (whole ticks), and the
            # pacing counts from the same instant
            now_us = time.time_ns() // 1000
            t0 = time.monotonic() - (now_us % L.TICK_US) / 1e6
            self.model.set_clock(now_us)
        else:
            t0 = time.monotonic()
        done = 0
        # one block is what a wake-up every block_s computes on time; more is an overrun
        block_ticks = max(1, math.ceil(rate * self.config.block_s * 2))
        while True:
            due = int((time.monotonic() - t0) * rate) - done
            if due > 0:
                self.health.woke(due, block_ticks, 1e6 / rate)
            while due > 0:
                n = min(due, MAX_BLOCK_TICKS)
                self._timed_advance(n)
                done += n
                due -= n
                if due > 0:
                    # Behind wall time (a busy CPU, the first compile): catch up, but serve
                    # clients between blocks so a late loop never starves the endpoint.
                    await asyncio.sleep(0)
            await asyncio.sleep(self.config.block_s)

    async def start(self, url: str | None = "ws://127.0.0.1:0", *more_urls: str,
                    run_loop: bool = True) -> str:
        """Listen on ``url`` (and ``more_urls``), start the loop; return the first bound URL.

        ``url`` None listens nowhere (in-memory clients only, `endpoint.connect_in_memory`);
        ``run_loop`` False starts no loop: the caller paces it with `run_until`.
        """
        bound = await self.endpoint.serve(url) if url is not None else ""
        for extra in more_urls:
            await self.endpoint.serve(extra)
        if run_loop:
            self._task = asyncio.get_running_loop().create_task(self._run(),
                                                                name="mount-emulator-loop")
        return bound

    async def stop(self) -> None:
        """Stop the loop and close every connection."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        await self.endpoint.close()

    async def __aenter__(self) -> MountEmulator:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()
