"""What each operation does: the procedures the supervisor runs, one phase after another.

Every motion follows the same recipe, in mount time:

1. PREPARING: the mount must be connected and not in fault; a moving mount is
   brought to rest and axes that are off are powered.
2. SLEWING: the mount slews with its own point-to-point profile to the *rest
   point* of a constant-acceleration run-up (`trajectories.plan_run_up`) that
   joins the target's path at a chosen instant with the path's position and
   rate. If the host was too slow (a paced mount does not wait), the join is
   planned again from where the mount is, with a larger margin.
3. WAITING / JOINING: the buffer is initialised, primed and started; a feeder
   keeps it filled beside the procedure, so the two end together.
4. SETTLING: `settle_s` after the join the encoders are compared with the
   path's demand at the same mount time: beyond `arrival_tolerance_arcsec` the
   operation fails with `not_arrived`, saying how far off it is; within, the
   request is answered (the operation has *begun*).
5. TRACKING until the duration or the pass ends, then ENDING: back to rest.

A procedure raises on anything that stops it; the supervisor decides whether
to run it again (`operations.resume_decision`), so a re-acquisition after an
underrun or a reconnection is just the procedure run once more from where the
mount is (a satellite pass in progress is joined where it is then).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
import warnings
from collections.abc import Awaitable
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from virtualstar.astro import (
    FixedAltAz,
    Satellite,
    UtcTimes,
    iso_utc,
    observe_mount_times,
    satellite_passes,
    unwrap_azimuth,
)
from virtualstar.astro.exceptions import SatelliteError

from . import closed_loop as guided
from . import goto_route, rate_procedures
from .corrections import Corrections
from .exceptions import InExclusionZone, StaleElements, TargetUnreachable
from .feeder import Feeder, FeederConfig
from .hand_pad import START_REQUESTS, ZERO_RATES, HandPad, PadState
from .operations import Operation, Phase
from .pass_selection import choose_pass, windows_from_passes
from .trajectories import (
    SLEW_MARGIN,
    ConstantRatePath,
    Path,
    RampIn,
    RampOut,
    TargetPath,
    plan_run_up,
    plan_satellite_pass,
)

if TYPE_CHECKING:
    from .station import Station

__all__ = ["follow_sky_target", "hold_fixed", "measure_pointing", "move_at_rates",
           "track_satellite_pass"]

log = logging.getLogger("virtualstar.server")

T = TypeVar("T")

MAX_JOIN_PLANS = 12  # plans of a join before giving up (each with 1.5× the previous margin)
PASS_LOOKBACK_S = 1800.0  # predictions start this far back, so a pass in progress is found
MIN_JOIN_TRACK_S = 10.0  # a finite path is joined only if this much of it is left
CLOSED_LOOP_LEAD_S = 5.0  # mount seconds buffered under a closed loop (real time's lead)
PASS_OFFSET_MARGIN_S = 30.0  # a pass is planned this much longer at both ends (path offsets)
RUN_UP_STEP_US = 2_000_000  # a run-up inside a zone moves the join this much later
MOVE_START_ATTEMPTS = 4  # starts of a move tried, each with twice the margin, before giving up


# ---------------------------------------------------------------------- shared steps
async def run_beside(main: Awaitable[T], feeder: Feeder) -> T:
    """Run `main` while the feeder keeps the buffer filled; either failing ends both.

    Neither outlives this call: a cancellation or an error cancels and awaits both
    tasks (no feeder left pushing points for an operation that ended).
    """
    loop = asyncio.get_running_loop()
    feeding = loop.create_task(feeder.run(), name="vss-feeder")
    main_task = loop.create_task(main, name="vss-procedure")  # type: ignore[arg-type]
    try:
        done, _ = await asyncio.wait({feeding, main_task}, return_when=asyncio.FIRST_COMPLETED)
        if feeding in done and not feeding.cancelled() and feeding.exception() is not None:
            raise feeding.exception()  # type: ignore[misc]
        return await main_task
    finally:
        for task in (feeding, main_task):
            task.cancel()
        await asyncio.wait({feeding, main_task})


async def acquire(t: Station, op: Operation, path: Path, *, not_before_us: int | None = None,
                  end_us: int | None = None, allow_sun: bool = False,
                  corrections: Corrections | None = None,
                  feed: FeederConfig | None = None) -> tuple[RampIn, Feeder]:
    """Slew to the run-up of `path` and start following it; return the run-up and its feeder.

    With `corrections`, offsets changed from now on start at the join (the run-up aims
    at the place they had when it was planned), and the feeder is handed to them.

    A mount without a trajectory buffer is joined by a goto to a point ahead and
    followed by a closed rate loop (`rate_procedures.acquire_by_rates`): the same
    shape comes back (the join and what keeps the mount on the path).
    """
    if not t.link.capabilities.trajectory_buffer:
        return await rate_procedures.acquire_by_rates(t, op, path, not_before_us=not_before_us,
                                                      end_us=end_us, allow_sun=allow_sun,
                                                      corrections=corrections)
    cfg = t.config
    lead_s = t.margins.start_lead_s
    plan = 0
    while plan < MAX_JOIN_PLANS:
        here = await t.motion.position()
        ramp = plan_run_up(path, az_rad=here.az_rad, el_rad=here.el_rad, now_us=here.t_us,
                           limits=t.limits, lead_s=lead_s, ramp_s=cfg.ramp_s,
                           not_before_us=not_before_us)
        if corrections is not None:
            corrections.hold_until(ramp.join_us)
        if end_us is not None and ramp.join_us > end_us - int(MIN_JOIN_TRACK_S * 1e6):
            raise TargetUnreachable(f"too little of the path is left to join it: it ends "
                                    f"{(end_us - here.t_us) / 1e6:.0f} s from now")
        rest_az, rest_el = float(ramp.rest_rad[0]), float(ramp.rest_rad[1])
        if t.safety.inside(rest_az, rest_el, ramp.begin_us, allow_sun=allow_sun):
            # the run-up would start inside a zone (a pass leaving it): join a little later
            not_before_us = ramp.join_us + RUN_UP_STEP_US
            continue
        clear_us = t.safety.first_clear_us(rest_az, rest_el, here.t_us, ramp.begin_us,
                                           allow_sun=allow_sun)
        if clear_us > here.t_us:
            # the Sun has not left the place to wait at yet: wait here until it has
            t.supervisor.phase(op, Phase.WAITING, start_utc=iso_utc(clear_us))
            await t.motion.wait_until(clear_us, op.info)
            continue
        t.supervisor.phase(op, Phase.SLEWING, to_az_deg=math.degrees(rest_az),
                           to_el_deg=math.degrees(rest_el), join_us=ramp.join_us)
        pos = await goto_safely(t, op, rest_az, rest_el, f"the run-up of {op.target}",
                                allow_sun=allow_sun)
        t.motion.verify_at(pos, rest_az, rest_el, cfg.arrival_tolerance_arcsec,
                           f"slew to the run-up of {op.target}")
        if pos.t_us + int(lead_s * 1e6) < ramp.begin_us:
            feed = feed or t.feeder_config()
            if ramp.begin_us - pos.t_us > feed.lead_s * 1e6:
                t.supervisor.phase(op, Phase.WAITING, start_utc=iso_utc(ramp.begin_us))
                await t.motion.wait_until(ramp.begin_us - int((feed.lead_s - lead_s) * 1e6),
                                          op.info)
            feeder = await t.motion.start_trajectory(ramp, feed, lead_s,
                                                     on_points=t.note_points)
            if feeder is not None:
                if corrections is not None:
                    corrections.attach(feeder)
                t.supervisor.phase(op, Phase.JOINING)
                return ramp, feeder
        log.warning("operation %s: the join at %s came too late for the host (plan %d); "
                    "planning again from where the mount is", op.id, iso_utc(ramp.join_us),
                    plan + 1)
        plan += 1
        op.info["join_plans"] = plan + 1
        lead_s *= 1.5
    raise TargetUnreachable(f"could not join {op.target} after {MAX_JOIN_PLANS} plans: the host "
                            f"cannot keep up with ×{t.clock.speed:g} simulated time")


async def goto_safely(t: Station, op: Operation, az_rad: float, el_rad: float, what: str, *,
                      allow_sun: bool, stow: bool = False):
    """Slew to encoder angles along a path out of the Sun/Moon zones (a detour if need be)."""
    here = await t.motion.position()
    legs = t.safety.route(here.az_rad, here.el_rad, az_rad, el_rad, here.t_us, what,
                          allow_sun=allow_sun, stow=stow)
    if len(legs) > 1:
        op.info["detour_deg"] = [[round(math.degrees(a), 3), round(math.degrees(e), 3)]
                                 for a, e in legs[:-1]]
    if not t.link.capabilities.trajectory_buffer:
        # a driver's goto takes its own path: legs short enough that its own way (any way
        # within the box of its native axes) keeps out of the zones too
        legs = goto_route.driver_legs(t, here, legs, what, allow_sun=allow_sun, stow=stow)
    pos = None
    for k, (leg_az, leg_el) in enumerate(legs):
        if k < len(legs) - 1 and not t.link.capabilities.trajectory_buffer:
            await t.link.call("goto_place", math.degrees(leg_az), math.degrees(leg_el))
            continue
        pos = await t.motion.goto(leg_az, leg_el, t.limits)
    return pos


def _settle_s(t: Station, feeder) -> float:
    """Mount seconds from the join to the landing check: the configured settle, or what a
    rate loop needs to take up the path's rate from a few driver reports."""
    if t.link.capabilities.trajectory_buffer:
        return t.config.settle_s
    return feeder.settle_s(t.config.settle_s)


