"""The telescope as the VSS drives it: operations, status, faults, tracking errors.

`Telescope` owns the `MountLink`, the tracking-error history, TimeS and at
most one running operation (slew, track, park, ...). A new operation replaces
the running one. Every motion follows the same recipe, in mount time:

1. prepare: the mount must be connected, not in fault; it is powered on and
   brought to rest if it was moving;
2. acquire: the mount slews (its own point-to-point profile) to the *rest
   point* of a constant-acceleration run-up (`trajectories.RampIn`) that joins
   the target's path at a chosen instant with the path's position and rate;
3. follow: the trajectory buffer is initialised, primed, started, and a
   `Feeder` keeps it filled until the path ends, a duration elapses, the target
   leaves the limits, or the operation is replaced or stopped.

A mount fault or a lost connection ends the operation and is reported as an
event; when the connection comes back, an interrupted track is resumed.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import math
import warnings
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import erfa
import numpy as np

from virtualstar.astro import (
    EarthOrientation,
    FixedAltAz,
    IcrsStar,
    MountLimits,
    Satellite,
    Site,
    UtcTimes,
    observe_mount_times,
    parse_radec,
    plan_slew,
    resolve_target,
    satellite_passes,
    unwrap_azimuth,
)
from virtualstar.astro.exceptions import AstroError

from .exceptions import (
    BadRequest,
    MappingError,
    MountFault,
    MountUnavailable,
    NotActive,
    OperationAborted,
    TargetUnreachable,
    VssError,
)
from .feeder import Feeder, FeederConfig
from .mount_link import MountLink
from .timesync import TimeSync
from .tracking_errors import TrackingErrorHistory
from .trajectories import RampIn, RampOut, TargetPath, plan_satellite_pass

__all__ = ["Operation", "Telescope", "TelescopeConfig"]

log = logging.getLogger("virtualstar.server")

_STATUS_ROLES = ("az_position", "el_position", "az_state", "el_state", "az_faults", "el_faults",
                 "mount_state", "mount_time", "free_points")
_SITE_KEYS = ("lat_deg", "lon_deg", "height_m", "pressure_hpa", "temperature_c", "humidity")
_OPTIONAL_STATUS = ("az_fault_text", "el_fault_text", "buffered_points", "underruns",
                    "late_points")


@dataclass(frozen=True)
class TelescopeConfig:
    """How the VSS drives the mount (mount seconds unless the name says wall)."""

    site: Site
    speed: float = 1.0  # mount seconds per wall second (simulated time > 1)
    simulated: bool = False
    point_rate_hz: float = 20.0
    lead_s: float | None = None  # None: 5 s, or 3 s of wall time in simulated time
    error_rate_hz: float = 1000.0
    ramp_s: float = 2.0
    settle_s: float = 1.0
    horizon_deg: float = 5.0
    sat_grid_s: float = 0.1
    pass_search_s: float = 2 * 86400.0
    keyhole_rate_fraction: float = 0.9
    active: bool = True
    poll_wall_s: float = 0.05
    timesync_period_s: float = 10.0

    @property
    def start_lead_s(self) -> float:
        """Mount time kept between "now" and the first point pushed (covers request delays)."""
        return max(1.0, 0.25 * self.speed)

    @property
    def feed_lead_s(self) -> float:
        """Mount time of points kept buffered ahead of the mount clock.

        In simulated time the same mount lead is a shorter wall time, and an
        event loop stalled by a loaded host must not drain the buffer: keep
        at least 3 s of wall time.
        """
        return self.lead_s if self.lead_s is not None else max(5.0, 3.0 * self.speed)


@dataclass
class Operation:
    """One operation: its id, kind, what it does now, and futures for "begun" and "done"."""

    id: int
    kind: str
    target: str
    phase: str = "starting"
    info: dict[str, Any] = field(default_factory=dict)
    begun: asyncio.Future | None = None
    done: asyncio.Future | None = None
    task: asyncio.Task | None = None
    cleanup: list[Callable[[], Any]] = field(default_factory=list)
    abort_error: VssError | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "target": self.target, "phase": self.phase,
                "info": self.info}


class Telescope:
    """Drive one mount through a `MountLink`; emit events through `emit(kind, data)`."""

    def __init__(self, link: MountLink, config: TelescopeConfig,
                 emit: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self.link = link
        self.config = config
        self.emit = emit or (lambda kind, data: None)
        self.codes = link.mapping.state_codes
        self.errors = TrackingErrorHistory()
        self.timesync = TimeSync(link, simulated=config.simulated,
                                 period_s=config.timesync_period_s)
        self.active = config.active
        self.timesync.active = config.active
        self.model = None
        self.model_source = ""
        self.limits = MountLimits()
        self.track_rate_limit_deg_s = 6.0
        self.op: Operation | None = None
        self._ids = itertools.count(1)
        self._tasks: list[asyncio.Task] = []
        self._stream_task: asyncio.Task | None = None
        self._resume: Callable[[], Awaitable[Operation]] | None = None
        self._eop = EarthOrientation.from_astropy_iers_data()
        self.last_fault = ""
        self._mount_state: int | None = None
        self.feeder: Feeder | None = None

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        """Connect to the mount and start the background tasks."""
        self.link.on_event = self._on_link_event
        self.link.start()
        loop = asyncio.get_running_loop()
        self._tasks = [loop.create_task(self._monitor(), name="vss-monitor"),
                       loop.create_task(self.timesync.run(), name="vss-timesync")]

    async def close(self) -> None:
        """Stop everything: a running operation is aborted and the mount brought to rest."""
        if self.op is not None and self.op.task is not None:
            self.op.task.cancel()
            with contextlib.suppress(BaseException):
                await self.op.task
        for task in [*self._tasks, self._stream_task]:
            if task is not None:
                task.cancel()
                with contextlib.suppress(BaseException):
                    await task
        await self.link.stop()

    def _on_link_event(self, kind: str, data: dict[str, Any]) -> None:
        self.emit(kind, data)
        if kind == "mount_connected":
            self._stream_task = asyncio.get_running_loop().create_task(self._on_connected())
        elif kind == "mount_disconnected":
            self._mount_state = None
            if self.op is not None and self.op.task is not None and not self.op.task.done():
                self._abort(MountUnavailable("lost the connection to the mount"))

    async def _on_connected(self) -> None:
        try:
            await self._after_connecting()
        except Exception:  # a task that dies unseen would leave the track never resumed
            log.exception("after the mount connected: setting up or resuming failed")

    async def _after_connecting(self) -> None:
        for attempt in range(5):  # a loaded host may time a first request out: try again
            try:
                await self._read_limits()
                await self._start_error_stream()
                break
            except VssError as exc:
                log.warning("after connecting (attempt %d): %s", attempt + 1, exc)
                await asyncio.sleep(0.2)
                if not self.link.connected:
                    return
        try:
            if self._resume is not None and self.active:
                resume, self._resume = self._resume, None
                op = await resume()
                self.emit("resumed", op.as_dict())
        except VssError as exc:
            log.warning("after reconnecting: %s", exc)

    async def _read_limits(self) -> None:
        m = self.link.mapping
        roles = [r for r in ("az_slew_rate_limit", "el_slew_rate_limit", "az_slew_accel_limit",
                             "el_slew_accel_limit", "az_track_rate_limit", "az_min", "az_max",
                             "el_min", "el_max") if m.has(r)]
        v = {k: math.degrees(x) for k, x in (await self.link.read(roles)).items()}
        d = MountLimits()
        self.limits = MountLimits(
            wrap_min_deg=v.get("az_min", d.wrap_min_deg), wrap_max_deg=v.get("az_max", d.wrap_max_deg),
            el_min_deg=max(v.get("el_min", d.el_min_deg), self.config.horizon_deg),
            el_max_deg=v.get("el_max", d.el_max_deg),
            az_max_rate_deg_s=v.get("az_slew_rate_limit", d.az_max_rate_deg_s),
            el_max_rate_deg_s=v.get("el_slew_rate_limit", d.el_max_rate_deg_s),
            az_max_accel_deg_s2=v.get("az_slew_accel_limit", d.az_max_accel_deg_s2),
            el_max_accel_deg_s2=v.get("el_slew_accel_limit", d.el_max_accel_deg_s2))
        self.track_rate_limit_deg_s = v.get("az_track_rate_limit", self.limits.az_max_rate_deg_s)

    async def _start_error_stream(self) -> None:
        link = self.link
        stream = await link.stream(["az_error", "el_error", "el_position"], self.config.error_rate_hz)
        names = stream.names
        s_az, s_el, s_pos = (link.scale("az_error"), link.scale("el_error"),
                             link.scale("el_position"))

        def on_packet(packet) -> None:
            self.errors.add(packet.t_us, packet.column(names[0]) * s_az,
                            packet.column(names[1]) * s_el, packet.column(names[2]) * s_pos)

        stream.on_packet(on_packet)

    async def _monitor(self) -> None:
        """Watch the mount state; a new fault ends the operation and is reported."""
        fault = self.codes["fault"]
        while True:
            await asyncio.sleep(self.config.poll_wall_s)
            if not self.link.connected:
                continue
            try:
                v = await self.link.read(["mount_state", "az_faults", "el_faults"])
            except VssError:
                continue
            state = int(v["mount_state"])
            if state == fault and self._mount_state != fault:
                text = await self._fault_text(v)
                self.last_fault = text
                self.emit("fault", {"state": "fault", "faults": text})
                if self.op is not None and self.op.task is not None and not self.op.task.done():
                    self._abort(MountFault(f"the mount faulted: {text}"))
            self._mount_state = state

    async def _fault_text(self, v: dict[str, Any]) -> str:
        roles = [r for r in ("az_fault_text", "el_fault_text") if self.link.mapping.has(r)]
        if roles:
            with contextlib.suppress(VssError):
                t = await self.link.read(roles)
                return "; ".join(f"{r[:2]}: {t[r]}" for r in roles)
        return f"az faults {int(v['az_faults'])}, el faults {int(v['el_faults'])}"

    # ------------------------------------------------------------------ mount time
    async def mount_time_us(self) -> int:
        return int((await self.link.read(["mount_time"]))["mount_time"])

    async def wait_until(self, t_us: int, op: Operation | None = None) -> int:
        """Sleep until the mount clock reaches `t_us`; return the mount time then."""
        while True:
            now = await self.mount_time_us()
            left_s = (t_us - now) / 1e6
            if left_s <= 0:
                return now
            if op is not None:
                op.info["seconds_left"] = round(left_s, 1)
            await asyncio.sleep(min(max(left_s / self.config.speed, 0.002), 0.25))

    async def wait_state(self, wanted: tuple[str, ...], timeout_s: float) -> None:
        """Wait (mount time) until the mount state is one of `wanted`; fault raises."""
        codes = {self.codes[w] for w in wanted}
        start = await self.mount_time_us()
        while True:
            v = await self.link.read(["mount_state", "mount_time", "az_faults", "el_faults"])
            state = int(v["mount_state"])
            if state in codes:
                return
            if state == self.codes["fault"]:
                raise MountFault(f"the mount faulted: {await self._fault_text(v)}")
            if (int(v["mount_time"]) - start) / 1e6 > timeout_s:
                raise OperationAborted(f"the mount did not reach {'/'.join(wanted)} within "
                                       f"{timeout_s:g} s (state {self.link.mapping.state_name(state)})")
            await asyncio.sleep(max(0.002, min(0.02, 0.2 / self.config.speed)))

    # ------------------------------------------------------------------ operations
    def _abort(self, error: VssError) -> None:
        op = self.op
        if op is None or op.task is None or op.task.done():
            return
        op.abort_error = error
        op.task.cancel()

    async def run_operation(self, kind: str, target: str,
                            body: Callable[[Operation], Awaitable[dict[str, Any]]],
                            *, resume: Callable[[], Awaitable[Operation]] | None = None) -> Operation:
        """Replace the running operation by a new one and start it; return it at once."""
        if not self.active:
            raise NotActive("the server is passive (it only watches the mount): send "
                            "'set_mode' with mode=active first")
        if not self.link.connected:
            raise MountUnavailable(f"the mount at {self.link.config.url} is not connected "
                                   f"({self.link.last_error or 'connecting'})")
        await self.cancel_operation("replaced by a new operation")
        loop = asyncio.get_running_loop()
        op = Operation(next(self._ids), kind, target, begun=loop.create_future(),
                       done=loop.create_future())
        self.op = op
        self._resume = None
        op.task = loop.create_task(self._run(op, body, resume), name=f"vss-op-{op.id}")
        self.emit("operation", op.as_dict())
        return op

    async def _run(self, op: Operation, body, resume) -> None:
        try:
            result = await body(op)
        except asyncio.CancelledError:
            error: VssError = op.abort_error or OperationAborted("cancelled (server shutting down)")
            phase = "aborted"
        except VssError as exc:
            error = exc
            phase = "aborted" if exc.code == MountUnavailable.code else "failed"
        except Exception as exc:  # a bug must not kill the server: report it
            log.exception("operation %s failed", op.id)
            self._finish(op, "failed", {"code": "internal", "message": f"{type(exc).__name__}: {exc}"})
            return
        else:
            op.info.update(result)
            self._finish(op, "done", None)
            return
        err = {"code": error.code, "message": str(error)}
        if error.code == MountUnavailable.code and resume is not None:
            # A cut line ends the operation either through its own request failing or through
            # the abort sent on the disconnect event, whichever comes first: both must resume.
            self._resume = resume
            err["message"] += "; the track resumes when the mount is back"
        self._finish(op, phase, err)
        await self._safe_stop_after_abort(error.code)

    def _finish(self, op: Operation, phase: str, error: dict | None) -> None:
        for fn in op.cleanup:
            fn()
        op.phase = phase
        if error is not None:
            op.info["error"] = error
        for fut in (op.begun, op.done):
            if fut is not None and not fut.done():
                fut.set_result(op)
        self.feeder = None
        self.emit("operation", op.as_dict())

    async def _safe_stop_after_abort(self, code: str) -> None:
        if code in ("mount_offline", "mount_fault") or not self.link.connected:
            return
        with contextlib.suppress(VssError):
            await self._halt()

    def _phase(self, op: Operation, phase: str, **info: Any) -> None:
        op.phase = phase
        op.info.update(info)
        self.emit("operation", op.as_dict())

    def _begun(self, op: Operation) -> None:
        if op.begun is not None and not op.begun.done():
            op.begun.set_result(op)

    async def cancel_operation(self, reason: str) -> None:
        op = self.op
        if op is not None and op.task is not None and not op.task.done():
            op.abort_error = OperationAborted(reason)
            op.task.cancel()
            with contextlib.suppress(BaseException):
                await op.task

    async def _halt(self) -> None:
        """Bring a moving mount to rest (tracking: abort the trajectory)."""
        v = await self.link.read(["mount_state"])
        state = int(v["mount_state"])
        c = self.codes
        if state == c["tracking"]:
            await self.link.call("traj_reset")
        elif state in (c["slewing"], c["manual"]):
            await self.link.call("stop")
        else:
            return
        await self.wait_state(("holding", "off"), 120.0)

    async def _prepare(self) -> None:
        v = await self.link.read(["mount_state", "az_faults", "el_faults"])
        state = int(v["mount_state"])
        c = self.codes
        if state == c["fault"]:
            raise MountFault(f"the mount is in FAULT ({await self._fault_text(v)}): reset the "
                             "faults first (vs stop --reset-faults, or the 'reset_faults' command)")
        if state in (c["tracking"], c["slewing"], c["manual"], c["stopping"]):
            await self._halt()
            if state == c["stopping"]:
                await self.wait_state(("holding", "off"), 120.0)
        axes = await self.link.read(["az_state", "el_state"])
        if c["off"] in (int(axes["az_state"]), int(axes["el_state"])):
            await self.link.call("power_on")  # closes the loops of the axes that are off

    async def _positions(self) -> tuple[float, float, int]:
        v = await self.link.read(["az_position", "el_position", "mount_time"])
        return float(v["az_position"]), float(v["el_position"]), int(v["mount_time"])

    async def _goto(self, op: Operation, az_rad: float, el_rad: float) -> None:
        lim = self.limits
        if not (math.radians(lim.wrap_min_deg) <= az_rad <= math.radians(lim.wrap_max_deg)):
            raise TargetUnreachable(f"azimuth {math.degrees(az_rad):.3f} deg is outside the "
                                    f"cable wrap {lim.wrap_min_deg:g}..{lim.wrap_max_deg:g} deg")
        await self.link.call("slew", math.degrees(az_rad), math.degrees(el_rad))
        self._phase(op, "slewing", to_az_deg=math.degrees(az_rad), to_el_deg=math.degrees(el_rad))
        await self.wait_state(("holding",), 600.0)

    async def _acquire_and_follow(self, op: Operation, path, *, slew_start_us: int,
                                  join_us: int | None = None, end_us: int | None = None,
                                  phase: str = "tracking") -> tuple[int, Feeder]:
        """Slew to the run-up of `path`, start the trajectory; return (join time, feeder).

        join_us: the earliest join (a satellite pass start); None joins as soon as the
        slew allows. When a slow host makes a slew or the priming late, the join is
        planned again from where the mount is (a pass is then joined a little later).
        """
        cfg = self.config
        lead = cfg.start_lead_s
        for _attempt in range(4):
            az, el, now = await self._positions()
            guess_s = 0.0
            for _ in range(3):
                j = now + int((guess_s + lead + cfg.ramp_s) * 1e6)
                if join_us is not None:
                    j = max(j, join_us)
                p = path.sample(np.array([j], np.int64))
                rest_az = p.az_rad[0] - 0.5 * p.az_rate_rad_s[0] * cfg.ramp_s
                rest_el = p.el_rad[0] - 0.5 * p.el_rate_rad_s[0] * cfg.ramp_s
                guess_s = plan_slew(az, el, rest_az, rest_el, self.limits).duration_s * 1.05 + 1.5
            join = now + int((guess_s + lead + cfg.ramp_s) * 1e6)
            if join_us is not None:
                join = max(join, join_us)
            if end_us is not None and join > end_us - 10_000_000:
                raise TargetUnreachable("too little of the path is left to join it")
            ramp = RampIn(path, join, cfg.ramp_s)
            await self._goto(op, float(ramp.rest_rad[0]), float(ramp.rest_rad[1]))
            now = await self.mount_time_us()
            if now + int(lead * 1e6) >= ramp.begin_us:
                continue  # the slew ended too late: plan again from here
            op.info["join_us"] = ramp.join_us
            if ramp.begin_us - now > cfg.feed_lead_s * 1e6:
                self._phase(op, "waiting", start_utc=_iso(ramp.begin_us))
                self._begun(op)
                await self.wait_until(ramp.begin_us - int((cfg.feed_lead_s - lead) * 1e6), op)
            await self.link.call("traj_init")
            fcfg = FeederConfig(point_rate_hz=cfg.point_rate_hz, lead_s=cfg.feed_lead_s,
                                min_lead_s=min(0.5, lead / 2), speed=cfg.speed)
            feeder = Feeder(self.link, fcfg, ramp, ramp.begin_us,
                            fault_code=self.codes["fault"], tracking_code=self.codes["tracking"])
            await feeder.cycle()
            if feeder.stats.rejected or feeder.stats.first_point_us != ramp.begin_us:
                # the host stalled past the start of the run-up: never start half-way up a
                # ramp; the mount has not been told to follow, so plan again
                log.warning("operation %s: trajectory primed too late, planning again", op.id)
                continue
            break
        else:
            raise TargetUnreachable("could not catch up with the target after 4 attempts "
                                    "(host too slow for this simulation speed?)")
        await self.link.call("traj_start")
        feeder.started = True
        self.feeder = feeder
        # the feeder runs from here on, also while the caller waits for the landing
        feeder.task = asyncio.get_running_loop().create_task(feeder.run(), name="vss-feeder")
        op.cleanup.append(feeder.task.cancel)
        self._phase(op, "joining" if phase == "tracking" else phase)
        return ramp.join_us, feeder

    def _prep_s(self, slew_s: float) -> float:
        """Return the mount seconds needed before a path can be joined after a slew of `slew_s`."""
        cfg = self.config
        return slew_s * 1.05 + 3.0 + cfg.start_lead_s + cfg.ramp_s

    async def _settle(self, op: Operation, join_us: int, slew_start_us: int) -> dict[str, Any]:
        await self.wait_until(join_us + int(self.config.settle_s * 1e6), op)
        s = self.errors.stats(join_us, join_us + int(self.config.settle_s * 1e6))
        return {"slew_time_s": (join_us - slew_start_us) / 1e6,
                "landing_rms_arcsec": s.rms_arcsec, "landing_peak_arcsec": s.peak_arcsec,
                "slew_from_us": slew_start_us, "landed_us": join_us}

    async def _run_feeder_until(self, op: Operation, feeder: Feeder, end_us: int | None,
                                end_reason: str = "duration elapsed") -> str:
        """Let the feeder run until the mount clock reaches `end_us` or the path ends."""
        task = feeder.task
        reason = ""
        try:
            while not reason:
                now = await self.mount_time_us()
                if end_us is not None and now >= end_us:
                    reason = end_reason
                    break
                if task.done():
                    exc = task.exception()
                    if isinstance(exc, TargetUnreachable):
                        reason = f"the target left the limits: {exc}"
                    elif exc is not None:
                        raise exc
                    elif end_us is None:
                        reason = "the path ended"
                    if reason:  # let the points already buffered play out
                        await self.wait_until(feeder.stats.last_point_us - 200_000)
                        break
                op.info["feeder"] = feeder.stats.as_dict()
                await asyncio.sleep(min(0.25, max(0.01, 1.0 / self.config.speed)))
        finally:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
        op.info["feeder"] = feeder.stats.as_dict()
        return reason

    # -- public operations --------------------------------------------------------------------
    async def follow_target(self, target, name: str, *, kind: str = "track",
                            duration_s: float | None = None) -> Operation:
        """Slew to `target` and track it (for `duration_s` mount seconds, or until stopped)."""

        async def body(op: Operation) -> dict[str, Any]:
            await self._prepare()
            az, _el, start = await self._positions()
            path = TargetPath(target, self.config.site, limits=self.limits, eop=self._eop,
                              model=self.model, current_az_rad=az)
            join, feeder = await self._acquire_and_follow(op, path, slew_start_us=start)
            landing = await self._settle(op, join, start)
            op.info.update(landing)
            self._phase(op, "tracking", tracking_from_us=join + int(self.config.settle_s * 1e6))
            self._begun(op)
            self.emit("slew_done", {"id": op.id, **landing})
            end = None if duration_s is None else join + int((self.config.settle_s + duration_s) * 1e6)
            reason = await self._run_feeder_until(op, feeder, end)
            track_to = await self.mount_time_us()
            await self._halt()
            s = self.errors.stats(op.info["tracking_from_us"], track_to)
            return {"ended": reason, "tracking_to_us": track_to, "tracking_rms_arcsec": s.rms_arcsec,
                    "tracking_peak_arcsec": s.peak_arcsec}

        async def resume() -> Operation:
            return await self.follow_target(target, name, kind=kind, duration_s=None)

        return await self.run_operation(kind, name, body, resume=resume)

    async def slew_altaz(self, az_deg: float, el_deg: float, *, kind: str = "slew",
                         power_off: bool = False) -> Operation:
        """Slew to a fixed observed direction and hold there (park: then power off)."""
        lim = self.limits
        if not lim.el_min_deg - self.config.horizon_deg <= el_deg <= lim.el_max_deg:
            raise TargetUnreachable(f"elevation {el_deg:g} deg is outside the mount's range "
                                    f"{lim.el_min_deg - self.config.horizon_deg:g}.."
                                    f"{lim.el_max_deg:g} deg")

        async def body(op: Operation) -> dict[str, Any]:
            await self._prepare()
            az0, _, start = await self._positions()
            t = FixedAltAz(az_deg % 360.0, el_deg)
            enc = TargetPath(t, self.config.site, limits=self.limits, eop=self._eop,
                             model=self.model, current_az_rad=az0).sample(np.array([start]))
            enc_az, enc_el = float(enc.az_rad[0]), float(enc.el_rad[0])
            await self._goto(op, enc_az, enc_el)
            v = await self.link.read(["az_position", "el_position", "mount_time"])
            d_az = (float(v["az_position"]) - enc_az) * math.cos(enc_el)
            d_el = float(v["el_position"]) - enc_el
            err = math.degrees(math.hypot(d_az, d_el)) * 3600.0
            if power_off:
                await self.link.call("power_off")
            return {"slew_time_s": (int(v["mount_time"]) - start) / 1e6, "landing_rms_arcsec": err,
                    "landing_peak_arcsec": err, "slew_from_us": start,
                    "landed_us": int(v["mount_time"])}

        return await self.run_operation(kind, f"az {az_deg:g} el {el_deg:g}", body)

    async def park(self) -> Operation:
        m = self.link.mapping
        return await self.slew_altaz(m.park_az_deg, m.park_el_deg, kind="park", power_off=True)

    async def pointing_sample(self, target, name: str, *, settle_s: float = 2.0) -> Operation:
        """Point at a sky target, hold, and measure the star's offset with the guide camera.

        The mount is sent to the target's observed place at the exposure instant
        t_exp (through the pointing model, if one is loaded) and *held* there, so the
        encoders and the star's place given to the camera refer to the same instant
        however long the requests take. The result (`op.info["sample"]`) gives the
        star's observed place, the encoders, the camera offset (star − optical axis,
        ΔA·cos E and ΔE, arcsec) and the sky place on the optical axis, which is what
        a TPOINT record pairs with the encoders (docs/vss-api.md). Raises MappingError
        when the mount has no guide camera (no `guide_measure` role).
        """
        if not self.link.mapping.has_function("guide_measure"):
            raise MappingError(f"{self.link.mapping.source}: no 'guide_measure' function role: "
                               "this mount has no guide camera, so pointing samples cannot be "
                               "measured (map it to the camera's measure(star_az_deg, "
                               "star_el_deg) -> [dx_arcsec, dy_arcsec] function)")
        if not settle_s >= 0:
            raise BadRequest(f"settle_s={settle_s}: expected >= 0 mount seconds")
        cfg = self.config

        async def body(op: Operation) -> dict[str, Any]:
            await self._prepare()
            az0, el0, start = await self._positions()
            # where the star will be when the mount has landed and settled
            o = observe_mount_times(target, np.array([start], np.int64), cfg.site, self._eop)
            slew_s = plan_slew(az0, el0, float(o.az_rad[0]), float(o.el_rad[0]),
                               self.limits).duration_s
            t_exp = start + int((slew_s * 1.05 + 1.0 + settle_s) * 1e6)
            o = observe_mount_times(target, np.array([t_exp], np.int64), cfg.site, self._eop)
            star_az, star_el = math.degrees(float(o.az_rad[0])) % 360.0, math.degrees(float(o.el_rad[0]))
            if not self.limits.el_min_deg <= star_el <= self.limits.el_max_deg:
                raise TargetUnreachable(f"{name} is at elevation {star_el:.2f} deg, outside the "
                                        f"limits {self.limits.el_min_deg:g}..{self.limits.el_max_deg:g} deg")
            enc = TargetPath(FixedAltAz(star_az, star_el), cfg.site, limits=self.limits,
                             eop=self._eop, model=self.model,
                             current_az_rad=az0).sample(np.array([t_exp], np.int64))
            await self._goto(op, float(enc.az_rad[0]), float(enc.el_rad[0]))
            now = await self.mount_time_us()
            await self.wait_until(max(now + int(settle_s * 1e6), t_exp), op)
            v = await self.link.read(["az_position", "el_position", "mount_time"])
            dx, dy = (float(x) for x in await self.link.call("guide_measure", star_az, star_el))
            enc_az, enc_el = math.degrees(float(v["az_position"])), math.degrees(float(v["el_position"]))
            # the sky place on the optical axis: the star minus its offset from the axis
            axis_el = star_el - dy / 3600.0
            axis_az = star_az - dx / 3600.0 / math.cos(math.radians(star_el))
            return {"sample": {
                "target": name, "slew_time_s": (now - start) / 1e6, "t_exp_us": t_exp, "utc": _iso(t_exp),
                "measured_us": int(v["mount_time"]),
                "star": {"az_deg": star_az, "el_deg": star_el},
                "encoder": {"az_deg": enc_az, "el_deg": enc_el},
                "offset_arcsec": {"dx": dx, "dy": dy, "total": math.hypot(dx, dy)},
                "axis": {"az_deg": axis_az, "el_deg": axis_el},
                "pointing_model": self.model_source or None}}

        return await self.run_operation("pointing_sample", name, body)

    async def track_satellite(self, sat: Satellite, *, max_wait_s: float | None = None) -> Operation:
        """Wait for the next pass of `sat` above the horizon limit and track it through."""
        cfg = self.config

        async def body(op: Operation) -> dict[str, Any]:
            await self._prepare()
            az, el, now = await self._positions()
            start = UtcTimes.from_unix_us(now)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                passes = satellite_passes(sat, cfg.site, start, start.shifted(cfg.pass_search_s),
                                          min_el_deg=self.limits.el_min_deg, eop=self._eop)
            chosen = None
            for p in passes:
                if p.set is None:
                    continue
                rise_us = int(p.rise.utc.to_unix_us()[0]) if p.rise else now
                set_us = int(p.set.utc.to_unix_us()[0])
                begin = max(rise_us, now + int(self._prep_s(0.0) * 1e6))
                if begin + 30_000_000 > set_us:
                    continue
                # time to slew from here to where the pass starts, run-up included
                o = observe_mount_times(sat, np.array([begin], np.int64), cfg.site, self._eop)
                to_az = float(unwrap_azimuth(o.az_rad, limits=self.limits, current_az_rad=az)[0])
                slew_s = plan_slew(az, el, to_az, float(o.el_rad[0]), self.limits).duration_s
                begin = max(begin, now + int(self._prep_s(slew_s) * 1e6))
                if begin + 30_000_000 <= set_us:  # at least 30 s of the pass left to track
                    chosen = p
                    break
            if chosen is None:
                raise TargetUnreachable(f"{sat.name} has no pass above "
                                        f"{self.limits.el_min_deg:g} deg in the next "
                                        f"{cfg.pass_search_s / 3600:g} h")
            if max_wait_s is not None and begin - now > max_wait_s * 1e6:
                raise TargetUnreachable(f"the next pass of {sat.name} begins in "
                                        f"{(begin - now) / 1e6:.0f} s, more than the "
                                        f"{max_wait_s:g} s allowed")
            plan = plan_satellite_pass(
                sat, cfg.site, begin, set_us, step_s=cfg.sat_grid_s, limits=self.limits,
                track_rate_limit_deg_s=self.track_rate_limit_deg_s * cfg.keyhole_rate_fraction,
                accel_limit_deg_s2=self.limits.az_max_accel_deg_s2, eop=self._eop,
                model=self.model, current_az_rad=az)
            op.info.update({"pass_start_us": begin, "pass_end_us": set_us,
                            "pass_start_utc": _iso(begin), "pass_end_utc": _iso(set_us),
                            "culmination_el_deg": chosen.culmination.el_deg,
                            "keyhole": plan.keyhole_limited,
                            "keyhole_max_error_arcsec": plan.keyhole_max_error_arcsec,
                            "max_az_rate_deg_s": plan.max_az_rate_deg_s})
            self._phase(op, "pass planned")
            # run out to rest after set, and hold: stopping a little late costs nothing
            path = RampOut(plan.path, cfg.ramp_s, max(2.0, 1.0 * cfg.speed))
            join, feeder = await self._acquire_and_follow(op, path, slew_start_us=now,
                                                          join_us=begin, end_us=set_us,
                                                          phase="waiting")
            self._begun(op)
            self._phase(op, "tracking", tracking_from_us=join)
            reason = await self._run_feeder_until(op, feeder, set_us, "the pass ended")
            track_to = min(await self.mount_time_us(), set_us)  # not the run-out after set
            await self._halt()
            s = self.errors.stats(join, track_to)
            return {"ended": reason, "tracking_to_us": track_to, "tracking_rms_arcsec": s.rms_arcsec,
                    "tracking_peak_arcsec": s.peak_arcsec}

        async def resume() -> Operation:
            return await self.track_satellite(sat, max_wait_s=max_wait_s)

        return await self.run_operation("track_satellite", sat.name, body, resume=resume)

    async def stop(self, *, reset_faults: bool = False) -> dict[str, Any]:
        """Stop any operation and bring the mount to rest; optionally clear latched faults."""
        if not self.active:
            raise NotActive("the server is passive: send 'set_mode' with mode=active first")
        self._resume = None
        await self.cancel_operation("stopped by a client")
        if reset_faults:
            await self.link.call("reset_faults")
            self.last_fault = ""
        with contextlib.suppress(MountFault):
            await self._halt()
        v = await self.link.read(["mount_state"])
        return {"mount_state": self.link.mapping.state_name(int(v["mount_state"]))}

    def set_mode(self, mode: str) -> dict[str, Any]:
        if mode not in ("active", "passive"):
            raise BadRequest(f"mode {mode!r}: expected 'active' or 'passive'")
        self.active = mode == "active"
        self.timesync.active = self.active  # a passive server sends the mount nothing
        self.emit("mode", {"mode": mode})
        return {"mode": mode}

    def load_model(self, path: str) -> dict[str, Any]:
        from pointing_model import PointingModelError, load_model

        try:
            self.model = load_model(path)
        except (PointingModelError, OSError, ValueError) as exc:
            raise BadRequest(f"cannot load pointing model {path}: {exc}") from None
        self.model_source = str(path)
        return {"pointing_model": self.model_source, "terms": self.model.as_dict()}

    def unload_model(self) -> dict[str, Any]:
        self.model, self.model_source = None, ""
        return {"pointing_model": None}

    # -- status ------------------------------------------------------------------------------
    async def status(self) -> dict[str, Any]:
        """Return encoder and observed positions, RA/Dec, states, mount time, error statistics."""
        out: dict[str, Any] = {"connected": self.link.connected, "url": self.link.config.url,
                               "mode": "active" if self.active else "passive",
                               "simulated": self.config.simulated, "speed": self.config.speed,
                               "pointing_model": self.model_source or None,
                               "site": {k: getattr(self.config.site, k) for k in _SITE_KEYS},
                               "operation": self.op.as_dict() if self.op else None,
                               "last_fault": self.last_fault or None,
                               "time_sync": self.timesync.status.as_dict(),
                               "tracking_error": {f"{w}s": self.errors.window(w).as_dict()
                                                  for w in (1, 10, 60)}}
        if not self.link.connected:
            out["mount_error"] = self.link.last_error
            return out
        m = self.link.mapping
        roles = list(_STATUS_ROLES) + [r for r in _OPTIONAL_STATUS if m.has(r)]
        v = await self.link.read(roles)
        enc_az, enc_el, t_us = float(v["az_position"]), float(v["el_position"]), int(v["mount_time"])
        obs_az, obs_el = math.degrees(enc_az), math.degrees(enc_el)
        if self.model is not None:
            a, e = self.model.encoder_to_observed(np.array([obs_az % 360.0]), np.array([obs_el]))
            obs_az, obs_el = float(np.asarray(a)[0]), float(np.asarray(e)[0])
        ra, dec = self._radec(obs_az % 360.0, obs_el, t_us)
        out.update({
            "mount_time_us": t_us, "mount_time_utc": _iso(t_us),
            "mount_state": m.state_name(int(v["mount_state"])),
            "encoder": {"az_deg": math.degrees(enc_az), "el_deg": math.degrees(enc_el)},
            "observed": {"az_deg": obs_az % 360.0, "el_deg": obs_el},
            "radec": {"ra_deg": ra, "dec_deg": dec},
            "axes": {ax: {"state": m.state_name(int(v[f"{ax}_state"])),
                          "faults": int(v[f"{ax}_faults"]),
                          "fault_text": v.get(f"{ax}_fault_text")} for ax in ("az", "el")},
            "buffer": {"free_points": int(v["free_points"]),
                       "points": v.get("buffered_points"), "underruns": v.get("underruns"),
                       "late_points": v.get("late_points")},
        })
        return out

    def _radec(self, az_deg: float, el_deg: float, t_us: int) -> tuple[float, float]:
        """Return ICRS RA/Dec (deg) of an observed direction at mount time (ERFA atoc13)."""
        site = self.config.site
        t = UtcTimes.from_unix_us(t_us)
        dut1, xp, yp = self._eop.interpolate(t.jd1, t.jd2, warn=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            ra, dec = erfa.atoc13("A", math.radians(az_deg), math.radians(90.0 - el_deg),
                                  t.jd1[0], t.jd2[0], float(dut1[0]), site.lon_rad, site.lat_rad,
                                  site.height_m, float(xp[0]), float(yp[0]), site.pressure_hpa,
                                  site.temperature_c, site.humidity, site.wavelength_um)
        return math.degrees(float(ra)) % 360.0, math.degrees(float(dec))


def _iso(t_us: int) -> str:
    return UtcTimes.from_unix_us(int(t_us)).iso(3)[0]


def parse_target(params: dict[str, Any]) -> tuple[Any, str, tuple[float, float] | None]:
    """Return (astro target, display name, fixed alt-az or None) from request parameters.

    Exactly one of ``radec`` ("RA DEC" text), ``ra_deg``+``dec_deg``, ``star`` (name),
    ``altaz`` ("AZ EL" text) or ``az_deg``+``el_deg`` must be given. Raises BadRequest.
    """
    given = [k for k in ("radec", "ra_deg", "star", "altaz", "az_deg") if params.get(k) is not None]
    if len(given) != 1:
        raise BadRequest("give exactly one target: radec (\"RA DEC\"), ra_deg+dec_deg, star "
                         f"(a name), altaz (\"AZ EL\") or az_deg+el_deg; got {given or 'none'}")
    key = given[0]
    try:
        if key == "radec":
            ra, dec = parse_radec(str(params["radec"]))
            return IcrsStar(ra, dec, name=f"RA {ra:.4f} Dec {dec:+.4f}"), str(params["radec"]), None
        if key == "ra_deg":
            ra, dec = _number(params, "ra_deg"), _number(params, "dec_deg")
            if not (0 <= ra < 360 and -90 <= dec <= 90):
                raise BadRequest(f"ra_deg={ra}, dec_deg={dec}: expected 0 <= ra < 360, -90 <= dec <= 90")
            return IcrsStar(ra, dec, name=f"RA {ra:.4f} Dec {dec:+.4f}"), f"RA {ra:g} Dec {dec:g}", None
        if key == "star":
            target = resolve_target(str(params["star"]))
            return target, getattr(target, "name", "") or str(params["star"]), None
        if key == "altaz":
            parts = str(params["altaz"]).replace(",", " ").split()
            if len(parts) != 2:
                raise BadRequest(f"altaz {params['altaz']!r}: expected \"AZ EL\" in degrees, "
                                 "e.g. \"180 45\"")
            try:
                az, el = float(parts[0]), float(parts[1])
            except ValueError:
                raise BadRequest(f"altaz {params['altaz']!r}: both values must be numbers "
                                 "(degrees), e.g. \"180 45\"") from None
        else:
            az, el = _number(params, "az_deg"), _number(params, "el_deg")
    except AstroError as exc:
        raise BadRequest(str(exc)) from None
    if not (math.isfinite(az) and -90.0 <= el <= 90.0):
        raise BadRequest(f"az {az}, el {el}: expected a finite azimuth and -90 <= el <= 90 degrees")
    return None, f"az {az:g} el {el:g}", (az, el)


def _number(params: dict[str, Any], key: str) -> float:
    value = params.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise BadRequest(f"{key}={value!r}: expected a finite number")
    return float(value)

