"""The telescope as the VSS drives it: the mount link, its watchers, and the commands.

`Telescope` puts the parts together: the `MountLink`, TimeS, the tracking-error
history fed by the mount's error stream, the motion primitives, and the
`Supervisor`, which owns every operation. Commands that move the mount are
checked here (active, connected, parameters in range) and handed to the
supervisor with their procedure (`procedures.py`); commands that only read
(status, errors) never wait for it.

The mount is watched two ways: the error stream carries the mount state with
every sample, so a fault ends the operation within one stream packet; a slow
poll (once a mount second) catches what the stream cannot, and in paced time
notices a mount clock that has stopped.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import erfa
import numpy as np

from astcom_client.events import EventLog
from virtualstar.astro import (
    AvoidanceZones,
    EarthOrientation,
    MountLimits,
    Satellite,
    Site,
    UtcTimes,
    check_places,
    iso_utc,
)
from virtualstar.astro.constants import ARCSEC_PER_RAD

from . import on_target, procedures, tracking_errors
from .clock import Margins, MountClock, PacedClock
from .event_log import KEPT_APART
from .exceptions import (
    BadRequest,
    MappingError,
    MountFault,
    MountUnavailable,
    NotActive,
    OperationAborted,
    StoppedByClient,
    TargetUnreachable,
    Unsupported,
    VssError,
)
from .feeder import FeederConfig
from .hand_pad import RATES_NOTE, RESTART_NOTE, HandPad
from .link_interface import MountBackend
from .motion import Motion
from .offset_path import sky_rate_arcsec_s
from .on_target import OnTarget
from .operations import Operation
from .programs import ProgramControl
from .safety import HOLD_LOOKAHEAD_S, Safety
from .steering import Steering
from .supervisor import Supervisor
from .timesync import TimeSync
from .tracking_errors import TrackingErrorHistory
from .trajectories import Points

__all__ = ["Operation", "Telescope", "TelescopeConfig"]

log = logging.getLogger("virtualstar.server")

_STATUS_ROLES = ("az_position", "el_position", "az_state", "el_state", "az_faults", "el_faults",
                 "mount_state", "mount_time", "free_points")
_SITE_KEYS = ("lat_deg", "lon_deg", "height_m", "pressure_hpa", "temperature_c", "humidity")
_OPTIONAL_STATUS = ("az_fault_text", "el_fault_text", "buffered_points", "underruns",
                    "late_points")
_LIMIT_ROLES = ("az_slew_rate_limit", "el_slew_rate_limit", "az_slew_accel_limit",
                "el_slew_accel_limit", "az_track_rate_limit", "az_min", "az_max", "el_min",
                "el_max")
WATCH_S = 1.0  # mount seconds between the slow polls of the mount state
STALL_WALL_S = 5.0  # paced time: a mount clock standing this long (wall) is a lost mount
SUN_WATCH_US = 60_000_000  # a mount at rest is checked against the zones once a mount minute


@dataclass(frozen=True)
class TelescopeConfig:
    """How the VSS drives the mount (mount seconds unless the name says otherwise)."""

    site: Site
    simulated: bool = False  # the mount's UTC truth is UTC (an emulator), not the host clock
    point_rate_hz: float = 20.0
    lead_s: float | None = None  # None: from the clock (clock.Margins)
    error_rate_hz: float = 1000.0
    ramp_s: float = 2.0
    settle_s: float = 1.0
    horizon_deg: float = 5.0
    sat_grid_s: float = 0.1
    pass_search_s: float = 2 * 86400.0
    min_pass_track_s: float = 30.0
    keyhole_rate_fraction: float = 0.9
    active: bool = True
    timesync_period_s: float = 10.0
    arrival_tolerance_arcsec: float = 5.0
    off_target_arcsec: float = 5.0  # the boresight farther than this from the target is off it
    degraded_after_s: float = 1.0  # a track off target longer than this is `degraded`
    max_tle_age_days: float = 14.0
    resume_timeout_s: float = 60.0  # wall seconds an interrupted track waits for the mount
    zones: AvoidanceZones = AvoidanceZones()  # Sun (30°), Moon, horizon profile
    hold_lookahead_s: float = HOLD_LOOKAHEAD_S  # a fixed hold must stay out of the zones this long
    offset_rate_arcsec_s: float = 1800.0  # how fast an offset moves the boresight (steering.py)
    offset_accel_arcsec_s2: float = 3600.0
    mount_endpoint: str = ""  # where ASTCom clients reach the mount ('' unknown or nowhere)


class Telescope:
    """Drive one mount through its mount link (`link_interface.MountBackend`); emit events through `emit(kind, data)`."""

    def __init__(self, link: MountBackend, config: TelescopeConfig, clock: MountClock | None = None,
                 emit: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self.link = link
        self.config = config
        self.clock = clock or PacedClock()
        self.margins = Margins.for_clock(self.clock, config.lead_s)  # the time mode's margins
        self.emit = emit or (lambda kind, data: None)
        self.codes = link.mapping.state_codes
        self.errors = TrackingErrorHistory(off_target_arcsec=config.off_target_arcsec)
        self.timesync = TimeSync(link, self.clock, simulated=config.simulated,
                                 period_s=config.timesync_period_s,
                                 on_offset=self.errors.note_clock_offset)
        self.active = config.active
        self.timesync.active = config.active
        self.model = None
        self.model_source = ""
        self.limits = MountLimits()
        self.track_rate_limit_deg_s = 6.0
        self.eop = EarthOrientation.from_astropy_iers_data()
        self.on_target = OnTarget(config.site, self.eop)  # the target followed, for the truth
        self.motion = Motion(link, self.clock)
        self.safety = Safety(config.zones, config.site, self.eop, lambda: self.limits)
        self.supervisor = Supervisor(link, self.motion, emit=lambda k, d: self.emit(k, d),
                                     resume_timeout_s=config.resume_timeout_s)
        self.last_fault = ""
        self._mount_state: int | None = None
        self._tasks: set[asyncio.Task] = set()
        self.programs = ProgramControl(self, lambda kind, data: self.emit(kind, data))
        self.steering = Steering(self)  # offsets and guide pulses of the running track
        self.log = EventLog("vss", kept_apart=KEPT_APART)
        self.last_mount_us: int | None = None  # the newest tracking-error sample's time
        self.signals_url: str | None = None  # where a rate-driven mount's reports are served
        self.signals = None

    def log_event(self, level: str, kind: str, message: str, **fields: Any) -> None:
        """Log an event at the mount time last seen; before any sample, the lockstep
        clock's mount time, or in real time the host's UTC (mount time is UTC there)."""
        t_us = self.last_mount_us
        if t_us is None:
            t_us = getattr(self.clock, "now_us", None)
        if t_us is None:
            t_us = time.time_ns() // 1000
        self.log.add(int(t_us), level, kind, message, **fields)

    @property
    def op(self) -> Operation | None:
        return self.supervisor.op

    @property
    def time_mode(self) -> str:
        """lockstep (one clock with the embedded emulator), paced (a simulated mount running
        by itself) or real time: from the clock and the mount."""
        if self.clock.lockstep:
            return "lockstep"
        return "paced" if self.config.simulated else "real time"

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> None:
        """Connect to the mount and start the background tasks."""
        tracking_errors.warm_up()  # compiled kernels ready before any client or sample comes
        on_target.warm_up()
        self.link.on_event = self._on_link_event
        if self.signals_url is not None:
            await self._serve_signals(self.signals_url)
        self.link.start()
        self._spawn(self._watch(), "vss-watch")
        self._spawn(self.timesync.run(), "vss-timesync")

    async def _serve_signals(self, url: str) -> None:
        """Serve a rate-driven mount's reports as ASTCom signals (backend_signals.py)."""
        if not hasattr(self.link, "report_listeners"):
            raise BadRequest("--signals: this mount streams its own signals over ASTCom; "
                             "record them from its endpoint")
        from .backend_signals import ReportSignals

        self.signals = ReportSignals(self.link)
        await self.signals.serve(url)

    async def close(self) -> None:
        """Stop everything: a running operation is ended (the mount brought to rest), tasks too."""
        await self.programs.cancel("the server is shutting down")
        await self.supervisor.stop("the server is shutting down",
                                   then=self.motion.halt_quietly if self.link.connected else None)
        tasks = set(self._tasks)
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks)
        await self.steering.close()
        await self.link.stop()
        if self.signals is not None:
            await self.signals.close()

    async def first_samples(self, timeout_s: float) -> None:
        """Wait until the error stream has delivered samples (the VSS is fully up)."""
        async def arrived() -> None:
            while not self.errors.samples:
                await self.clock.sleep(0.01)

        try:
            async with asyncio.timeout(timeout_s):
                await arrived()
        except TimeoutError:
            raise MountUnavailable(f"no tracking-error samples from the mount at "
                                   f"{self.link.config.url} within {timeout_s:g} s") from None

    def _spawn(self, coro, name: str) -> None:
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _on_link_event(self, kind: str, data: dict[str, Any]) -> None:
        self.emit(kind, data)
        if kind == "mount_connected":
            self._spawn(self._after_connecting(), "vss-after-connecting")
        elif kind == "mount_disconnected":
            self._mount_state = None
            if self.link.capabilities.trajectory_buffer:
                self.supervisor.interrupt(MountUnavailable("lost the connection to the mount"))
            else:
                # a mount told rates keeps turning at them: an operation on it cannot wait
                # for the link to come back, it ends with a fault (the link told it to stop)
                self.last_fault = f"lost the driver: {data.get('reason', 'connection lost')}"
                self.supervisor.interrupt(MountFault(
                    f"lost the {self.link.capabilities.backend} driver in the middle of the "
                    f"operation ({data.get('reason', 'connection lost')}); the mount was told "
                    "to stop"))

    async def _after_connecting(self) -> None:
        for attempt in range(5):  # a loaded host may time a first request out: try again
            try:
                await self._read_limits()
                if self.link.capabilities.error_stream:
                    await self._start_error_stream()
                return
            except VssError as exc:
                log.warning("after connecting (attempt %d): %s", attempt + 1, exc)
                if not self.link.connected:
                    return
                await asyncio.sleep(0.2)
        log.error("could not read the mount's limits or start its error stream; "
                  "the next reconnection tries again")
        self.link.mark_lost()

    async def _read_limits(self) -> None:
        m = self.link.mapping
        roles = [r for r in _LIMIT_ROLES if m.has(r)]
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
        if m.has("replace_min_lead"):
            lead = (await self.link.read(["replace_min_lead"]))["replace_min_lead"]
            self.steering.min_lead_us = max(0, int(lead))

    async def _start_error_stream(self) -> None:
        link = self.link
        stream = await link.stream(["az_error", "el_error", "az_position", "el_position",
                                    "mount_state"], self.config.error_rate_hz)
        az_name, el_name, az_pos_name, el_pos_name, state_name = stream.names
        s_az, s_el, s_az_pos, s_el_pos = (link.scale("az_error"), link.scale("el_error"),
                                          link.scale("az_position"), link.scale("el_position"))
        fault = self.codes["fault"]

        def on_packet(packet) -> None:
            if len(packet.t_us):
                self.last_mount_us = int(packet.t_us[-1])
            az_err, el_err = packet.column(az_name) * s_az, packet.column(el_name) * s_el
            enc_az = packet.column(az_pos_name) * s_az_pos
            enc_el = packet.column(el_pos_name) * s_el_pos
            # the demand is where the encoders are plus what they miss of it
            truth = self.on_target.measure(packet.t_us, enc_az, enc_el,
                                           enc_az + az_err / ARCSEC_PER_RAD,
                                           enc_el + el_err / ARCSEC_PER_RAD)
            self.errors.add(packet.t_us, az_err, el_err, enc_el,
                            *(truth if truth is not None else ()))
            states = packet.column(state_name)
            if len(states):
                self._saw_state(int(states[-1]) if not np.any(states == fault) else fault)

        stream.on_packet(on_packet)

    def _saw_state(self, state: int) -> None:
        fault = self.codes["fault"]
        if state == fault and self._mount_state != fault:
            self._spawn(self._on_fault(), "vss-fault")
        self._mount_state = state

    async def _on_fault(self) -> None:
        try:
            text = await self.motion.fault_text()
        except VssError as exc:
            text = f"(fault text unavailable: {exc})"
        self.last_fault = text
        self.emit("fault", {"state": "fault", "faults": text})
        self.supervisor.interrupt(MountFault(f"the mount faulted: {text}"))

    async def _watch(self) -> None:
        """Poll the mount state once a mount second; in paced time notice a stopped clock."""
        last_t, last_wall = None, time.monotonic()
        last_sun: int | None = None
        while True:
            await self.clock.sleep(WATCH_S)
            if not self.link.connected:
                continue
            try:
                v = await self.link.read(["mount_state", "mount_time"])
            except VssError:
                continue
            self._saw_state(int(v["mount_state"]))
            t, wall = int(v["mount_time"]), time.monotonic()
            if last_sun is None or t - last_sun >= SUN_WATCH_US:
                last_sun = t
                await self._keep_out_of_the_sun(int(v["mount_state"]), t)
            if t != last_t:
                last_t, last_wall = t, wall
            elif not self.clock.lockstep and wall - last_wall > STALL_WALL_S:
                log.error("the mount clock has not moved for %.0f s", wall - last_wall)
                self.supervisor.interrupt(MountUnavailable(
                    f"the mount clock stopped at {iso_utc(t)} ({wall - last_wall:.0f} s "
                    "without a tick)"))
                self.link.mark_lost()
                last_wall = wall

    async def _keep_out_of_the_sun(self, state: int, t_us: int) -> None:
        """A mount at rest the Sun (or Moon) is about to reach is moved to the park position.

        Tracks and slews are guarded on their own; a hold is checked for an hour when it
        is commanded, and this catches the rest (a hold kept longer, a mount left alone):
        once a mount minute, the place it points to is checked now and two minutes ahead.
        """
        c = self.codes
        if not self.active or state not in (c["holding"], c["off"]) or self.supervisor.busy:
            return  # a running operation guards its own places and paths (an override too)
        try:
            pos = await self.motion.position()
        except VssError:
            return
        m = self.link.mapping
        if self._near(pos, m.park_az_deg, m.park_el_deg):
            return  # the stow is the safe place by definition
        obs_az, obs_el = self._observed_deg(pos.az_rad, pos.el_rad)
        zones = dataclasses.replace(self.safety.zones(), horizon=None, el_min_deg=-90.0)
        # now and two checks ahead: the mount leaves before the zone reaches it
        t = np.array([t_us, t_us + 2 * SUN_WATCH_US], np.int64)
        hit = check_places(np.full(2, math.radians(obs_az)), np.full(2, math.radians(obs_el)), t,
                           zones, self.config.site, self.eop)
        if hit is None:
            return
        text = hit.describe("the telescope")
        log.error("safety: %s; moving it to the park position", text)
        self.emit("safety", {"reason": text, "action": "park"})

        async def idle() -> None:  # under the lock: a command that came meanwhile wins
            if self.supervisor.busy:
                raise OperationAborted("a command came first")

        async def procedure(evade: Operation) -> dict[str, Any]:
            return await procedures.hold_fixed(self, evade, m.park_az_deg, m.park_el_deg,
                                               power_off=False, stow=True)

        with contextlib.suppress(OperationAborted):
            await self.supervisor.start("evade", f"park (away from the {hit.zone})", procedure,
                                        check=idle)

    @staticmethod
    def _near(pos, az_deg: float, el_deg: float, tolerance_deg: float = 1.0) -> bool:
        d_az = ((math.degrees(pos.az_rad) - az_deg + 180.0) % 360.0) - 180.0
        return (abs(math.degrees(pos.el_rad) - el_deg) < tolerance_deg
                and (abs(d_az) < tolerance_deg or el_deg > 89.0))

    def note_points(self, p: Points) -> None:
        """The feeder pushed points: keep the target's on-sky rate for the on-sky error."""
        self.errors.note_rates(p.t_us, sky_rate_arcsec_s(p))

    def feeder_config(self) -> FeederConfig:
        cfg = self.config
        return FeederConfig(point_rate_hz=cfg.point_rate_hz, lead_s=self.margins.feed_lead_s,
                            min_lead_s=min(0.5, self.margins.start_lead_s / 2))

    # ------------------------------------------------------------------ commands
    def check_can_move(self) -> None:
        """Refuse a moving command on a passive server or without a mount (again under the lock)."""
        if not self.active:
            raise NotActive("the server is passive (it only watches the mount): run "
                            "`vs mode active` (API: set_mode with mode=active) first")
        if not self.link.connected:
            raise MountUnavailable(f"the mount at {self.link.config.url} is not connected "
                                   f"({self.link.last_error or 'connecting'})")

    async def follow_target(self, target, name: str, *, kind: str = "track",
                            duration_s: float | None = None, allow_sun: bool = False,
                            closed_loop: bool = False) -> Operation:
        """Slew to `target` and track it (for `duration_s` mount seconds, or until stopped);
        `closed_loop`: guided by the guide camera's centroids (closed_loop.py)."""
        self.check_can_move()
        if closed_loop:
            self.steering.need_camera(kind)

        async def procedure(op: Operation) -> dict[str, Any]:
            return await procedures.follow_sky_target(self, op, target, duration_s=duration_s,
                                                      allow_sun=allow_sun, closed_loop=closed_loop)

        check = self._target_check(target, name, allow_sun)
        return await self._start(kind, name, procedure, resumable=True, allow_sun=allow_sun,
                                 check=check)

    def _target_check(self, target, name: str, allow_sun: bool):
        """The check a sky target passes under the supervisor's lock before it starts."""
        async def check() -> None:
            self.safety.check_target(target, await self.motion.mount_time_us(), name,
                                     allow_sun=allow_sun)
        return check

    async def _start(self, kind: str, name: str, procedure, *, resumable: bool = False,
                     allow_sun: bool = False, check=None, steer=None) -> Operation:
        async def checks() -> None:
            self.check_can_move()  # it may have gone passive while this waited for the lock
            if check is not None:
                await check()

        async def run(op: Operation) -> dict[str, Any]:
            try:
                return await procedure(op)
            finally:  # ended early (stopped, replaced, failed): its target is no longer followed
                self.on_target.end(self.last_mount_us or 0, op_id=op.id)

        ops_before = self.supervisor.operations_started
        op = await self.supervisor.start(kind, name, run, resumable=resumable, check=checks,
                                         steer=steer)
        if allow_sun and self.supervisor.operations_started > ops_before:
            op.info["allow_sun"] = True
            log.warning("safety override: operation %s (%s %s) may point inside the Sun and "
                        "Moon exclusion zones", op.id, kind, name)
            self.emit("safety_override", {"id": op.id, "kind": kind, "target": name,
                                          "zones": sorted(self.safety.configured.bodies)})
        return op

    async def slew_altaz(self, az_deg: float, el_deg: float, *, kind: str = "slew",
                         power_off: bool = False, allow_sun: bool = False) -> Operation:
        """Slew to a fixed observed direction and hold there (park: then power off).

        A hold must stay out of the Sun/Moon zones for the next hour (the Sun drifts
        15°/h); the park position is exempt (the stow is the safe place).
        """
        self.check_can_move()
        lim = self.limits
        lowest = lim.el_min_deg - self.config.horizon_deg if kind == "park" else lim.el_min_deg
        if not lowest <= el_deg <= lim.el_max_deg:
            raise TargetUnreachable(f"elevation {el_deg:g}° is outside the range "
                                    f"{lowest:g}..{lim.el_max_deg:g}° the mount may point to")
        name = f"az {az_deg:g} el {el_deg:g}"

        async def check() -> None:
            if kind != "park":
                self.safety.check_place(az_deg % 360.0, el_deg,
                                        await self.motion.mount_time_us(), name,
                                        allow_sun=allow_sun,
                                        ahead_s=self.config.hold_lookahead_s)

        async def procedure(op: Operation) -> dict[str, Any]:
            return await procedures.hold_fixed(self, op, az_deg, el_deg, power_off=power_off,
                                               allow_sun=allow_sun, stow=kind == "park")

        op = await self._start(kind, name, procedure, allow_sun=allow_sun, check=check)
        op.info["fixed"] = True  # a held direction, not a sky target: nothing is tracked
        return op

    async def park(self) -> Operation:
        caps = self.link.capabilities
        if not caps.park:
            raise Unsupported(f"park: the {caps.backend} mount cannot park (its driver says "
                              "so); slew to a safe place and stop instead")
        m = self.link.mapping
        return await self.slew_altaz(m.park_az_deg, m.park_el_deg, kind="park", power_off=True)

    async def pointing_sample(self, target, name: str, *, settle_s: float = 2.0,
                              allow_sun: bool = False) -> Operation:
        """Point at a sky target, hold, and measure the star's offset with the guide camera.

        The result (`op.info["sample"]`) gives the star's observed place, the
        encoders, the camera offset and the sky place on the optical axis
        (docs/vss-api.md). Raises MappingError without a `guide_measure` role.
        """
        if not self.link.mapping.has_function("guide_measure"):
            raise MappingError(f"{self.link.mapping.source}: no 'guide_measure' function role: "
                               "this mount has no guide camera, so pointing samples cannot be "
                               "measured (map it to the camera's measure(star_az_deg, "
                               "star_el_deg) -> [dx_arcsec, dy_arcsec] function)")
        if not settle_s >= 0:
            raise BadRequest(f"settle_s={settle_s}: expected >= 0 mount seconds")
        self.check_can_move()

        async def procedure(op: Operation) -> dict[str, Any]:
            return await procedures.measure_pointing(self, op, target, name, settle_s=settle_s,
                                                     allow_sun=allow_sun)

        check = self._target_check(target, name, allow_sun)
        return await self._start("pointing_sample", name, procedure, allow_sun=allow_sun,
                                 check=check)

    async def move(self, az_rate_deg_s: float, el_rate_deg_s: float, *,
                   allow_sun: bool = False) -> Operation:
        """Turn the axes at constant rates until stopped or a limit/zone is near (hand pad).

        A move while a move runs changes its rates (from the minimum lead, with
        `traj_replace`; hand_pad.py), zero rates included: it ramps down and ends.
        Without `traj_replace`, or zero rates with no move running, as before: a new
        move ends the running operation; zero rates are refused.
        """
        lim = self.limits
        for name, rate, top in (("az_rate_deg_s", az_rate_deg_s, lim.az_max_rate_deg_s),
                                ("el_rate_deg_s", el_rate_deg_s, lim.el_max_rate_deg_s)):
            if abs(rate) > top:
                raise BadRequest(f"move: {name}={rate:g} is beyond the mount's rate limit "
                                 f"±{top:g}°/s")
        self.check_can_move()
        name = f"move az {az_rate_deg_s:+g}°/s el {el_rate_deg_s:+g}°/s"
        buffered = self.link.capabilities.trajectory_buffer
        replace = buffered and self.steering.mode.can_replace
        pad = HandPad(az_rate_deg_s, el_rate_deg_s, allow_sun=allow_sun, replace=replace,
                      note=RESTART_NOTE if buffered else RATES_NOTE)

        async def steer(running: Operation | None) -> bool:
            other = self.steering.hand_pad(running)
            if other is not None and await other.retarget(self, running, az_rate_deg_s,
                                                          el_rate_deg_s, allow_sun=allow_sun):
                return True
            if pad.zero:
                raise BadRequest("move: both rates are 0 and no hand-pad move runs that could "
                                 "ramp down; send stop to end a move")
            return False

        async def procedure(op: Operation) -> dict[str, Any]:
            return await procedures.move_at_rates(self, op, pad)

        op = await self._start("move", name, procedure, allow_sun=allow_sun, steer=steer)
        self.steering.keep_hand_pad(op, pad)
        return op

    async def guide(self, north_arcsec: float, east_arcsec: float,
                    rate_arcsec_s: float) -> dict[str, Any]:
        """Offset the target being tracked north/east at `rate_arcsec_s` (a guide pulse).

        A slew or track accepts pulses from its start: given before the mount has
        joined the target, they are part of the place it joins (steering.py).
        """
        return await self.steering.guide(north_arcsec, east_arcsec, rate_arcsec_s)

    async def track_satellite(self, sat: Satellite, *, max_wait_s: float | None = None,
                              allow_sun: bool = False, closed_loop: bool = False) -> Operation:
        """Track the pass of `sat` in progress, or the next one above the horizon limit;
        `closed_loop`: the along/across offsets follow the guide camera (closed_loop.py)."""
        self.check_can_move()
        if closed_loop:
            self.steering.need_camera("track")

        async def procedure(op: Operation) -> dict[str, Any]:
            return await procedures.track_satellite_pass(self, op, sat, max_wait_s=max_wait_s,
                                                         allow_sun=allow_sun,
                                                         closed_loop=closed_loop)

        return await self._start("track_satellite", sat.name, procedure, resumable=True,
                                 allow_sun=allow_sun)

    async def stop(self, *, reset_faults: bool = False) -> dict[str, Any]:
        """End any operation and bring the mount to rest; optionally clear latched faults."""
        if not self.active:
            raise NotActive("the server is passive: run `vs mode active` (API: set_mode with "
                            "mode=active) first")
        result: dict[str, Any] = {}

        async def to_rest() -> None:
            if reset_faults:
                await self.link.call("reset_faults")
                self.last_fault = ""
            await self.motion.halt()
            state = await self.motion.state()
            result["mount_state"] = self.link.mapping.state_name(state)

        await self.supervisor.stop(StoppedByClient("stopped by a client"), then=to_rest)
        return result

    async def set_mode(self, mode: str) -> dict[str, Any]:
        """active: commands move the mount; passive: watch only (the operation ends first)."""
        if mode not in ("active", "passive"):
            raise BadRequest(f"mode {mode!r}: expected 'active' or 'passive'")
        if mode == "passive" and self.active:
            self.active = False  # first: a command waiting for the lock is refused under it
            await self.supervisor.stop("the server went passive",
                                       then=self.motion.halt if self.link.connected else None)
        self.active = mode == "active"
        self.timesync.active = self.active  # a passive server sends the mount nothing
        self.emit("mode", {"mode": mode})
        return {"mode": mode}

    def load_model(self, path: str, text: str | None = None) -> dict[str, Any]:
        """Use the pointing model in file `path` (its `text` when already read)."""
        from pointing_model import PointingModelError, load_model, model_from_text

        try:
            self.model = load_model(path) if text is None else model_from_text(text, str(path))
        except (PointingModelError, OSError, ValueError) as exc:
            raise BadRequest(f"cannot load pointing model {path}: {exc}") from None
        self.model_source = str(path)
        return {"pointing_model": self.model_source, "terms": self.model.as_dict()}

    def unload_model(self) -> dict[str, Any]:
        self.model, self.model_source = None, ""
        return {"pointing_model": None}

    # -- status ------------------------------------------------------------------------------
    def _observed_deg(self, enc_az_rad: float, enc_el_rad: float) -> tuple[float, float]:
        """The sky place (degrees) of an encoder place: through the pointing model if loaded
        (its azimuth then in 0..360), else the encoder angles themselves."""
        obs_az, obs_el = math.degrees(enc_az_rad), math.degrees(enc_el_rad)
        if self.model is not None:
            a, e = self.model.encoder_to_observed(np.array([obs_az % 360.0]), np.array([obs_el]))
            obs_az, obs_el = float(np.asarray(a)[0]), float(np.asarray(e)[0])
        return obs_az, obs_el

    async def status(self) -> dict[str, Any]:
        """Return encoder and observed positions, RA/Dec, states, mount time, error statistics."""
        cfg = self.config
        out: dict[str, Any] = {"connected": self.link.connected, "url": self.link.config.url,
                               "mount_endpoint": cfg.mount_endpoint or None,
                               "mode": "active" if self.active else "passive",
                               "simulated": cfg.simulated, "time_mode": self.time_mode,
                               "speed": self.clock.pace,
                               "pointing_model": self.model_source or None,
                               "site": {k: getattr(cfg.site, k) for k in _SITE_KEYS},
                               "operation": self.op.as_dict() if self.op else None,
                               "last_fault": self.last_fault or None,
                               "time_sync": self.timesync.status.as_dict(),
                               "safety": self._safety_doc(),
                               "limits": dataclasses.asdict(self.limits),
                               "corrections": self.steering.status(self.last_mount_us),
                               "backend": {**self.link.describe(), "signals_url":
                                           self.signals.url if self.signals else None},
                               "tracking_error": {f"{w}s": self.errors.window(w).as_dict()
                                                  for w in (1, 10, 60)}}
        if not self.link.connected:
            out["mount_error"] = self.link.last_error
            return out
        m = self.link.mapping
        roles = list(_STATUS_ROLES) + [r for r in _OPTIONAL_STATUS if m.has(r)]
        v = await self.link.read(roles)
        enc_az, enc_el, t_us = float(v["az_position"]), float(v["el_position"]), int(v["mount_time"])
        obs_az, obs_el = self._observed_deg(enc_az, enc_el)
        ra, dec = self._radec(obs_az % 360.0, obs_el, t_us)
        out.update({
            "mount_time_us": t_us, "mount_time_utc": iso_utc(t_us, 3),
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
            "on_target": self._on_target_now(t_us, obs_az, obs_el),
        })
        return out

    def _on_target_now(self, t_us: int, obs_az_deg: float, obs_el_deg: float):
        """The boresight against the followed target's true place at the status's mount time,
        with the newest sample's on-target error and planned deviation (docs/vss-api.md)."""
        now = self.on_target.now(t_us, obs_az_deg % 360.0, obs_el_deg)
        if now is not None:
            e = self.errors
            now["last_sample"] = {"t_us": e.last_t_us, "on_target_arcsec": e.last_on_target_arcsec,
                                  "planned_deviation_arcsec": e.last_deviation_arcsec}
        return now

    def _safety_doc(self) -> dict[str, Any]:
        return self.safety.zones().as_dict()

    def _radec(self, az_deg: float, el_deg: float, t_us: int) -> tuple[float, float]:
        """Return ICRS RA/Dec (deg) of an observed direction at mount time (ERFA atoc13)."""
        site = self.config.site
        t = UtcTimes.from_unix_us(t_us)
        dut1, xp, yp = self.eop.interpolate(t.jd1, t.jd2, warn=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", erfa.ErfaWarning)
            ra, dec = erfa.atoc13("A", math.radians(az_deg), math.radians(90.0 - el_deg),
                                  t.jd1[0], t.jd2[0], float(dut1[0]), site.lon_rad, site.lat_rad,
                                  site.height_m, float(xp[0]), float(yp[0]), site.pressure_hpa,
                                  site.temperature_c, site.humidity, site.wavelength_um)
        return math.degrees(float(ra)) % 360.0, math.degrees(float(dec))