def _place_tolerance(t: Station) -> float:
    """How close a slew to a fixed place must land: the arrival tolerance, or the goto
    accuracy a mount without a trajectory buffer declares (its driver lands the goto)."""
    return max(t.config.arrival_tolerance_arcsec,
               t.link.capabilities.goto_tolerance_arcsec or 0.0)


async def verify_joined(t: Station, ramp, feeder, what: str) -> float:
    """Compare the mount with the path after the join: the encoders at the same mount time
    (a trajectory buffer), or the rate loop's last report at its own time (rate axes)."""
    tolerance = t.config.arrival_tolerance_arcsec
    if t.link.capabilities.trajectory_buffer:
        return await t.motion.verify_on_path(ramp, tolerance, what)
    return await feeder.verify(tolerance, what)


async def prepare(t: Station, op: Operation) -> None:
    t.supervisor.phase(op, Phase.PREPARING)
    await t.motion.prepare()


# ---------------------------------------------------------------------- procedures
async def follow_sky_target(t: Station, op: Operation, target: Any, *,
                            duration_s: float | None, allow_sun: bool = False,
                            closed_loop: bool = False) -> dict[str, Any]:
    """Slew to a sky target, verify the landing, track it (for `duration_s`, or until ended).

    The track stops before the target would enter a Sun/Moon zone or pass below the
    horizon (`ended` says which and when).
    """
    cfg = t.config
    await prepare(t, op)
    here = await t.motion.position()
    corrections = t.steering.corrections(op)
    path = corrections.wrap(TargetPath(target, cfg.site, limits=t.limits, eop=t.eop,
                                       model=t.model, current_az_rad=here.az_rad,
                                       guard=t.safety.guard(op.target, allow_sun=allow_sun)))
    ramp, feeder = await acquire(t, op, path, allow_sun=allow_sun, corrections=corrections,
                                 feed=_feed(t, closed_loop))
    t.on_target.follow(target, op.target, model=t.model, from_us=ramp.join_us, op_id=op.id,
                       offsets=corrections.offsets)

    async def on_path() -> dict[str, Any]:
        await t.motion.wait_until(ramp.join_us)
        async with guided.running(t, op, corrections, "sky", closed_loop):
            return await joined()

    async def joined() -> dict[str, Any]:
        settled_us = ramp.join_us + int(_settle_s(t, feeder) * 1e6)
        t.supervisor.phase(op, Phase.SETTLING)
        await t.motion.wait_until(settled_us)
        err = await verify_joined(t, ramp, feeder, f"landing on {op.target}")
        s = t.errors.stats(ramp.join_us, settled_us)
        landing = {"slew_time_s": (ramp.join_us - here.t_us) / 1e6,
                   "landing_rms_arcsec": s.rms_arcsec, "landing_peak_arcsec": s.peak_arcsec,
                   "landing_error_arcsec": err, "slew_from_us": here.t_us,
                   "landed_us": ramp.join_us}
        t.supervisor.phase(op, Phase.TRACKING, tracking_from_us=settled_us, **landing)
        t.supervisor.begun(op)
        t.emit("slew_done", {"id": op.id, **landing})
        if duration_s is None:
            await asyncio.Event().wait()  # until stopped, replaced, or the target leaves
        end = settled_us + int(duration_s * 1e6)
        await t.motion.wait_until(end, op.info)
        return {"ended": "duration elapsed", "tracking_to_us": end}

    try:
        result = await run_beside(on_path(), feeder)
    except (TargetUnreachable, InExclusionZone) as exc:
        corrections.attach(None)
        if op.phase is not Phase.TRACKING:
            raise
        # the next chunk would leave the limits or enter a zone: the points already
        # buffered stop short of it; let them play out, then rest
        if t.link.capabilities.trajectory_buffer:
            await t.motion.wait_until(feeder.stats.last_point_us - 200_000)
        else:
            await feeder.halt_rates()
        why = ("the target left the limits" if isinstance(exc, TargetUnreachable)
               else "stopped before entering the exclusion zone")
        result = {"ended": f"{why}: {exc}", "tracking_to_us": await t.motion.mount_time_us()}
    finally:
        corrections.attach(None)
    op.info["feeder"] = feeder.stats.as_dict()
    t.on_target.end(result["tracking_to_us"])
    t.supervisor.phase(op, Phase.ENDING)
    await t.motion.halt()
    s = t.errors.stats(op.info["tracking_from_us"], result["tracking_to_us"])
    return {**result, **tracking_figures(t, op, s)}


