"""The steps of a procedure on a rate-driven mount (no trajectory buffer): join, follow, passes.

`procedures.py` chooses these from the mount's capabilities (``trajectory_buffer``
false, ``rate_axes`` true); the recipe is the same as with a buffer, in mount time:

* `acquire_by_rates`: plan the join instant from the distance and the driver's rate,
  go round the Sun/Moon zones through fixed waypoints (`slew` role, the checks of
  `goto_safely`), goto the start of the run-up to the path's place at the join
  (`goto_native`, held by the mount's tracking), then hand over to a `RateFollower`
  that starts the path's rate along the run-up and follows the path from the join.
* `equatorial_stretch`: on an equatorial mount, the part of a satellite pass the mount
  can follow without a meridian flip (German) and with its right-ascension axis within
  its rate limit near the pole (the equatorial keyhole).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import erfa
import numpy as np

from .exceptions import TargetUnreachable, Unsupported
from .goto_route import driver_legs
from .operations import Operation, Phase
from .rate_loop import (
    MERIDIAN_LIMIT_DEG,
    NativeFrame,
    RateFollower,
    RateJoin,
    run_up_s,
    run_up_start,
)
from .trajectories import Path, TablePath

if TYPE_CHECKING:
    from .station import Station

__all__ = ["acquire_by_rates", "equatorial_stretch", "follow_now"]

JOIN_MARGIN_S = 5.0  # mount seconds between landing and the run-up's start (the axis-sign
# probe runs meanwhile: about 2 s)
PROBE_ALLOWANCE_US = 4_000_000  # the axis-sign probe: about 2 s at 4 reports a second
STILL_ARCSEC = 2.0  # a path that moves less than this (native axes) may be joined sooner
SOONER_MARGIN_US = 3_000_000  # ... this long after the goto landed, for the loop to take up
# the goto's residual (a loaded host: at 0.5 s an Alpaca star landed 288″ off at the check)
GOTO_SETTLE_S = 1.5  # a goto's end is seen a few reports after the driver lands
MAX_JOIN_PLANS = 6
POLE_RATE_FRACTION = 0.9  # the right-ascension axis may use this much of its rate limit


def frame_of(t: Station) -> NativeFrame:
    return NativeFrame(t.link.capabilities, t.config.site, t.eop)


def require_rates(t: Station) -> None:
    caps = t.link.capabilities
    if not caps.rate_axes:
        raise Unsupported(f"the {caps.backend} mount only takes gotos (no trajectory buffer, no "
                          "rate axes): it can point at a target but not follow it")


def route_estimate_s(t: Station, here, legs: list[tuple[float, float]]) -> float:
    """How long the gotos along `legs` take: 1.5× their length at the driver's top rate,
    and `GOTO_SETTLE_S` each (the driver's end of slew is seen a few reports late)."""
    rate = t.link.capabilities.max_rate_deg_s or 1.0
    total, az0, el0 = 0.0, here.az_rad, here.el_rad
    for az1, el1 in legs:
        total += math.degrees(erfa.seps(az0, el0, az1, el1))
        az0, el0 = az1, el1
    return 1.5 * total / rate + GOTO_SETTLE_S * len(legs)


async def acquire_by_rates(t: Station, op: Operation, path: Path, *,
                           not_before_us: int | None = None, end_us: int | None = None,
                           allow_sun: bool = False,
                           corrections=None) -> tuple[RateJoin, RateFollower]:
    """Goto a point ahead on `path`, then return the join and the follower that takes over.

    Offsets (`corrections`, PWI4-style, guide pulses) need nothing more on a rate mount:
    the loop samples the offset path at every report, so a change is followed from the
    next report on. Changes made before the join start at the join (the goto aims at the
    place the offsets had when it was planned).
    """
    require_rates(t)
    frame = frame_of(t)
    stats = getattr(t.link, "stats", None)
    run_up_us = int(run_up_s(stats.period_s() if stats is not None else None) * 1e6)
    margin_s = JOIN_MARGIN_S + run_up_us / 1e6
    for plan in range(MAX_JOIN_PLANS):
        here = await t.motion.position()
        join_us = max(here.t_us, not_before_us or 0)
        for _ in range(2):  # the route (a detour round a zone) sets the goto's length
            at = path.sample(np.array([join_us], np.int64))
            what = f"the join point of {op.target}"
            legs = driver_legs(t, here, t.safety.route(
                here.az_rad, here.el_rad, float(at.az_rad[0]), float(at.el_rad[0]), here.t_us,
                what, allow_sun=allow_sun), what, allow_sun=allow_sun)
            slew_s = route_estimate_s(t, here, legs)
            join_us = here.t_us + int((slew_s + margin_s) * 1e6)
            if not_before_us is not None:
                join_us = max(join_us, int(not_before_us))
        if end_us is not None and join_us > end_us - 10_000_000:
            raise TargetUnreachable(f"too little of the path is left to join it: it ends "
                                    f"{(end_us - here.t_us) / 1e6:.0f} s from now")
        # the goto goes to the start of the run-up (a few degrees before the join point
        # at most, on the line the path arrives along): that place is checked and routed
        if corrections is not None:
            corrections.hold_until(join_us)
        start = run_up_start(frame, path, join_us, run_up_us)
        az, el = frame.observed(start, join_us - run_up_us)
        t.supervisor.phase(op, Phase.SLEWING, to_az_deg=math.degrees(az) % 360.0,
                           to_el_deg=math.degrees(el), join_us=join_us,
                           run_up_s=run_up_us / 1e6)
        legs = t.safety.route(here.az_rad, here.el_rad, az, el, here.t_us,
                              f"the run-up to {op.target}", allow_sun=allow_sun)
        if len(legs) > 1:
            op.info["detour_deg"] = [[round(math.degrees(a), 3), round(math.degrees(e), 3)]
                                     for a, e in legs[:-1]]
        steps = driver_legs(t, here, legs, f"the run-up to {op.target}", allow_sun=allow_sun)
        for leg_az, leg_el in steps[:-1]:  # waypoints round a zone
            await t.link.call("goto_place", math.degrees(leg_az), math.degrees(leg_el))
        await t.link.call("goto_native", start[0], start[1])
        landed_us = await t.motion.mount_time_us()
        # the sign probe (after a connection or a pier change) runs before the run-up
        probe_us = 0 if getattr(t.link, "signs_measured", True) else PROBE_ALLOWANCE_US
        if landed_us < join_us - run_up_us - probe_us - 500_000:
            join_us = _sooner_if_still(frame, path, join_us,
                                       landed_us + probe_us + run_up_us + SOONER_MARGIN_US)
            if corrections is not None:
                corrections.hold_until(join_us)
            if join_us - landed_us > 5e6:
                t.supervisor.phase(op, Phase.WAITING, join_us=join_us)
            follower = RateFollower(t.link, frame, path, join_us, errors=t.errors,
                                    note_rates=None, run_up_us=run_up_us)
            op.info["join_plans"] = plan + 1
            t.supervisor.phase(op, Phase.JOINING)
            return RateJoin(path, join_us, landed_us), follower
        margin_s *= 2.0  # the goto took longer than planned: join later
    raise TargetUnreachable(f"could not reach the join point of {op.target} ahead of the "
                            f"target after {MAX_JOIN_PLANS} gotos (the driver's gotos are "
                            "slower than its rate limit says)")


def _sooner_if_still(frame: NativeFrame, path: Path, join_us: int, earliest_us: int) -> int:
    """Join at `earliest_us` instead when the path's native place is the same then (within
    `STILL_ARCSEC`): a star on an equatorial mount, whose place of date barely moves, need
    not wait for the slew estimate (made for the driver's worst case) to run out."""
    if earliest_us >= join_us:
        return join_us
    at = np.array([earliest_us, join_us], np.int64)
    a1, a2 = frame.place(path, at)
    d1 = float((a1[1] - a1[0] + math.pi) % (2 * math.pi) - math.pi) * math.cos(float(a2[1]))
    moved_arcsec = math.degrees(math.hypot(d1, float(a2[1] - a2[0]))) * 3600.0
    return earliest_us if moved_arcsec < STILL_ARCSEC else join_us


def follow_now(t: Station, path: Path, join_us: int) -> tuple[RateJoin, RateFollower]:
    """Start following `path` from where the mount is (a move at rates: no goto first)."""
    require_rates(t)
    frame = frame_of(t)
    return (RateJoin(path, join_us, join_us),
            RateFollower(t.link, frame, path, join_us, errors=t.errors))


def equatorial_stretch(t: Station, path: TablePath, join_us: int,
                       min_s: float) -> tuple[int, int, str | None]:
    """Return (start, end, why it stops early) of the pass an equatorial mount can follow.

    German mounts: one side of the meridian (hour angle sign kept, `MERIDIAN_LIMIT_DEG`
    beyond it). Both: the right-ascension rate within `POLE_RATE_FRACTION` of the limit
    (near the pole it grows as 1/cos δ). The longest such stretch from `join_us` lasting
    `min_s`; TargetUnreachable when there is none.
    """
    caps = t.link.capabilities
    p = path.points
    frame = frame_of(t)
    native = frame.sample(path, p.t_us)
    ok = p.t_us >= join_us
    limit = math.radians(caps.max_rate_deg_s or 1.0) * POLE_RATE_FRACTION
    fast = np.abs(native.az_rate_rad_s) > limit
    ok &= ~fast
    why_end = {}
    if caps.geometry == "german":
        ha = frame.hour_angle(native.az_rad, p.t_us)
        east = ha < math.radians(MERIDIAN_LIMIT_DEG)
        # split at every change of side: each stretch keeps one side of the pier
        side_change = np.r_[False, east[1:] != east[:-1]]
        why_end["meridian"] = side_change
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    stretches = []
    for i0, i1 in zip(edges[::2], edges[1::2] - 1, strict=True):
        cuts = [i0]
        if "meridian" in why_end:
            cuts += [int(k) for k in np.flatnonzero(why_end["meridian"][i0 + 1:i1 + 1]) + i0 + 1]
        cuts.append(i1 + 1)
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            if b - 1 > a:
                stretches.append((a, b - 1))
    good = [(a, b) for a, b in stretches if (p.t_us[b] - p.t_us[a]) / 1e6 >= min_s]
    if not good:
        what = "crosses the meridian (a German mount would flip) and " if caps.geometry == \
            "german" else ""
        raise TargetUnreachable(f"the pass {what}leaves less than {min_s:g} s that the "
                                f"{caps.geometry} mount can follow (right-ascension rate "
                                f"limit {math.degrees(limit):.2f}°/s near the pole)")
    a, b = max(good, key=lambda s: p.t_us[s[1]] - p.t_us[s[0]])
    why = None
    if b + 1 < len(p.t_us):
        if fast[b + 1]:
            why = "stops before the pole, where the right-ascension axis would exceed its rate"
        elif caps.geometry == "german":
            why = "stops at the meridian: a German mount would need a flip mid-track"
    if a > 0 and caps.geometry == "german" and "meridian" in why_end and why_end["meridian"][a]:
        why = (why + "; " if why else "") + "starts after the meridian (the flip is done " \
            "by the goto before the join)"
    return int(p.t_us[a]), int(p.t_us[b]), why
