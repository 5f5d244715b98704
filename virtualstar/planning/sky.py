"""Where the targets, the Sun and the Moon are over a night: the grids the scheduler works on.

Everything here is evaluated once per night on a grid of `step_s` (a minute by default):
the scheduler then only compares arrays. A block is accepted only if the grid points
one step before its start and after its end satisfy its constraints too, so the smooth
motion in between cannot break them (the tests check every block at one-second steps).
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass

import erfa
import numpy as np

from virtualstar.astro import (
    AvoidanceZones,
    EarthOrientation,
    Satellite,
    Site,
    UtcTimes,
    find_events,
    observe_mount_times,
    plan_slew,
    resolve_target,
)
from virtualstar.astro.avoidance import body_places
from virtualstar.astro.bodies import DARK_SUN_EL_DEG, satellite_sunlit

from .exceptions import ProgramError
from .program import ProgramTarget

__all__ = ["SUNSET_SUN_EL_DEG", "NightGrid", "TargetSky", "night_window", "target_skies"]

DEFAULT_STEP_S = 60.0
SCAN_STEP_S = 10.0  # satellites: the step of the search for passes above min_el
#: Sidereal targets observed together (ERFA's per-time work is shared by all the chunks);
#: their arrays, not the whole program's, are what a plan holds at once.
STARS_PER_CHUNK = 256


@dataclass(frozen=True)
class NightGrid:
    """Mount times of the night (µs) and the Sun's and Moon's observed places on them (deg)."""

    t_us: np.ndarray
    sun_az_deg: np.ndarray
    sun_el_deg: np.ndarray
    moon_az_deg: np.ndarray
    moon_el_deg: np.ndarray
    step_s: float

    @classmethod
    def build(cls, start_us: int, end_us: int, site: Site, eop: EarthOrientation,
              step_s: float = DEFAULT_STEP_S) -> NightGrid:
        t = np.arange(start_us, end_us + 1, int(step_s * 1e6), dtype=np.int64)
        places = body_places(UtcTimes.from_unix_us(t), site, eop, ("sun", "moon"))
        (saz, sel), (maz, mel) = places["sun"], places["moon"]
        return cls(t, np.degrees(saz), np.degrees(sel), np.degrees(maz), np.degrees(mel), step_s)

    @functools.cached_property
    def times(self) -> UtcTimes:
        """The grid as UtcTimes (one object: ERFA's per-grid context is cached on its values)."""
        return UtcTimes.from_unix_us(self.t_us)

    def interpolated(self, t_us: np.ndarray) -> NightGrid:
        """The Sun and Moon at other times of the night, interpolated (they move < 0.25°
        per minute: linear interpolation on the grid is good to a few arcseconds)."""
        def at(values: np.ndarray, angle: bool = False) -> np.ndarray:
            v = np.unwrap(values, period=360.0) if angle else values
            out = np.interp(t_us, self.t_us, v)
            return out % 360.0 if angle else out

        return NightGrid(np.asarray(t_us), at(self.sun_az_deg, True), at(self.sun_el_deg),
                         at(self.moon_az_deg, True), at(self.moon_el_deg), self.step_s)


@dataclass(frozen=True)
class TargetSky:
    """A target's observed place on the grid and where its constraints hold.

    `valid`: every constraint holds (mask over the grid); `never`: the constraints that hold
    at no grid point. The place (degrees, float32: 0.1″ is plenty for a plan) is kept only
    for a target that is valid somewhere: a night of 10 000 targets, most of them never
    up, stays small (benchmarks/bench_plan_memory.py).
    """

    target: ProgramTarget
    az_deg: np.ndarray | None
    el_deg: np.ndarray | None
    valid: np.ndarray
    never: tuple[str, ...] = ()

    @classmethod
    def from_masks(cls, target: ProgramTarget, az_deg: np.ndarray, el_deg: np.ndarray,
                   checks: dict[str, np.ndarray]) -> TargetSky:
        """Reduce {constraint: mask} to `valid` and `never`; keep the place if ever valid."""
        valid = np.ones(az_deg.shape, bool)
        for mask in checks.values():
            valid &= mask
        never = tuple(name for name, mask in checks.items() if not mask.any())
        if not valid.any():
            return cls(target, None, None, valid, never)
        return cls(target, az_deg.astype(np.float32), el_deg.astype(np.float32), valid, never)


#: Sunset and sunrise: the Sun's upper limb on the horizon with standard refraction, i.e. its
#: centre's geometric elevation at −(16′ semi-diameter + 34′ refraction) (USNO, skyfield's
#: almanac). The site's own refraction model is not used for it: at the horizon no model
#: is good to a few arcminutes, and the almanac's sunset is the one people compare with.
SUNSET_SUN_EL_DEG = -50.0 / 60.0


def night_window(date_text: str, site: Site, eop: EarthOrientation) -> tuple[int, int]:
    """Return (sunset, sunrise) in µs of the night that begins on a local calendar date.

    Sunset and sunrise as in the almanacs: SUNSET_SUN_EL_DEG (the upper limb touching the
    horizon through standard refraction), for a sea-level horizon (no dip for the height).
    """
    try:
        day = UtcTimes.from_iso([f"{date_text}T12:00:00Z"])
    except Exception as exc:
        raise ProgramError(f"--night {date_text!r}: expected a date, e.g. 2024-05-18 ({exc})") \
            from None
    # local noon: 12 h UTC shifted by the longitude, then the next set and rise of the Sun
    noon = day.shifted(-site.lon_deg / 15.0 * 3600.0)
    from virtualstar.astro import SolarSystemBody

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        events = find_events(SolarSystemBody("sun"), site.without_refraction(), noon,
                             36 * 3600.0, horizon_deg=SUNSET_SUN_EL_DEG, eop=eop)
    sets = [e for e in events if e.kind == "set"]
    if not sets:
        raise ProgramError(f"--night {date_text}: the Sun does not set at this site (polar "
                           "day); give --from and --to")
    sunset = sets[0].utc
    rises = [e for e in events if e.kind == "rise"
             and float(e.utc.seconds_since(sunset.jd1[0], sunset.jd2[0])[0]) > 0]
    if not rises:
        raise ProgramError(f"--night {date_text}: the Sun does not rise again within a day "
                           "(polar night); give --from and --to")
    return int(sunset.to_unix_us()[0]), int(rises[0].utc.to_unix_us()[0])


def _sky_object(target: ProgramTarget):
    from virtualstar.astro import IcrsStar, parse_radec

    if target.kind == "radec":
        ra, dec = parse_radec(target.spec)
        return IcrsStar(ra, dec, name=target.name)
    try:
        return resolve_target(target.spec)
    except KeyError as exc:
        raise ProgramError(f"target {target.name!r}: {str(exc).strip(chr(34))}") from None


def load_target_satellite(target: ProgramTarget) -> Satellite:
    """Return the satellite of a target, from the TLE text its program carries."""
    return _satellite(target.tle_text, target.spec, str(target.tle_file or "the TLE text"),
                      target.name)


@functools.lru_cache(maxsize=64)  # re-planning a night reads the same elements again
def _satellite(tle_text: str, spec: str, source: str, name: str) -> Satellite:
    from catalogs import select_satellite
    from catalogs.exceptions import CatalogError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            records = _tle_records(tle_text, source)
        return Satellite.from_record(select_satellite(list(records), spec))
    except (KeyError, ValueError, CatalogError) as exc:
        raise ProgramError(f"target {name!r}: {str(exc).strip(chr(34))}") from None


@functools.lru_cache(maxsize=8)  # several targets of a program share one TLE file
def _tle_records(tle_text: str, source: str) -> tuple:
    from catalogs import parse_tle_text

    return tuple(parse_tle_text(tle_text, source))


def target_tle_text(target: ProgramTarget) -> str:
    """Return the three TLE lines of a satellite target (its name line first)."""
    from catalogs import select_satellite

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = select_satellite(list(_tle_records(target.tle_text, "the TLE text")), target.spec)
    return f"{rec.name}\n{rec.line1}\n{rec.line2}\n"


def target_skies(targets: list[ProgramTarget], grid: NightGrid, site: Site,
                 eop: EarthOrientation, zones: AvoidanceZones) -> list[TargetSky]:
    """Observe sidereal targets on the grid and evaluate their constraints there.

    Catalog stars and RA/Dec targets are observed together (`observe_stars`: ERFA's
    per-time work once for all of them); planets and the Moon one by one.
    """
    from virtualstar.astro import IcrsStar
    from virtualstar.astro.stars import observe_stars

    objects = [_sky_object(t) for t in targets]
    out: list[TargetSky | None] = [None] * len(targets)

    def keep(k: int, az_rad: np.ndarray, el_rad: np.ndarray) -> None:
        az, el = np.degrees(az_rad) % 360.0, np.degrees(el_rad)
        out[k] = TargetSky.from_masks(targets[k], az, el,
                                      constraint_masks(targets[k], az, el, grid, zones))

    stars = [k for k, obj in enumerate(objects) if isinstance(obj, IcrsStar)]
    for first in range(0, len(stars), STARS_PER_CHUNK):  # memory: one chunk's arrays at a time
        chunk = stars[first:first + STARS_PER_CHUNK]
        az, el = observe_stars([objects[k] for k in chunk], grid.times, site, eop)
        for i, k in enumerate(chunk):
            keep(k, az[i], el[i])
    for k, obj in enumerate(objects):
        if out[k] is None:
            obs = observe_mount_times(obj, grid.t_us, site, eop)
            keep(k, obs.az_rad, obs.el_rad)
    return [sky for sky in out if sky is not None]


def constraint_masks(target: ProgramTarget, az: np.ndarray, el: np.ndarray, grid: NightGrid,
                     zones: AvoidanceZones) -> dict[str, np.ndarray]:
    """Return {constraint: mask} for directions (deg) at the grid's times."""
    floor = np.maximum(target.min_el_deg, zones.min_el_deg(np.radians(az)))
    sun_sep = _sep(az, el, grid.sun_az_deg, grid.sun_el_deg)
    checks = {
        "elevation": el >= floor,
        "azimuth": target.az_allowed(az),
        "sun_altitude": grid.sun_el_deg <= target.sun_max_el_deg,
        "sun_zone": sun_sep >= zones.sun_radius_deg,
    }
    if target.moon_min_sep_deg or zones.moon_radius_deg:
        moon_sep = _sep(az, el, grid.moon_az_deg, grid.moon_el_deg)
        checks["moon_separation"] = moon_sep >= max(target.moon_min_sep_deg,
                                                    zones.moon_radius_deg or 0.0)
    if target.window_us is not None:
        lo, hi = target.window_us
        checks["window"] = (grid.t_us >= lo) & (grid.t_us <= hi)
    return checks


def satellite_windows(target: ProgramTarget, grid: NightGrid, site: Site, eop: EarthOrientation,
                      zones: AvoidanceZones, step_s: float = 1.0, *,
                      mount_geometry: str = "altaz") -> list[dict]:
    """Return the passes of a satellite target in the night, each trimmed to its part that
    satisfies the target's constraints: [{start_us, end_us, culmination_el_deg, az/el...}].

    On a German mount (`mount_geometry="german"`) a pass is never planned across the
    meridian, where the mount would have to flip mid-track: it is cut to its longest
    stretch on one side (``meridian_cut`` true), as the VSS's pass selection does.
    """
    sat = load_target_satellite(target)
    t0, t1 = int(grid.t_us[0]), int(grid.t_us[-1])
    # where it is above min_el: a scan every SCAN_STEP_S (one vectorised SGP4 call), each
    # stretch then widened by a scan step and sampled every `step_s`, so that the
    # constraint masks find its edges to `step_s` (a pass shorter than a scan step is
    # too short for a block anyway)
    scan_us = int(SCAN_STEP_S * 1e6)
    coarse = np.arange(t0, t1 + 1, scan_us, dtype=np.int64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        coarse_el = np.degrees(observe_mount_times(sat, coarse, site, eop).el_rad)
    out = []
    for i0, i1 in _runs(coarse_el >= target.min_el_deg):
        a, b = max(t0, int(coarse[i0]) - scan_us), min(t1, int(coarse[i1]) + scan_us)
        t = np.arange(a, b + 1, int(step_s * 1e6), dtype=np.int64)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            obs = observe_mount_times(sat, t, site, eop)
        az, el = np.degrees(obs.az_rad) % 360.0, np.degrees(obs.el_rad)
        fine = grid.interpolated(t)
        ok = np.ones(t.shape, bool)
        for mask in constraint_masks(target, az, el, fine, zones).values():
            ok &= mask
        if target.sunlit_while_dark:
            ok &= (satellite_sunlit(sat.satrec, UtcTimes.from_unix_us(t), eop)
                   & (fine.sun_el_deg < DARK_SUN_EL_DEG))
        whole = _runs(ok)
        if mount_geometry == "german":
            ok &= ~_meridian_crossings(obs.az_rad, obs.el_rad, site)
        runs = _runs(ok)
        if not runs:
            continue
        j0, j1 = max(runs, key=lambda r: r[1] - r[0])
        cut = (j0, j1) != max(whole, key=lambda r: r[1] - r[0])  # not what alt-az gets
        path = np.degrees(np.unwrap(obs.az_rad[j0:j1 + 1]))
        out.append({"start_us": int(t[j0]), "end_us": int(t[j1]),
                    "az_travel_deg": float(path[-1] - path[0]),
                    "start_az_deg": float(az[j0]), "start_el_deg": float(el[j0]),
                    "end_az_deg": float(az[j1]), "end_el_deg": float(el[j1]),
                    "culmination_el_deg": float(el.max()),
                    **({"meridian_cut": True} if cut else {})})
    return out


def _meridian_crossings(az_rad: np.ndarray, el_rad: np.ndarray, site: Site) -> np.ndarray:
    """True at each sample whose hour angle has the other sign than the sample before (the
    first sample after a meridian crossing): removing them splits a pass into its sides.
    The hour angle's sign is the azimuth's side of the meridian (refraction leaves it)."""
    ha, _dec = erfa.ae2hd(np.mod(az_rad, 2 * np.pi), el_rad, np.radians(site.lat_deg))
    side = np.sin(ha) >= 0
    return np.r_[False, side[1:] != side[:-1]]


def _sep(az1, el1, az2, el2) -> np.ndarray:
    return np.degrees(erfa.seps(np.radians(az1), np.radians(el1), np.radians(az2),
                                np.radians(el2)))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Return (first, last) index of every run of True."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def slew_s(from_az_deg: float, from_el_deg: float, to_az_deg: float, to_el_deg: float,
           limits) -> float:
    """Mount seconds of the point-to-point slew between two places (shortest azimuth way)."""
    d_az = (to_az_deg - from_az_deg + 180.0) % 360.0 - 180.0
    return plan_slew_deg(0.0, from_el_deg, d_az, to_el_deg, limits)


def plan_slew_deg(from_az_deg: float, from_el_deg: float, to_az_deg: float, to_el_deg: float,
                  limits) -> float:
    """Mount seconds of the point-to-point slew between two mount positions (deg, as is)."""
    return plan_slew(math.radians(from_az_deg), math.radians(from_el_deg),
                     math.radians(to_az_deg), math.radians(to_el_deg), limits).duration_s