async def hold_fixed(t: Station, op: Operation, az_deg: float, el_deg: float, *,
                     power_off: bool, allow_sun: bool = False, stow: bool = False) -> dict[str, Any]:
    """Slew to a fixed observed direction, verify the landing and hold (park: power off)."""
    await prepare(t, op)
    here = await t.motion.position()
    pos, enc_az, enc_el = await _slew_to_fixed(t, op, here, az_deg % 360.0, el_deg, here.t_us,
                                               op.target, allow_sun=allow_sun, stow=stow)
    t.supervisor.phase(op, Phase.SETTLING)
    err = t.motion.verify_at(pos, enc_az, enc_el, _place_tolerance(t), f"slew to {op.target}")
    if power_off:
        t.supervisor.phase(op, Phase.ENDING)
        await t.link.call("power_off")
    return {"slew_time_s": (pos.t_us - here.t_us) / 1e6, "landing_rms_arcsec": err,
            "landing_peak_arcsec": err, "landing_error_arcsec": err, "slew_from_us": here.t_us,
            "landed_us": pos.t_us}


async def _slew_to_fixed(t: Station, op: Operation, here, az_deg: float, el_deg: float,
                         at_us: int, name: str, *, allow_sun: bool, stow: bool = False):
    """Slew to the encoder place of an observed direction (through the pointing model, in
    the cable wrap nearest `here`) as it is at `at_us`; return (landed position, enc az, el)."""
    enc = TargetPath(FixedAltAz(az_deg, el_deg), t.config.site, limits=t.limits, eop=t.eop,
                     model=t.model, current_az_rad=here.az_rad).sample(np.array([at_us], np.int64))
    enc_az, enc_el = float(enc.az_rad[0]), float(enc.el_rad[0])
    t.supervisor.phase(op, Phase.SLEWING, to_az_deg=math.degrees(enc_az),
                       to_el_deg=math.degrees(enc_el))
    pos = await goto_safely(t, op, enc_az, enc_el, name, allow_sun=allow_sun, stow=stow)
    return pos, enc_az, enc_el


