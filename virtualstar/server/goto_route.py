"""Waypoints for a goto mount whose own slew path must keep out of the Sun/Moon zones.

A mount without a trajectory buffer (an Alpaca or INDI driver) does not follow our path
between two waypoints: it slews its own way, each native axis from its start to its end
— linearly in RA and Dec together (the Alpaca simulator), or each axis at its own speed
(the INDI simulator), in right ascension/declination of date on an equatorial mount, in
azimuth/elevation on an alt-az one. Any such way stays inside the *box* its two ends span
in the native axes (the right ascension the shorter way round). So a leg is safe when
that whole box, sampled on a grid and seen from the site at the times the gotos run, keeps
`GOTO_PATH_MARGIN_DEG` out of every body's zone (like the envelope's own route check, the
way may pass low: the horizon is the targets' and waypoints' check); a leg whose
box does not is cut in two along the route the safety envelope checked, until every box
clears. As the legs shorten, the boxes shrink onto that route, which the envelope keeps
`avoidance._CROSSING_MARGIN_DEG` clear of the zones: the splitting ends.

A leg that starts inside a zone (the Sun came to a parked mount) or ends in one (the
stow) may not take the box deeper than its ends are.

Not modelled: a German mount that flips its pier side in the middle of a goto (its axes
then go through the pole); the waypoints are short, and `rate_loop`'s planner keeps
passes off the meridian, but a goto that flips is only as safe as the driver's own flip.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from virtualstar.astro import EarthOrientation, Site
from virtualstar.astro.avoidance import AvoidanceZones, zone_hits
from virtualstar.astro.mount_frames import apparent_radec_to_observed, observed_to_apparent_radec

from .exceptions import InExclusionZone

if TYPE_CHECKING:
    from .station import Station

__all__ = ["GOTO_PATH_MARGIN_DEG", "driver_legs", "leg_clearance_deg", "split_for_driver"]

GOTO_PATH_MARGIN_DEG = 1.0  # a driver's box keeps this far outside every body's zone
MIN_LEG_DEG = 0.25  # a leg this short whose box still touches a zone: no safe way
BOX_GRID = 9  # samples per native axis of a leg's box
ROUTE_WINDOW_S = 120.0  # the boxes are judged against the bodies now and this much later


def _box_samples(a0: float, e0: float, a1: float, e1: float, t_us: int, equatorial: bool,
                 site: Site, eop: EarthOrientation) -> tuple[np.ndarray, np.ndarray]:
    """Observed (az, el) over the native-axis box spanned by a leg's ends, rad."""
    if equatorial:
        t = np.array([t_us, t_us], np.int64)
        ra, dec = observed_to_apparent_radec(np.array([a0, a1]), np.array([e0, e1]), t, site,
                                             eop)
        d_ra = (ra[1] - ra[0] + math.pi) % (2 * math.pi) - math.pi
        u = np.linspace(0.0, 1.0, BOX_GRID)
        g_ra, g_dec = np.meshgrid(ra[0] + u * d_ra, dec[0] + u * (dec[1] - dec[0]))
        n = g_ra.size
        return apparent_radec_to_observed(g_ra.ravel(), g_dec.ravel(),
                                          np.full(n, t_us, np.int64), site, eop)
    u = np.linspace(0.0, 1.0, BOX_GRID)
    g_az, g_el = np.meshgrid(a0 + u * (a1 - a0), e0 + u * (e1 - e0))
    return g_az.ravel(), g_el.ravel()


def _clear_deg(hit: tuple) -> np.ndarray:
    """How far (deg) beyond a body's zone and `GOTO_PATH_MARGIN_DEG`, from `zone_hits`."""
    return np.asarray(hit[4], float) - np.asarray(hit[5], float) - GOTO_PATH_MARGIN_DEG


def leg_clearance_deg(a0: float, e0: float, a1: float, e1: float, times_us: list[int],
                      equatorial: bool, zones: AvoidanceZones, site: Site,
                      eop: EarthOrientation) -> float:
    """How far the worst place of a leg's box stays outside a zone (deg, negative: inside),
    judged against how far its ends are (a leg may not go deeper than its ends)."""
    worst = math.inf
    for t_us in times_us:
        az, el = _box_samples(a0, e0, a1, e1, t_us, equatorial, site, eop)
        ends_az, ends_el = np.array([a0, a1]), np.array([e0, e1])
        # bodies only: like the envelope's route check, a slew's way may pass low (a mount
        # parked low leaves from there), never near the Sun or Moon
        box = zone_hits(az, el, t_us, zones, site, eop, horizon=False)
        ends = zone_hits(ends_az, ends_el, t_us, zones, site, eop, horizon=False)
        for name in box:
            clear, end_sep = _clear_deg(box[name]), _clear_deg(ends[name])
            # a leg that starts or ends inside may reach as deep as its ends, no deeper
            floor = min(0.0, float(np.min(end_sep)))
            worst = min(worst, float(np.min(clear)) - floor)
    return worst


def split_for_driver(here_az: float, here_el: float, legs: list[tuple[float, float]],
                     times_us: list[int], equatorial: bool, zones: AvoidanceZones, site: Site,
                     eop: EarthOrientation, what: str) -> list[tuple[float, float]]:
    """Cut route legs (mount az/el, rad; target last) into gotos whose native boxes clear
    the zones; the azimuths run as the route was checked (not the shorter way round)."""
    out: list[tuple[float, float]] = []
    a0, e0 = here_az, here_el
    for a1, e1 in legs:
        pending = [(a0, e0, a1, e1)]  # a leg whose box clears stays one goto
        while pending:
            b0, f0, b1, f1 = pending.pop(0)
            if leg_clearance_deg(b0, f0, b1, f1, times_us, equatorial, zones, site, eop) >= 0:
                out.append((b1, f1))
                continue
            length = math.degrees(math.hypot((b1 - b0) * math.cos(0.5 * (f0 + f1)), f1 - f0))
            if length < MIN_LEG_DEG:
                raise InExclusionZone(
                    f"no goto path to {what} keeps the driver's own slew out of the exclusion "
                    f"zones: near az {math.degrees(b0) % 360:.2f}° el {math.degrees(f0):.2f}° "
                    f"even a {length:.2f}° goto would pass within {GOTO_PATH_MARGIN_DEG:g}° "
                    "of a zone")
            bm, fm = 0.5 * (b0 + b1), 0.5 * (f0 + f1)
            pending[:0] = [(b0, f0, bm, fm), (bm, fm, b1, f1)]
        a0, e0 = a1, e1
    return out


def driver_legs(t: Station, here, legs: list[tuple[float, float]], what: str, *,
                allow_sun: bool = False, stow: bool = False) -> list[tuple[float, float]]:
    """The gotos a driver mount takes along a checked route (`Safety.route`'s legs)."""
    zones = t.safety.zones(allow_sun=allow_sun)
    times = [here.t_us, here.t_us + int(ROUTE_WINDOW_S * 1e6)]
    if stow:
        # the park may lie inside a zone: its last leg is the envelope's (target_exempt)
        *head, last = legs
        if not head:
            return legs
        out = split_for_driver(here.az_rad, here.el_rad, head, times,
                               t.link.capabilities.equatorial, zones, t.config.site, t.eop,
                               what)
        return [*out, last]
    return split_for_driver(here.az_rad, here.el_rad, legs, times,
                            t.link.capabilities.equatorial, zones, t.config.site, t.eop, what)
