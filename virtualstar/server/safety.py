"""Keep the telescope out of the Sun and Moon zones and above the horizon: the VSS's checks.

`Safety` applies the site's `AvoidanceZones` (virtualstar.astro.avoidance) wherever
the VSS decides where the mount goes:

* a command's target, before anything moves (a refused command leaves the running
  operation alone); a fixed place also over the next `HOLD_LOOKAHEAD_S`, as the Sun
  drifts 15°/h;
* every slew, along the path the mount really takes (`slew_route`: straight, or a
  detour, or refused);
* every chunk of a track (`guard`, called by the trajectory as it is computed): a
  track stops before it would enter a zone or pass below the horizon, and says so;
* a satellite pass: only a stretch outside every zone is tracked (`safe_stretch`).

An operator may override the Sun/Moon zones for one operation (`allow_sun`), for
engineering; the horizon still holds, and each override is logged and broadcast.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable

import numpy as np

from virtualstar.astro import (
    AvoidanceZones,
    EarthOrientation,
    MountLimits,
    Site,
    ZoneHit,
    check_places,
    observe_mount_times,
    slew_route,
    zone_mask,
)

from .exceptions import InExclusionZone, TargetUnreachable

__all__ = ["HOLD_LOOKAHEAD_S", "Safety"]

log = logging.getLogger("virtualstar.server.safety")

HOLD_LOOKAHEAD_S = 3600.0  # a fixed place must stay out of the zones this long (mount s)
_LOOKAHEAD_STEP_S = 300.0


def refusal(hit: ZoneHit, what: str) -> InExclusionZone | TargetUnreachable:
    """Return the error that refuses `what` for `hit` (horizon: unreachable; Sun/Moon: zone)."""
    text = hit.describe(what)
    return TargetUnreachable(text) if hit.zone == "horizon" else InExclusionZone(text)


class Safety:
    """The VSS's avoidance checks for one site, with the mount's current limits."""

    def __init__(self, zones: AvoidanceZones, site: Site, eop: EarthOrientation,
                 limits: Callable[[], MountLimits]) -> None:
        self.configured = zones
        self.site = site
        self.eop = eop
        self._limits = limits

    def zones(self, *, allow_sun: bool = False) -> AvoidanceZones:
        """The zones in force: the flat limit is the mount's; `allow_sun` drops Sun and Moon."""
        zones = dataclasses.replace(self.configured, el_min_deg=self._limits().el_min_deg)
        if allow_sun:
            zones = dataclasses.replace(zones, sun_radius_deg=0.0, moon_radius_deg=None)
        return zones

    def check_target(self, target, t_us: int, what: str, *, allow_sun: bool = False,
                     ahead_s: float = 0.0) -> None:
        """Refuse a sky target inside a zone at `t_us` (and over the next `ahead_s`)."""
        t = _lookahead_us(t_us, ahead_s)
        obs = observe_mount_times(target, t, self.site, self.eop)
        self._check(obs.az_rad, obs.el_rad, t, what, allow_sun, horizon_now_only=True)

    def check_place(self, az_deg: float, el_deg: float, t_us: int, what: str, *,
                    allow_sun: bool = False, ahead_s: float = 0.0) -> None:
        """Refuse a fixed observed place inside a zone now or over the next `ahead_s`."""
        t = _lookahead_us(t_us, ahead_s)
        az = np.full(t.shape, math.radians(az_deg))
        el = np.full(t.shape, math.radians(el_deg))
        self._check(az, el, t, what, allow_sun, horizon_now_only=False)

    def _check(self, az, el, t, what: str, allow_sun: bool, *, horizon_now_only: bool) -> None:
        zones = self.zones(allow_sun=allow_sun)
        # a moving target only has to be above the horizon when the command is given
        hit = check_places(az[:1], el[:1], t[:1], zones, self.site, self.eop)
        if hit is None and len(t) > 1:
            hit = check_places(az, el, t, zones, self.site, self.eop,
                               horizon=not horizon_now_only)
        if hit is not None:
            raise refusal(hit, what)

    def first_hit(self, az_rad: np.ndarray, el_rad: np.ndarray, t_us: np.ndarray, *,
                  allow_sun: bool = False) -> ZoneHit | None:
        """Return the first of these directions (encoder angles as the sky's, azimuth in any
        turn of the cable wrap, at mount times) inside a zone, or None."""
        return check_places(np.mod(az_rad, 2 * math.pi), el_rad, t_us,
                            self.zones(allow_sun=allow_sun), self.site, self.eop)

    def inside(self, az_rad: float, el_rad: float, t_us: int, *, allow_sun: bool = False) -> bool:
        """Return whether a direction (encoder angles as the sky's) lies inside a zone."""
        return self.first_hit(np.array([az_rad]), np.array([el_rad]),
                              np.array([t_us], np.int64), allow_sun=allow_sun) is not None

    def first_clear_us(self, az_rad: float, el_rad: float, from_us: int, to_us: int, *,
                       allow_sun: bool = False, step_s: float = 10.0) -> int:
        """Return the first mount time in [from_us, to_us] a place lies outside every zone.

        `to_us` when it is inside until then (the caller checked that it is clear then).
        """
        t = np.append(np.arange(from_us, to_us, int(step_s * 1e6), dtype=np.int64), to_us)
        inside = zone_mask(np.full(t.shape, az_rad % (2 * math.pi)), np.full(t.shape, el_rad), t,
                           self.zones(allow_sun=allow_sun), self.site, self.eop)
        clear = np.flatnonzero(~inside)
        return int(t[clear[0]]) if clear.size else int(to_us)

    def route(self, from_az_rad: float, from_el_rad: float, to_az_rad: float, to_el_rad: float,
              t_us: int, what: str, *, allow_sun: bool = False,
              stow: bool = False) -> list[tuple[float, float]]:
        """Return the waypoints of a slew that keeps out of the Sun/Moon zones (target last).

        `stow` (the park position): the target itself may lie inside a zone, the way there
        may not go deeper.
        """
        legs, hit = slew_route(from_az_rad, from_el_rad, to_az_rad, to_el_rad, t_us,
                               self._limits(), self.zones(allow_sun=allow_sun), self.site,
                               self.eop, target_exempt=stow)
        if hit is not None:
            raise InExclusionZone(f"no slew path to {what} keeps out of the "
                                  f"{hit.zone.capitalize()} exclusion zone: the straight path "
                                  f"{hit.describe('').strip().removeprefix('is ')}")
        if len(legs) > 1:
            log.info("slew to %s goes round the exclusion zones via %s", what,
                     [(round(math.degrees(a), 2), round(math.degrees(e), 2)) for a, e in legs[:-1]])
        return legs

    def guard(self, what: str, *, allow_sun: bool = False):
        """Return a check for a trajectory's chunks: raise before a chunk enters a zone."""
        zones = self.zones(allow_sun=allow_sun)

        def check(t_us: np.ndarray, az_rad: np.ndarray, el_rad: np.ndarray) -> None:
            hit = check_places(az_rad, el_rad, t_us, zones, self.site, self.eop)
            if hit is not None:
                raise refusal(hit, what)

        return check

    def safe_stretch(self, t_us: np.ndarray, az_rad: np.ndarray, el_rad: np.ndarray,
                     not_before_us: int, min_s: float, *, allow_sun: bool = False
                     ) -> tuple[int, int, ZoneHit | None]:
        """Return (first, last) index of the first run outside every zone from `not_before_us`
        lasting `min_s`, and the hit that ends it (None: it runs to the end).

        Raises the refusal of the first hit when there is no such run.
        """
        zones = self.zones(allow_sun=allow_sun)
        inside = zone_mask(az_rad, el_rad, t_us, zones, self.site, self.eop)
        ok = ~inside & (t_us >= not_before_us)
        edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
        for i0, i1 in zip(edges[::2], edges[1::2] - 1, strict=True):
            if (t_us[i1] - t_us[i0]) / 1e6 >= min_s:
                end_hit = None
                if i1 + 1 < len(t_us):
                    end_hit = check_places(az_rad[i1 + 1:], el_rad[i1 + 1:], t_us[i1 + 1:], zones,
                                           self.site, self.eop)
                return int(i0), int(i1), end_hit
        first = check_places(az_rad, el_rad, t_us, zones, self.site, self.eop)
        if first is None:
            raise TargetUnreachable(f"less than {min_s:g} s of the pass is left to track")
        raise refusal(first, "the pass")


def _lookahead_us(t_us: int, ahead_s: float) -> np.ndarray:
    """Mount times from `t_us` over the next `ahead_s`, every _LOOKAHEAD_STEP_S."""
    return t_us + np.round(np.arange(0.0, ahead_s + 1.0, _LOOKAHEAD_STEP_S) * 1e6).astype(np.int64)