async def move_at_rates(t: Station, op: Operation, pad: HandPad) -> dict[str, Any]:
    """Turn the axes at the hand pad's rates from where the mount rests (ASCOM MoveAxis).

    With `traj_replace` the axes leave the minimum lead after the command at their
    acceleration limits, and a new `move` changes the rates the same way (hand_pad.py);
    without it, the move starts after the start lead with a run-up (a new move starts
    again). It ends, with a run-out to rest, before an axis limit or a Sun/Moon/horizon
    zone (checked an hour ahead); `stop` or any other command ends it sooner. The
    operation has *begun* once the mount follows the trajectory.
    """
    await prepare(t, op)
    if not t.link.capabilities.trajectory_buffer:
        return await _move_by_rates(t, op, pad)
    async with pad.lock:  # a change of rates meanwhile waits for the start
        if pad.zero:  # the rates were set to 0 before it moved
            pad.state = PadState.ENDED
            t.supervisor.phase(op, Phase.SLEWING, az_rate_deg_s=0.0, el_rate_deg_s=0.0)
            t.supervisor.phase(op, Phase.ENDING)
            return {"ended": f"{ZERO_RATES} before the move began",
                    "moved_until_us": await t.motion.mount_time_us()}
        feeder = await _start_move(t, op, pad)
        pad.feeder, pad.state = feeder, PadState.MOVING
    t.supervisor.begun(op)
    try:
        await run_beside(pad.wait_for_end(t, op), feeder)
    finally:
        pad.state = PadState.ENDED
    op.info["feeder"] = feeder.stats.as_dict()
    t.supervisor.phase(op, Phase.ENDING)
    await t.motion.halt()
    return {"ended": pad.why, "moved_until_us": pad.stop_us}


