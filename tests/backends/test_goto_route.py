"""A goto mount's own slew path round the Sun: the waypoints `goto_route` plans keep it out.

The driver does not follow our path between waypoints; the simulators move their axes
in right ascension and declination of date, either both together (the Alpaca
simulator: linear in RA/Dec) or each at its own speed (the INDI simulator: both until
the shorter is done, then the other). Here both ways are flown between every pair of
planned waypoints, and every place on them is judged against astropy's Sun: the
conversions of the waypoints and the paths, and the Sun itself, are astropy's, not ours.
The geometry is the backend scenario's: the Sun about 50° high 2.5 h east of the
meridian at latitude −30°, the route's ends 40° × 1/cos el either side of it at el 35°.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from virtualstar.astro import EarthOrientation, Site, SolarSystemBody, observe_mount_times
from virtualstar.astro.altaz import MountLimits
from virtualstar.astro.avoidance import AvoidanceZones, slew_route
from virtualstar.astro.mount_frames import hour_angle_rad, observed_to_apparent_radec
from virtualstar.server.exceptions import InExclusionZone
from virtualstar.server.goto_route import GOTO_PATH_MARGIN_DEG, split_for_driver

SUN_RADIUS_DEG = 30.0
ROUTE_OFF_DEG = 40.0  # the scenario's route ends: this far (× 1/cos el) either side of the Sun
# instants within astropy-iers-data's measured table, over the seasons (the Sun's declination)
INSTANTS_UTC = ["2025-03-20T06:00:00", "2025-06-21T06:00:00", "2025-09-22T06:00:00",
                "2025-12-21T06:00:00"]


@pytest.fixture(scope="module")
def eop() -> EarthOrientation:
    return EarthOrientation.from_astropy_iers_data()


def _us(iso: str) -> int:
    from astropy.time import Time

    return int(round(Time(iso, scale="utc").unix * 1e6))


def _morning_site(t_us: int, eop) -> Site:
    """Latitude −30°, the longitude that puts the Sun at hour angle −37.5° at `t_us`."""
    base = Site(lat_deg=-30.0, lon_deg=0.0, height_m=1500.0, pressure_hpa=850.0,
                temperature_c=10.0)
    t = np.array([t_us], np.int64)
    o = observe_mount_times(SolarSystemBody("sun"), t, base, eop)
    ra, _ = observed_to_apparent_radec(o.az_rad, o.el_rad, t, base, eop)
    ha = math.degrees(float(hour_angle_rad(ra, t, base, eop)[0]))
    return base.with_overrides(lon_deg=(-37.5 - ha + 180.0) % 360.0 - 180.0)


def _astropy_frames(site: Site, t_us: np.ndarray):
    import astropy.units as u
    from astropy.coordinates import TETE, AltAz, EarthLocation
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    loc = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg,
                                      site.height_m * u.m)
    t = Time(np.asarray(t_us) / 1e6, format="unix", scale="utc")
    altaz = AltAz(obstime=t, location=loc, pressure=site.pressure_hpa * u.hPa,
                  temperature=site.temperature_c * u.deg_C, relative_humidity=site.humidity,
                  obswl=site.wavelength_um * u.um)
    return altaz, TETE(obstime=t, location=loc), t


def _radec_of_date(site, az_deg, el_deg, t_us):
    """astropy: observed az/el → topocentric RA/Dec of date (TETE), degrees."""
    import astropy.units as u
    from astropy.coordinates import SkyCoord

    altaz, tete, _ = _astropy_frames(site, t_us)
    c = SkyCoord(az=np.asarray(az_deg) * u.deg, alt=np.asarray(el_deg) * u.deg, frame=altaz)
    d = c.transform_to(tete)
    return d.ra.deg, d.dec.deg


def _sun_separation_deg(site, ra_deg, dec_deg, t_us) -> np.ndarray:
    """astropy: the observed separation of RA/Dec-of-date places from the Sun, degrees."""
    import astropy.units as u
    from astropy.coordinates import SkyCoord, get_body

    altaz, tete, t = _astropy_frames(site, t_us)
    places = SkyCoord(ra=np.asarray(ra_deg) * u.deg, dec=np.asarray(dec_deg) * u.deg,
                      frame=tete).transform_to(altaz)
    sun = get_body("sun", t, location=altaz.location).transform_to(altaz)
    return places.separation(sun).deg


def _fly(ra0, dec0, ra1, dec1, way: str, n: int = 60):
    """The driver's way between two places of date (degrees): 'linear' (both axes together)
    or 'axes' (each at the same speed: both until the shorter is done, then the other)."""
    d_ra = (ra1 - ra0 + 180.0) % 360.0 - 180.0
    d_dec = dec1 - dec0
    s = np.linspace(0.0, 1.0, n)
    if way == "linear":
        return ra0 + s * d_ra, dec0 + s * d_dec
    longest = max(abs(d_ra), abs(d_dec), 1e-12)
    step = s * longest
    return (ra0 + np.sign(d_ra) * np.minimum(step, abs(d_ra)),
            dec0 + np.sign(d_dec) * np.minimum(step, abs(d_dec)))


def _route(iso: str, eop, step_deg: float | None = None):
    """The scenario's second slew (round the Sun); the gotos `goto_route` plans for it
    (or, with `step_deg`, the route cut into equal az/el steps of at most that)."""
    t0 = _us(iso)
    site = _morning_site(t0, eop)
    sun = observe_mount_times(SolarSystemBody("sun"), np.array([t0], np.int64), site, eop)
    sun_az, sun_el = math.degrees(sun.az_rad[0]), math.degrees(sun.el_rad[0])
    el = 35.0 if sun_el > 30 else 25.0
    off = ROUTE_OFF_DEG / math.cos(math.radians(el))
    a = (math.radians(sun_az + off), math.radians(el))
    b = (math.radians(sun_az - off), math.radians(el))
    zones = AvoidanceZones(sun_radius_deg=SUN_RADIUS_DEG, el_min_deg=15.0)
    limits = MountLimits(el_min_deg=15.0)
    legs, hit = slew_route(*a, *b, t0, limits, zones, site, eop)
    assert hit is None and len(legs) > 1, "the scenario's slew must need a detour"
    if step_deg is None:
        gotos = split_for_driver(*a, legs, [t0, t0 + 120_000_000], True, zones, site, eop,
                                 "the test's end")
    else:
        gotos, a0, e0 = [], *a
        for a1, e1 in legs:
            span = math.degrees(math.hypot((a1 - a0) * math.cos(0.5 * (e0 + e1)), e1 - e0))
            n = max(1, math.ceil(span / step_deg))
            gotos += [(a0 + (a1 - a0) * k / n, e0 + (e1 - e0) * k / n) for k in range(1, n + 1)]
            a0, e0 = a1, e1
    return site, t0, a, gotos


def _closest_approach_deg(site, t0, start, gotos, way: str) -> float:
    places = [start, *gotos]
    az = np.degrees([p[0] for p in places]) % 360.0
    el = np.degrees([p[1] for p in places])
    t = np.full(len(places), t0, np.int64)
    ra, dec = _radec_of_date(site, az, el, t)
    path_ra, path_dec = [], []
    for k in range(len(places) - 1):
        r, d = _fly(ra[k], dec[k], ra[k + 1], dec[k + 1], way)
        path_ra.append(r)
        path_dec.append(d)
    path_ra, path_dec = np.concatenate(path_ra), np.concatenate(path_dec)
    return float(_sun_separation_deg(site, path_ra % 360.0, path_dec,
                                     np.full(len(path_ra), t0, np.int64)).min())


@pytest.mark.parametrize("iso", INSTANTS_UTC)
@pytest.mark.parametrize("way", ["linear", "axes"])
def test_the_drivers_own_slew_between_planned_waypoints_keeps_out_of_the_sun_zone(iso, way, eop):
    site, t0, start, gotos = _route(iso, eop)
    closest = _closest_approach_deg(site, t0, start, gotos, way)
    # the planner keeps every box GOTO_PATH_MARGIN_DEG out; astropy sees the same sky to
    # well under a tenth of that
    assert closest > SUN_RADIUS_DEG + 0.9 * GOTO_PATH_MARGIN_DEG, closest


def test_equal_twenty_degree_steps_let_the_drivers_path_cut_the_zone(eop):
    """The way it was (the route cut into equal az/el steps of ≤ 20°): on at least one
    season the simulators' own way passes nearer the Sun than the planner allows."""
    closest = min(_closest_approach_deg(*_route(iso, eop, step_deg=20.0), way)
                  for iso in INSTANTS_UTC for way in ("linear", "axes"))
    assert closest < SUN_RADIUS_DEG + GOTO_PATH_MARGIN_DEG, closest


def test_a_leg_whose_box_cannot_clear_is_refused(eop):
    """Waypoints on the zone's edge (no room to split into): refused, never flown."""
    t0 = _us(INSTANTS_UTC[0])
    site = _morning_site(t0, eop)
    sun = observe_mount_times(SolarSystemBody("sun"), np.array([t0], np.int64), site, eop)
    az, el = float(sun.az_rad[0]), float(sun.el_rad[0])
    # a leg that runs along the zone's edge, 30.5° below the Sun: inside the margin
    edge = el - math.radians(SUN_RADIUS_DEG + 0.5)
    zones = AvoidanceZones(sun_radius_deg=SUN_RADIUS_DEG)
    with pytest.raises(InExclusionZone, match="driver's own slew"):
        split_for_driver(az - 0.1, edge, [(az + 0.1, edge)], [t0], True, zones, site, eop,
                         "the edge")
