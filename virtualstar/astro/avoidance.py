"""Where a telescope must never point: near the Sun (and the Moon), below the local horizon.

`AvoidanceZones` holds the rules: a cone of `sun_radius_deg` around the Sun
(default 30°), optionally one of `moon_radius_deg` around the Moon, and a horizon
profile (`Horizon`: azimuth → lowest usable elevation) or a flat elevation limit.
The functions here are pure: directions and times in, verdicts out.

* `check_places` judges observed directions at mount times and returns the first
  one inside a zone (which zone, how far from the body, when).
* `slew_route` finds how to slew from one place to another without the path
  the mount actually takes (both axes moving, each with its own trapezoid)
  crossing the Sun or Moon zone: straight, one axis first, or over the top.
* `load_horizon_file` reads a horizon profile from a text file (format below).

Horizon file: one point per line, ``AZ_DEG EL_DEG`` (azimuth north through east,
the lowest usable elevation there), `#` starts a comment; between points the
elevation is interpolated linearly in azimuth, through north. Example::

    # trees in the east, a dome in the south-west
    0    8
    90   15
    135  8
    225  20
    270  8
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import erfa
import numpy as np

from .altaz import Horizon, MountLimits
from .bodies import SolarSystemBody
from .earth_orientation import EarthOrientation
from .exceptions import EarthOrientationWarning, SiteError
from .site import Site
from .slew import plan_slew
from .timescales import UtcTimes

__all__ = ["DEFAULT_SUN_RADIUS_DEG", "AvoidanceZones", "ZoneHit", "avoidance_from_options",
           "body_places", "check_places", "load_avoidance", "load_horizon_file", "slew_route",
           "zone_hits", "zone_mask"]

DEFAULT_SUN_RADIUS_DEG = 30.0
ROUTE_STEP_S = 0.5  # slew paths are judged every half second
_OVER_THE_TOP_DEG = 85.0  # a detour may cross over the top at this elevation
_CROSSING_MARGIN_DEG = 3.0  # ... or this far above or below a zone
_DRIFT_DEG = 0.01  # the body moves a little during a slew: tolerated when leaving a zone


@dataclass(frozen=True)
class AvoidanceZones:
    """The places a telescope must not point to (degrees).

    sun_radius_deg: cone around the Sun (0 switches it off: engineering only);
    moon_radius_deg: cone around the Moon, None for none; horizon: the site's
    profile, None for the flat `el_min_deg`.
    """

    sun_radius_deg: float = DEFAULT_SUN_RADIUS_DEG
    moon_radius_deg: float | None = None
    horizon: Horizon | None = None
    el_min_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sun_radius_deg) and 0.0 <= self.sun_radius_deg <= 90.0):
            raise ValueError(f"sun_radius_deg={self.sun_radius_deg}: expected 0..90 degrees")
        if self.moon_radius_deg is not None and not (
                math.isfinite(self.moon_radius_deg) and 0.0 <= self.moon_radius_deg <= 90.0):
            raise ValueError(f"moon_radius_deg={self.moon_radius_deg}: expected 0..90 degrees")

    def as_dict(self) -> dict[str, Any]:
        """The zones as JSON (the server's status `safety`); `from_dict` reads it back."""
        h = self.horizon
        return {"sun_radius_deg": self.sun_radius_deg, "moon_radius_deg": self.moon_radius_deg,
                "el_min_deg": self.el_min_deg,
                "horizon": None if h is None else {"az_deg": list(h.az_deg),
                                                   "el_deg": list(h.el_deg)}}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> AvoidanceZones:
        h = doc.get("horizon")
        return cls(sun_radius_deg=doc["sun_radius_deg"], moon_radius_deg=doc.get("moon_radius_deg"),
                   horizon=Horizon(tuple(h["az_deg"]), tuple(h["el_deg"])) if h else None,
                   el_min_deg=doc.get("el_min_deg", 0.0))

    @property
    def bodies(self) -> dict[str, float]:
        """Return {body: radius_deg} of the zones in force."""
        out = {}
        if self.sun_radius_deg > 0:
            out["sun"] = self.sun_radius_deg
        if self.moon_radius_deg:
            out["moon"] = self.moon_radius_deg
        return out

    def min_el_deg(self, az_rad: np.ndarray) -> np.ndarray:
        """Return the lowest usable elevation (deg) at observed azimuths (rad)."""
        flat = np.full(np.shape(az_rad), self.el_min_deg, dtype=float)
        if self.horizon is None:
            return flat
        return np.maximum(flat, np.degrees(self.horizon.min_el_rad(np.asarray(az_rad))))


@dataclass(frozen=True)
class ZoneHit:
    """The first direction found inside a zone: which, where, when, how far from the body."""

    zone: str  # "sun", "moon" or "horizon"
    index: int  # into the arrays checked
    t_us: int
    az_deg: float
    el_deg: float
    separation_deg: float  # from the body; for the horizon: elevation above (−: below) it
    limit_deg: float  # the zone's radius; for the horizon: the lowest usable elevation there

    def describe(self, what: str = "the target") -> str:
        when = UtcTimes.from_unix_us(self.t_us).iso(0)[0]
        if self.zone == "horizon":
            return (f"{what} is at elevation {self.el_deg:.2f}° (az {self.az_deg:.2f}°) at {when}, "
                    f"below the horizon limit {self.limit_deg:.2f}° there")
        body = self.zone.capitalize()
        return (f"{what} is {self.separation_deg:.2f}° from the {body} at {when} "
                f"(az {self.az_deg:.2f}° el {self.el_deg:.2f}°), inside the {self.limit_deg:g}° "
                f"{body} exclusion zone")


def body_places(times: UtcTimes, site: Site, eop: EarthOrientation | None,
                bodies=("sun",)) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Return {body: (az_rad, el_rad)} observed at `times` (skyfield's ephemeris).

    The places are interpolated (as unit vectors) between exact ones a minute apart,
    cached per hour: the Sun moves 0.25° and the Moon 0.5° in a minute, so the
    interpolation errs by well under an arcsecond, and a check costs microseconds
    instead of an ephemeris evaluation each time.
    """
    t_us = np.asarray(times.to_unix_us(), np.int64)
    out = {}
    for name in bodies:
        vec = np.empty((t_us.size, 3))
        hours = t_us // _HOUR_US
        for hour in np.unique(hours):
            sel = hours == hour
            grid_us, grid = _body_hour(name, site, eop, int(hour))
            frac = (t_us[sel] - grid_us[0]) / _GRID_US
            k = np.clip(frac.astype(np.int64), 0, len(grid_us) - 2)
            w = (frac - k)[:, None]
            vec[sel] = grid[k] * (1.0 - w) + grid[k + 1] * w
        vec /= np.linalg.norm(vec, axis=1)[:, None]
        out[name] = (np.arctan2(vec[:, 1], vec[:, 0]) % (2 * math.pi),
                     np.arcsin(np.clip(vec[:, 2], -1.0, 1.0)))
    return out


_HOUR_US = 3_600_000_000
_GRID_US = 60_000_000


@functools.lru_cache(maxsize=512)
def _body_hour(name: str, site: Site, eop, hour: int) -> tuple[np.ndarray, np.ndarray]:
    """Return (grid µs, unit vectors N,E,up) of a body's observed place, a minute apart.

    `eop` is part of the key by identity (EarthOrientation compares by identity).
    """
    grid_us = hour * _HOUR_US + np.arange(0, _HOUR_US + _GRID_US, _GRID_US, dtype=np.int64)
    with warnings.catch_warnings():
        # predicted UT1 costs a zone of tens of degrees nothing: no notice for it
        warnings.simplefilter("ignore", EarthOrientationWarning)
        obs = SolarSystemBody(name).observe(UtcTimes.from_unix_us(grid_us), site, eop)
    ce = np.cos(obs.el_rad)
    return grid_us, np.stack([ce * np.cos(obs.az_rad), ce * np.sin(obs.az_rad),
                              np.sin(obs.el_rad)], axis=1)


def check_places(az_rad: np.ndarray, el_rad: np.ndarray, t_us: np.ndarray, zones: AvoidanceZones,
                 site: Site, eop: EarthOrientation | None = None, *,
                 horizon: bool = True) -> ZoneHit | None:
    """Return the first of the observed directions (at mount times `t_us`) inside a zone, or None.

    Directions are compared with the Sun/Moon at the same times; `horizon` False
    judges only the body zones (a slew path may pass low, not near the Sun).
    """
    hits = zone_hits(az_rad, el_rad, t_us, zones, site, eop, horizon=horizon)
    firsts = [_hit(name, np.argmax(inside), *rest) for name, (inside, *rest) in hits.items()
              if inside.any()]
    return min(firsts, key=lambda h: h.index) if firsts else None


def zone_mask(az_rad: np.ndarray, el_rad: np.ndarray, t_us: np.ndarray, zones: AvoidanceZones,
              site: Site, eop: EarthOrientation | None = None, *,
              horizon: bool = True) -> np.ndarray:
    """Return a boolean array: True where a direction lies inside any zone."""
    hits = zone_hits(az_rad, el_rad, t_us, zones, site, eop, horizon=horizon)
    inside = np.zeros(np.shape(np.atleast_1d(az_rad)), bool)
    for mask, *_ in hits.values():
        inside |= mask
    return inside


def zone_hits(az_rad, el_rad, t_us, zones: AvoidanceZones, site: Site,
              eop: EarthOrientation | None = None, *, horizon: bool = True) -> dict[str, tuple]:
    """Return {zone: (inside mask, t_us, az, el, separation_deg, limit_deg)} per zone in force."""
    az = np.atleast_1d(np.asarray(az_rad, float))
    el = np.atleast_1d(np.asarray(el_rad, float))
    t = np.broadcast_to(np.atleast_1d(np.asarray(t_us, np.int64)), az.shape)
    out: dict[str, tuple] = {}
    if horizon:
        floor = zones.min_el_deg(az)
        out["horizon"] = (np.degrees(el) < floor - 1e-9, t, az, el, np.degrees(el) - floor, floor)
    bodies = zones.bodies
    if bodies and az.size:
        times = UtcTimes.from_unix_us(t)
        for name, (baz, bel) in body_places(times, site, eop, tuple(bodies)).items():
            sep = np.degrees(erfa.seps(az, el, baz, bel))
            radius = np.full(az.shape, bodies[name])
            out[name] = (sep < radius, t, az, el, sep, radius)
    return out


def _hit(zone: str, i, t, az, el, separation, limit) -> ZoneHit:
    i = int(i)
    return ZoneHit(zone, i, int(t[i]), math.degrees(az[i]) % 360.0, math.degrees(el[i]),
                   float(separation[i]) if zone != "horizon" else 0.0, float(limit[i]))


def slew_route(from_az_rad: float, from_el_rad: float, to_az_rad: float, to_el_rad: float,
               t_us: int, limits: MountLimits, zones: AvoidanceZones, site: Site,
               eop: EarthOrientation | None = None, *,
               target_exempt: bool = False) -> tuple[list[tuple[float, float]], ZoneHit | None]:
    """Return (waypoints, None) for a slew whose path keeps out of the Sun/Moon zones.

    A mount that starts inside a zone may leave it, moving away from the body all the
    while; otherwise a path may not enter a zone. `target_exempt` (the park position,
    the stow) lets the final approach end inside, moving towards its target only.
    Azimuths are mount (cable-wrap) angles. The waypoints end with the target; the
    first candidate that is clear wins: straight; azimuth first (el held); elevation
    first (az held); then across at another elevation — high (85°), just above the
    zones, just below them — going up or down first. If none is, returns ([], the
    straight path's first hit).
    """
    target = (to_az_rad, to_el_rad)
    candidates = [
        [target],
        [(to_az_rad, from_el_rad), target],
        [(from_az_rad, to_el_rad), target],
    ]
    for el in _crossing_elevations_rad(t_us, limits, zones, site, eop):
        candidates.append([(from_az_rad, el), (to_az_rad, el), target])
    first_hit = None
    for legs in candidates:
        hit = _route_hit([(from_az_rad, from_el_rad), *legs], t_us, limits, zones, site, eop,
                         target_exempt)
        if hit is None:
            return legs, None
        first_hit = first_hit or hit
    return [], first_hit


def _crossing_elevations_rad(t_us: int, limits: MountLimits, zones: AvoidanceZones, site: Site,
                             eop) -> list[float]:
    """Elevations at which to cross in azimuth: high, and clear above/below each body's zone."""
    out = [_OVER_THE_TOP_DEG]
    bodies = zones.bodies
    if bodies:
        places = body_places(UtcTimes.from_unix_us(np.array([t_us], np.int64)), site, eop,
                             tuple(bodies))
        for name, (_, bel) in places.items():
            el = math.degrees(float(bel[0]))
            out += [el + bodies[name] + _CROSSING_MARGIN_DEG, el - bodies[name] - _CROSSING_MARGIN_DEG]
    low = max(limits.el_min_deg, zones.el_min_deg) + 1.0
    high = min(limits.el_max_deg, 88.0)
    return [math.radians(e) for e in out if low <= e <= high]


def _route_hit(points: list[tuple[float, float]], t_us: int, limits: MountLimits,
               zones: AvoidanceZones, site: Site, eop, target_exempt: bool = False
               ) -> ZoneHit | None:
    az_parts, el_parts, t_parts = [], [], []
    t0 = t_us
    for (a0, e0), (a1, e1) in zip(points[:-1], points[1:], strict=True):
        plan = plan_slew(a0, e0, a1, e1, limits)
        t_s, az, el = plan.sample(ROUTE_STEP_S)
        az_parts.append(az)
        el_parts.append(el)
        t_parts.append(t0 + np.round(np.asarray(t_s) * 1e6).astype(np.int64))
        t0 += int(plan.duration_s * 1e6)
    az, el, t = np.concatenate(az_parts), np.concatenate(el_parts), np.concatenate(t_parts)
    hits = zone_hits(az, el, t, zones, site, eop, horizon=False)
    found = []
    for name, (inside, *rest) in hits.items():
        sep = rest[3]
        bad = inside.copy()
        # a mount that starts inside a zone (the Sun came to it) may leave it, but only
        # by moving away from the body: no sample of that first stretch may come nearer
        lead = _run_length(inside)
        if lead:
            bad[:lead] = sep[:lead] < np.maximum.accumulate(sep[:lead]) - _DRIFT_DEG
        if target_exempt:  # the stow: the last stretch may end inside, never deeper than it
            tail = _run_length(inside[::-1])
            if tail and tail < len(inside):
                end = len(inside) - tail
                bad[end:] = sep[end:] < sep[-1] - _DRIFT_DEG
        idx = np.flatnonzero(bad)
        if idx.size:
            found.append(_hit(name, idx[0], *rest))
    return min(found, key=lambda h: h.index) if found else None


def _run_length(mask: np.ndarray) -> int:
    """Return how many leading elements of `mask` are True."""
    off = np.flatnonzero(~mask)
    return int(off[0]) if off.size else len(mask)


def load_horizon_file(path: str | Path) -> Horizon:
    """Read a horizon profile (``AZ_DEG EL_DEG`` per line, `#` comments); raise SiteError."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SiteError(f"cannot read horizon file {path}: {getattr(exc, 'strerror', exc)}") from None
    az, el = [], []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        try:
            a, e = (float(x) for x in parts)
        except ValueError:
            raise SiteError(f"{path}, line {number}: {raw.strip()!r}: expected two numbers, "
                            "AZ_DEG EL_DEG (e.g. '135 12.5')") from None
        if not (math.isfinite(a) and 0.0 <= a <= 360.0):
            raise SiteError(f"{path}, line {number}: azimuth {a:g}: expected 0..360 degrees")
        if not (math.isfinite(e) and -5.0 <= e <= 89.0):
            raise SiteError(f"{path}, line {number}: elevation {e:g}: expected -5..89 degrees")
        az.append(a)
        el.append(e)
    if not az:
        raise SiteError(f"{path}: no points; expected lines of AZ_DEG EL_DEG")
    if len(set(a % 360.0 for a in az)) != len(az):
        raise SiteError(f"{path}: an azimuth appears twice (0 and 360 are the same)")
    return Horizon(tuple(az), tuple(el))


def load_avoidance(path: str | Path | None = None) -> AvoidanceZones:
    """Read the `[safety]` table of a site TOML file (the same file as `load_site`).

    Keys: ``sun_radius_deg`` (default 30), ``moon_radius_deg`` (default none),
    ``horizon_file`` (a horizon profile, relative to the TOML file). Without a path the
    file named by $VIRTUALSTAR_SITE is read, else the defaults apply. Raises SiteError.
    """
    import os

    from .site import SITE_ENV_VAR, read_site_file

    if path is None:
        path = os.environ.get(SITE_ENV_VAR) or None
    if path is None:
        return AvoidanceZones()
    path = Path(path)
    table = read_site_file(path).get("safety", {})
    known = {"sun_radius_deg", "moon_radius_deg", "horizon_file"}
    unknown = sorted(set(table) - known)
    if unknown:
        raise SiteError(f"{path} [safety]: unknown keys {unknown}; valid keys: {sorted(known)}")
    horizon = None
    if "horizon_file" in table:
        horizon = load_horizon_file(path.parent / str(table["horizon_file"]))
    try:
        return AvoidanceZones(sun_radius_deg=float(table.get("sun_radius_deg",
                                                             DEFAULT_SUN_RADIUS_DEG)),
                              moon_radius_deg=(None if table.get("moon_radius_deg") is None
                                               else float(table["moon_radius_deg"])),
                              horizon=horizon)
    except (TypeError, ValueError) as exc:
        raise SiteError(f"{path} [safety]: {exc}") from None


def avoidance_from_options(*, site_file: str | Path | None = None,
                           sun_radius_deg: float | None = None,
                           moon_radius_deg: float | None = None,
                           horizon_file: str | Path | None = None) -> AvoidanceZones:
    """Return the site's zones with command-line overrides applied (None = keep); SiteError."""
    import dataclasses

    zones = load_avoidance(site_file)
    changes: dict = {}
    if sun_radius_deg is not None:
        changes["sun_radius_deg"] = sun_radius_deg
    if moon_radius_deg is not None:
        changes["moon_radius_deg"] = moon_radius_deg or None
    if horizon_file is not None:
        changes["horizon"] = load_horizon_file(horizon_file)
    try:
        return dataclasses.replace(zones, **changes)
    except ValueError as exc:
        raise SiteError(str(exc)) from None