async def _start_move(t: Station, op: Operation, pad: HandPad) -> Feeder:
    """Plan the move from where the mount rests and start following it (under `pad.lock`)."""
    mode = t.steering.mode
    margin_us = mode.margin_us
    for _attempt in range(MOVE_START_ATTEMPTS):
        # the buffer emptied before the mount time is read: three requests to wait for
        # after it (the feeder's read, its first push, traj_start), not four
        await t.link.call("traj_init")
        here = await t.motion.held_place()
        if pad.replace:  # from the minimum lead, at the axes' acceleration limits
            lead_us = mode.min_lead_us + START_REQUESTS * margin_us
            pad.accel = HandPad.accel_rad_s2(t.limits)
            latest_us = here.t_us + lead_us - mode.min_lead_us // 2 - 2 * margin_us
        else:  # after the start lead, with a run-up as the other paths have
            lead_us = int(t.margins.start_lead_s * 1e6)
            pad.accel = _run_up_accel(t, pad)
            latest_us = here.t_us + lead_us // 2
        from_us = here.t_us + lead_us
        reached = _plan_move(t, pad, from_us, here)
        t.supervisor.phase(op, Phase.SLEWING)
        pad.report(t, op, start={"accepted_us": here.t_us, "from_us": from_us,
                                 "lead_ms": lead_us / 1000, "rates_reached_us": reached})
        config = t.feeder_config()
        if pad.replace:  # the first points are due within the minimum lead
            config = dataclasses.replace(config, min_lead_s=min(config.min_lead_s,
                                                                lead_us / 2e6))
        feeder = await t.motion.start_following(pad.path, from_us, config, latest_us=latest_us,
                                                on_points=t.note_points, initialised=True)
        if feeder is not None:
            return feeder
        margin_us = max(2 * margin_us, 5_000)
    raise TargetUnreachable("the host was too slow to start the move; send it again")


def _plan_move(t: Station, pad: HandPad, from_us: int, here) -> int:
    """Plan the pad's rates from a place at rest; refuse a move that would stop at once."""
    try:
        return pad.plan(t, from_us, az_rad=here.az_rad, el_rad=here.el_rad)
    except TargetUnreachable as exc:
        az, el = pad.rates_deg_s
        raise TargetUnreachable(f"moving at az {az:g}°/s, el {el:g}°/s from az "
                                f"{math.degrees(here.az_rad):.2f}° el "
                                f"{math.degrees(here.el_rad):.2f}°: {exc} at once") from None


def _run_up_accel(t: Station, pad: HandPad) -> np.ndarray:
    """The run-up of a move without re-planning: both axes reach their rates together, in
    `ramp_s` (2 s) or twice what the acceleration limits allow (rad/s²)."""
    v = np.abs(np.radians(pad.rates_deg_s))
    limit = HandPad.accel_rad_s2(t.limits)
    ramp_s = max(t.config.ramp_s, 2.0 * float(np.max(v / limit)))
    return np.where(v > 0, v / ramp_s, limit)


async def _move_by_rates(t: Station, op: Operation, pad: HandPad) -> dict[str, Any]:
    """A move on a mount without a trajectory buffer: its driver turns at the rates at once."""
    here = await t.motion.position()
    pad.accel = _run_up_accel(t, pad)  # the driver's own run-out is not known: a gentle one
    from_us = here.t_us + int(t.margins.start_lead_s * 1e6)
    _plan_move(t, pad, from_us, here)
    v = np.radians(pad.rates_deg_s)
    path = ConstantRatePath(from_us, here.az_rad, here.el_rad, float(v[0]), float(v[1]),
                            pad.stop_us)
    t.supervisor.phase(op, Phase.SLEWING)
    pad.report(t, op)
    pad.state = PadState.ENDED  # a new move starts again
    _ramp, feeder = rate_procedures.follow_now(t, path, path.at_us)
    t.supervisor.begun(op)

    async def moving() -> None:
        await t.motion.wait_until(path.end_us, op.info)

    await run_beside(moving(), feeder)
    op.info["feeder"] = feeder.stats.as_dict()
    t.supervisor.phase(op, Phase.ENDING)
    await t.motion.halt()
    return {"ended": pad.why, "moved_until_us": pad.stop_us}


