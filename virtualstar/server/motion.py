"""Motion primitives over the mount link: rest, power, slew, start a trajectory, wait.

Each primitive is one short conversation with the mount in roles (`link_interface.MountBackend`; `MountLink` for ASTCom),
waiting in mount time on the VSS's clock (`clock.MountClock`). Primitives never
decide *what* to do next; the procedures (`procedures.py`) do, and only the
supervisor runs procedures, so everything here is called by one owner at a time.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import erfa
import numpy as np

from virtualstar.astro import MountLimits, plan_slew
from virtualstar.astro.constants import ARCSEC_PER_RAD

from .clock import MountClock
from .exceptions import MountFault, NotArrived, OperationAborted, TargetUnreachable, VssError
from .feeder import Feeder, FeederConfig
from .link_interface import MountBackend
from .trajectories import Path, RampIn

__all__ = ["Motion", "Position", "sky_distance_arcsec"]

log = logging.getLogger("virtualstar.server")

HALT_TIMEOUT_S = 120.0  # mount seconds for a moving mount to come to rest
SLEW_TIMEOUT_MARGIN_S = 30.0  # mount seconds allowed beyond a slew's planned duration


@dataclass(frozen=True)
class Position:
    """Encoder angles (rad) and the mount time (µs) of the same tick."""

    az_rad: float
    el_rad: float
    t_us: int


def sky_distance_arcsec(az1_rad: float, el1_rad: float, az2_rad: float, el2_rad: float) -> float:
    """Return the great-circle distance (arcsec) between two az/el directions (ERFA seps)."""
    return float(erfa.seps(az1_rad, el1_rad, az2_rad, el2_rad)) * ARCSEC_PER_RAD


class Motion:
    """What the VSS can make the mount do, in mount time."""

    def __init__(self, link: MountBackend, clock: MountClock) -> None:
        self.link = link
        self.clock = clock
        self.codes = link.mapping.state_codes
        # how often the mount state is polled while waiting for it (mount seconds)
        self.poll_s = 0.05 if clock.lockstep else max(0.002, 0.01 * clock.speed)

    # ------------------------------------------------------------------ reading
    async def mount_time_us(self) -> int:
        return int((await self.link.read(["mount_time"]))["mount_time"])

    async def position(self) -> Position:
        v = await self.link.read(["az_position", "el_position", "mount_time"])
        return Position(float(v["az_position"]), float(v["el_position"]), int(v["mount_time"]))

    async def held_place(self) -> Position:
        """Where the controller holds the axes at rest, and the mount time of that tick.

        The encoders plus what they miss of the reference (the following-error roles,
        arcsec), so a path that leaves from here starts without a step; the encoders
        alone when the mount maps no error roles.
        """
        roles = ["az_position", "el_position", "mount_time"]
        errors = all(self.link.mapping.has(r) for r in ("az_error", "el_error"))
        v = await self.link.read(roles + (["az_error", "el_error"] if errors else []))
        az, el = float(v["az_position"]), float(v["el_position"])
        if errors:
            az += float(v["az_error"]) / ARCSEC_PER_RAD
            el += float(v["el_error"]) / ARCSEC_PER_RAD
        return Position(az, el, int(v["mount_time"]))

    async def state(self) -> int:
        return int((await self.link.read(["mount_state"]))["mount_state"])

    async def fault_text(self, v: dict[str, Any] | None = None) -> str:
        """Return the latched faults as text (per axis), from the fault-text roles if mapped."""
        roles = [r for r in ("az_fault_text", "el_fault_text") if self.link.mapping.has(r)]
        if roles:
            t = await self.link.read(roles)
            return "; ".join(f"{r[:2]}: {t[r]}" for r in roles)
        v = v or await self.link.read(["az_faults", "el_faults"])
        return f"az faults {int(v['az_faults'])}, el faults {int(v['el_faults'])}"

    # ------------------------------------------------------------------ waiting
    async def wait_until(self, t_us: int, progress: dict[str, Any] | None = None) -> int:
        """Wait until the mount clock reaches `t_us`; return the mount time then.

        `progress`, if given, gets ``seconds_left`` as the wait goes on.
        """
        chunk_s = math.inf if self.clock.lockstep else max(0.25 * self.clock.speed, 0.05)
        while True:
            now = await self.mount_time_us()
            left_s = (t_us - now) / 1e6
            if left_s <= 0:
                return now
            if progress is not None:
                progress["seconds_left"] = round(left_s, 1)
            await self.clock.sleep(min(left_s, chunk_s))

    async def wait_state(self, wanted: tuple[str, ...], timeout_s: float, *,
                         first_poll_s: float = 0.0) -> None:
        """Wait (mount time) until the mount state is one of `wanted`; a fault raises."""
        codes = {self.codes[w] for w in wanted}
        start = await self.mount_time_us()
        if first_poll_s > 0:
            await self.clock.sleep(first_poll_s)
        while True:
            v = await self.link.read(["mount_state", "mount_time", "az_faults", "el_faults"])
            state = int(v["mount_state"])
            if state in codes:
                return
            if state == self.codes["fault"]:
                raise MountFault(f"the mount faulted: {await self.fault_text(v)}")
            if (int(v["mount_time"]) - start) / 1e6 > timeout_s:
                raise OperationAborted(f"the mount did not reach {'/'.join(wanted)} within "
                                       f"{timeout_s:g} s (state {self.link.mapping.state_name(state)})")
            await self.clock.sleep(self.poll_s)

    # ------------------------------------------------------------------ moving
    async def halt(self) -> None:
        """Bring a moving mount to rest (a trajectory is reset, a slew stopped)."""
        state = await self.state()
        c = self.codes
        if state == c["tracking"]:
            await self.link.call("traj_reset")
        elif state in (c["slewing"], c["manual"]):
            await self.link.call("stop")
        elif state != c["stopping"]:
            return
        await self.wait_state(("holding", "off"), HALT_TIMEOUT_S)

    async def prepare(self) -> None:
        """Refuse a faulted mount; bring a moving one to rest; power the axes that are off."""
        v = await self.link.read(["mount_state", "az_faults", "el_faults", "az_state", "el_state"])
        state = int(v["mount_state"])
        c = self.codes
        if state == c["fault"]:
            raise MountFault(f"the mount is in FAULT ({await self.fault_text(v)}): reset the "
                             "faults first (vs stop --reset-faults, or the 'reset_faults' command)")
        if state in (c["tracking"], c["slewing"], c["manual"], c["stopping"]):
            await self.halt()
            v = await self.link.read(["az_state", "el_state"])
        if c["off"] in (int(v["az_state"]), int(v["el_state"])):
            await self.link.call("power_on")  # closes the loops of the axes that are off

    async def goto(self, az_rad: float, el_rad: float, limits: MountLimits) -> Position:
        """Slew to encoder angles with the mount's own profile; return where it came to rest."""
        if not (math.radians(limits.wrap_min_deg) <= az_rad <= math.radians(limits.wrap_max_deg)):
            raise TargetUnreachable(f"azimuth {math.degrees(az_rad):.3f} deg is outside the "
                                    f"cable wrap {limits.wrap_min_deg:g}..{limits.wrap_max_deg:g} deg")
        here = await self.position()
        planned_s = plan_slew(here.az_rad, here.el_rad, az_rad, el_rad, limits).duration_s
        await self.link.call("slew", math.degrees(az_rad), math.degrees(el_rad))
        # sleep through most of the planned slew before polling for its end
        await self.wait_state(("holding",), planned_s + SLEW_TIMEOUT_MARGIN_S,
                              first_poll_s=0.9 * planned_s)
        return await self.position()

    @staticmethod
    def verify_at(pos: Position, az_rad: float, el_rad: float, tolerance_arcsec: float,
                  what: str) -> float:
        """Return the distance (arcsec) from `pos` to the demand; NotArrived beyond tolerance.

        An encoder a whole turn from its demand points the same way but sits on the other
        side of the cable wrap: that is not an arrival either.
        """
        err = sky_distance_arcsec(pos.az_rad, pos.el_rad, az_rad, el_rad)
        turns = round((pos.az_rad - az_rad) / (2 * math.pi))
        if turns:
            raise NotArrived(f"{what}: the azimuth encoder is {turns:+d} turn(s) of the cable "
                             f"wrap from the demand ({math.degrees(pos.az_rad):.3f}° vs "
                             f"{math.degrees(az_rad):.3f}°)", err + abs(turns) * 1296000.0)
        if not err <= tolerance_arcsec:
            raise NotArrived(
                f"{what}: the encoders are {_angle_text(err)} from the demand "
                f"(az {math.degrees(pos.az_rad):.4f}° vs {math.degrees(az_rad):.4f}°, "
                f"el {math.degrees(pos.el_rad):.4f}° vs {math.degrees(el_rad):.4f}°; "
                f"tolerance {tolerance_arcsec:g}″)", err)
        return err

    async def verify_on_path(self, path: Path, tolerance_arcsec: float, what: str) -> float:
        """Read the encoders and compare them with the path's demand at the same mount time."""
        pos = await self.position()
        demand = path.sample(np.array([pos.t_us], np.int64))
        return self.verify_at(pos, float(demand.az_rad[0]), float(demand.el_rad[0]),
                              tolerance_arcsec, what)

    async def start_trajectory(self, ramp: RampIn, feeder_config: FeederConfig,
                               start_lead_s: float, on_points=None) -> Feeder | None:
        """Initialise the buffer, prime it from the run-up's start, start following.

        Returns None, leaving the mount holding, when the host was too slow to prime
        the buffer before the run-up began (the caller plans the join again).
        """
        return await self.start_following(ramp, ramp.begin_us, feeder_config,
                                          latest_us=ramp.begin_us - int(start_lead_s * 1e6 / 2),
                                          on_points=on_points)

    async def start_following(self, path: Path, first_us: int, feeder_config: FeederConfig, *,
                              latest_us: int, on_points=None,
                              initialised: bool = False) -> Feeder | None:
        """Initialise the buffer, prime it with `path` from `first_us`, start following.

        The axes hold until `first_us`. Returns None, leaving the mount holding, when a
        point was refused or the mount time read before priming was past `latest_us`
        (the rest of the start would come too late: the caller plans again).
        `initialised`: the caller already called `traj_init` (one request less to wait for).
        """
        if not initialised:
            await self.link.call("traj_init")
        feeder = Feeder(self.link, self.clock, feeder_config, path, first_us,
                        fault_code=self.codes["fault"], tracking_code=self.codes["tracking"],
                        on_points=on_points)
        now = await feeder.cycle()
        if feeder.stats.rejected or feeder.stats.first_point_us != first_us or now > latest_us:
            # never start half-way up a ramp: the mount was not told to follow yet
            return None
        await self.link.call("traj_start")
        feeder.started = True
        return feeder

    async def halt_quietly(self) -> str:
        """Halt after a failure; return what went wrong halting, or '' (the first error stands)."""
        try:
            await self.halt()
        except VssError as exc:
            log.warning("bringing the mount to rest after a failure: %s", exc)
            return str(exc)
        return ""

    def plan_slew_s(self, here: Position, az_rad: float, el_rad: float,
                    limits: MountLimits) -> float:
        return plan_slew(here.az_rad, here.el_rad, az_rad, el_rad, limits).duration_s


def _angle_text(arcsec: float) -> str:
    if arcsec >= 3600.0:
        return f"{arcsec / 3600.0:.2f}° ({arcsec:.0f}″)"
    if arcsec >= 60.0:
        return f"{arcsec / 60.0:.2f}′ ({arcsec:.1f}″)"
    return f"{arcsec:.2f}″"