async def measure_pointing(t: Station, op: Operation, target: Any, name: str, *,
                           settle_s: float, allow_sun: bool = False) -> dict[str, Any]:
    """Point at a sky target's place at the exposure instant, hold, and measure with the camera.

    The mount is sent to the target's observed place at t_exp (through the pointing
    model, if one is loaded) and *held* there, so the encoders and the star's place
    given to the camera refer to the same instant however long the requests take.
    """
    await prepare(t, op)
    here = await t.motion.position()
    # where the star will be when the mount has landed and settled
    first = _observed_deg(t, target, here.t_us)
    slew_s = t.motion.plan_slew_s(here, math.radians(first[0]), math.radians(first[1]), t.limits)
    t_exp = here.t_us + int((slew_s * SLEW_MARGIN + 1.0 + settle_s) * 1e6)
    star_az, star_el = _observed_deg(t, target, t_exp)
    if not t.limits.el_min_deg <= star_el <= t.limits.el_max_deg:
        raise TargetUnreachable(f"{name} is at elevation {star_el:.2f} deg, outside the "
                                f"limits {t.limits.el_min_deg:g}..{t.limits.el_max_deg:g} deg")
    t.safety.check_place(star_az, star_el, t_exp, name, allow_sun=allow_sun)
    pos, enc_az, enc_el = await _slew_to_fixed(t, op, here, star_az, star_el, t_exp, name,
                                               allow_sun=allow_sun)
    t.motion.verify_at(pos, enc_az, enc_el, _place_tolerance(t), f"slew to {name}")
    t.supervisor.phase(op, Phase.MEASURING)
    await t.motion.wait_until(max(pos.t_us + int(settle_s * 1e6), t_exp), op.info)
    v = await t.link.read(["az_position", "el_position", "mount_time"])
    dx, dy = (float(x) for x in await t.link.call("guide_measure", star_az, star_el))
    enc_az_deg, enc_el_deg = math.degrees(float(v["az_position"])), math.degrees(float(v["el_position"]))
    # the sky place on the optical axis: the star minus its offset from the axis
    axis_el = star_el - dy / 3600.0
    axis_az = star_az - dx / 3600.0 / math.cos(math.radians(star_el))
    return {"sample": {
        "target": name, "slew_time_s": (pos.t_us - here.t_us) / 1e6, "t_exp_us": t_exp,
        "utc": iso_utc(t_exp, 3), "measured_us": int(v["mount_time"]),
        "star": {"az_deg": star_az, "el_deg": star_el},
        "encoder": {"az_deg": enc_az_deg, "el_deg": enc_el_deg},
        "offset_arcsec": {"dx": dx, "dy": dy, "total": math.hypot(dx, dy)},
        "axis": {"az_deg": axis_az, "el_deg": axis_el},
        "pointing_model": t.model_source or None}}


async def track_satellite_pass(t: Station, op: Operation, sat: Satellite, *,
                               max_wait_s: float | None, allow_sun: bool = False,
                               closed_loop: bool = False) -> dict[str, Any]:
    """Track the next pass of `sat` that can still be reached, or the one in progress.

    Only a stretch of the pass outside every zone (Sun, Moon, horizon profile) is
    tracked: the track joins after the pass leaves a zone and stops before it enters
    one (`zone_stop` in the info says which and when).
    """
    cfg = t.config
    await prepare(t, op)
    here = await t.motion.position()
    check_elements(sat, here.t_us, cfg.max_tle_age_days)
    choice = _choose_pass(t, sat, here)
    window = choice.window
    set_us = int(window.set_us)  # choose_pass only returns passes with a set
    if max_wait_s is not None and choice.join_us - here.t_us > max_wait_s * 1e6:
        raise TargetUnreachable(f"the next pass of {sat.name} begins in "
                                f"{(choice.join_us - here.t_us) / 1e6:.0f} s, more than the "
                                f"{max_wait_s:g} s allowed")
    full = _plan_pass(t, sat, here, choice.join_us, set_us)
    plan = dataclasses.replace(full, path=full.path.between(choice.join_us, set_us))
    join_us, set_us, stops = _safe_part(t, plan, choice.join_us, allow_sun)
    if stops is not None:
        op.info["zone_stop"] = stops
    caps = t.link.capabilities
    if caps.equatorial:
        join_us, set_us, turns = rate_procedures.equatorial_stretch(
            t, plan.path.between(join_us, set_us), join_us, cfg.min_pass_track_s)
        if turns is not None:
            op.info["geometry_stop"] = turns
    plan = dataclasses.replace(plan, path=plan.path.between(join_us, set_us))
    t.supervisor.phase(op, Phase.PLANNED, slew_from_us=here.t_us, pass_start_us=join_us,
                       pass_end_us=set_us, pass_start_utc=iso_utc(join_us, 3),
                       pass_end_utc=iso_utc(set_us, 3),
                       pass_rise_utc=None if window.rise_us is None else iso_utc(window.rise_us, 3),
                       pass_in_progress=choice.in_progress,
                       culmination_el_deg=window.culmination_el_deg,
                       keyhole=plan.keyhole_limited,
                       keyhole_max_error_arcsec=plan.keyhole_max_error_arcsec,
                       max_az_rate_deg_s=plan.max_az_rate_deg_s)
    t.supervisor.begun(op)
    # the offsets move along the whole table (margins included), the feed ends at set
    corrections = t.steering.corrections(op)
    # run out to rest after set, and hold: stopping a little late costs nothing
    path = (RampOut(corrections.wrap(full.path, end_us=set_us), cfg.ramp_s,
                    t.margins.hold_after_run_out_s)
            if caps.trajectory_buffer else plan.path)
    ramp, feeder = await acquire(t, op, path, not_before_us=join_us, end_us=set_us,
                                 allow_sun=allow_sun, corrections=corrections,
                                 feed=_feed(t, closed_loop))
    planned = ["keyhole"] if plan.keyhole_limited else []
    t.on_target.follow(sat, sat.name, model=t.model, from_us=ramp.join_us, op_id=op.id,
                       planned=planned, offsets=corrections.offsets)
    op.info["planned_deviation"] = planned  # known from the plan, before the pass ends

    async def on_path() -> int:
        await t.motion.wait_until(ramp.join_us)
        async with guided.running(t, op, corrections, "satellite", closed_loop):
            return await joined()

    async def joined() -> int:
        t.supervisor.phase(op, Phase.SETTLING, tracking_from_us=ramp.join_us)
        await t.motion.wait_until(ramp.join_us + int(_settle_s(t, feeder) * 1e6))
        err = await verify_joined(t, ramp, feeder, f"joining the pass of {sat.name}")
        t.supervisor.phase(op, Phase.TRACKING, join_error_arcsec=err)
        return min(await t.motion.wait_until(set_us, op.info), set_us)

    try:
        track_to = await run_beside(on_path(), feeder)
    finally:
        corrections.attach(None)
    op.info["feeder"] = feeder.stats.as_dict()
    t.on_target.end(track_to)
    t.supervisor.phase(op, Phase.ENDING)
    await t.motion.halt()
    s = t.errors.stats(op.info["tracking_from_us"], track_to)
    return {"ended": "the pass ended", "tracking_to_us": track_to, **tracking_figures(t, op, s)}


# ---------------------------------------------------------------------- helpers
def _feed(t: Station, closed_loop: bool) -> FeederConfig:
    """The feed of a track: a closed loop re-plans ten times a second, and each re-plan
    sends the buffered future again, so it keeps at most `CLOSED_LOOP_LEAD_S` buffered."""
    feed = t.feeder_config()
    if closed_loop and feed.lead_s > CLOSED_LOOP_LEAD_S:
        feed = dataclasses.replace(feed, lead_s=CLOSED_LOOP_LEAD_S)
    return feed


def _plan_pass(t: Station, sat: Satellite, here, join_us: int, set_us: int):
    """Plan the pass from `join_us` to `set_us`, with `PASS_OFFSET_MARGIN_S` more at both
    ends for path offsets (without, if the longer pass would not fit the cable wrap)."""
    cfg = t.config
    margin_us = int(PASS_OFFSET_MARGIN_S * 1e6)
    for margin in (margin_us, 0):
        try:
            with _sgp4_errors(sat, here.t_us):
                return plan_satellite_pass(
                    sat, cfg.site, join_us - margin, set_us + margin, step_s=cfg.sat_grid_s,
                    limits=t.limits,
                    track_rate_limit_deg_s=(t.track_rate_limit_deg_s * cfg.keyhole_rate_fraction
                                            if not t.link.capabilities.equatorial else 1e9),
                    accel_limit_deg_s2=t.limits.az_max_accel_deg_s2, eop=t.eop, model=t.model,
                    current_az_rad=here.az_rad)
        except TargetUnreachable:
            if not margin:
                raise
    raise AssertionError("unreachable")


def _safe_part(t: Station, plan, join_us: int, allow_sun: bool) -> tuple[int, int, str | None]:
    """Return (join, end, why it ends early or None) of the pass stretch outside every zone.

    (`acquire` then keeps the run-up's rest point outside too.)
    """
    p = plan.path.points
    i0, i1, hit = t.safety.safe_stretch(p.t_us, np.mod(p.az_rad, 2 * math.pi), p.el_rad,
                                        join_us, t.config.min_pass_track_s, allow_sun=allow_sun)
    end = int(p.t_us[i1])
    if hit is not None:
        # the run-out after the end carries on about half a ramp along the path: end that
        # much (and a second) earlier, so it too stays outside
        end -= int((t.config.ramp_s / 2 + 1.0) * 1e6)
    why = None if hit is None else f"stops before: {hit.describe('the satellite')}"
    return int(p.t_us[i0]), end, why



def tracking_figures(t: Station, op: Operation, s) -> dict[str, Any]:
    """A finished track's figures: on target (the truth), following, planned, the outcome;
    the offsets in force at its end apart (the place on target moved with them)."""
    figures = s.track_summary(t.config.degraded_after_s, t.on_target.planned_for(op.id))
    offsets = t.steering.corrections(op).offsets
    if offsets.any:
        end_us = int(op.info.get("tracking_to_us") or s.to_us)
        figures["guide_offset_arcsec"] = {"north": offsets.total("dec", end_us),
                                          "east": offsets.total("ra", end_us)}
        figures["offsets"] = {axis: offsets.total(axis, end_us)
                              for axis in ("ra", "dec", "az", "el", "path", "transverse")
                              if offsets.total(axis, end_us)}
    return figures


def _observed_deg(t: Station, target: Any, t_us: int) -> tuple[float, float]:
    o = observe_mount_times(target, np.array([t_us], np.int64), t.config.site, t.eop)
    return math.degrees(float(o.az_rad[0])) % 360.0, math.degrees(float(o.el_rad[0]))


def check_elements(sat: Satellite, now_us: int, max_age_days: float) -> None:
    """Refuse elements farther than `max_age_days` from the mount time (StaleElements)."""
    epoch_us = int(sat.epoch.to_unix_us()[0])
    age_days = (now_us - epoch_us) / 86_400e6
    if abs(age_days) > max_age_days:
        side = "after" if age_days > 0 else "before"
        raise StaleElements(
            f"{sat.name}: the mount time {iso_utc(now_us)} is {abs(age_days):.1f} days {side} "
            f"the TLE epoch {iso_utc(epoch_us)} (limit {max_age_days:g} days); positions may be "
            "off by kilometres or the satellite may have decayed -- load fresh elements "
            "(e.g. from CelesTrak); `vs where --tle FILE` gives the same warning")


@contextlib.contextmanager
def _sgp4_errors(sat: Satellite, now_us: int):
    try:
        yield
    except SatelliteError as exc:
        raise StaleElements(
            f"{sat.name}: SGP4 cannot propagate these elements to {iso_utc(now_us)} ({exc}); "
            "the satellite may have decayed or the TLE is too old -- load fresh elements "
            "(e.g. from CelesTrak); `vs where --tle FILE` gives the same warning") from None


def _choose_pass(t: Station, sat: Satellite, here):
    cfg = t.config
    start = UtcTimes.from_unix_us(here.t_us - int(PASS_LOOKBACK_S * 1e6))
    with _sgp4_errors(sat, here.t_us), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        passes = satellite_passes(sat, cfg.site, start,
                                  start.shifted(PASS_LOOKBACK_S + cfg.pass_search_s),
                                  min_el_deg=t.limits.el_min_deg, eop=t.eop)

    def prepare_s(join_us: int) -> float:
        # the slew from here to where the pass is at the join, the run-up and the margins
        o = observe_mount_times(sat, np.array([join_us], np.int64), cfg.site, t.eop)
        to_az = float(unwrap_azimuth(o.az_rad, limits=t.limits, current_az_rad=here.az_rad)[0])
        slew_s = t.motion.plan_slew_s(here, to_az, float(o.el_rad[0]), t.limits)
        return slew_s * SLEW_MARGIN + 3.0 + t.margins.start_lead_s + cfg.ramp_s

    with _sgp4_errors(sat, here.t_us):
        choice = choose_pass(windows_from_passes(passes), here.t_us, prepare_s=prepare_s,
                             min_track_s=cfg.min_pass_track_s)
    if choice is None:
        raise TargetUnreachable(f"{sat.name} has no pass above {t.limits.el_min_deg:g} deg with "
                                f"at least {cfg.min_pass_track_s:g} s left to track in the next "
                                f"{cfg.pass_search_s / 3600:g} h")
    return choice
