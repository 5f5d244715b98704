"""A day that ends in a leap second (2016-12-31, 86 401 s): UTC in, positions right.

Mount time counts POSIX seconds (86 400 a day); ERFA's quasi-JD scales the day fraction by
the day's real length; SGP4 counts UTC continuously (held at 24:00:00 through the leap
second); anything interpolated in time runs in SI seconds. Skyfield and astropy, computed
here, are the truth, over the whole day and inside 23:59:60.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest
from astro_testkit import sep_rad
from sgp4.api import WGS72, Satrec

from virtualstar.astro.exceptions import TimeParseError
from virtualstar.astro.satellites import Satellite
from virtualstar.astro.timescales import UtcTimes

ONE_ARCSEC_RAD = math.radians(1 / 3600)
ONE_MAS_RAD = ONE_ARCSEC_RAD / 1000


def _iss_like_satellite_with_epoch_on_the_leap_day() -> Satellite:
    """An ISS-like orbit (51.6°, 15.54 rev/day) whose elements date from 2016-12-31 06:00 UTC."""
    sat = Satrec()
    epoch_days_since_1949_12_31 = (dt.datetime(2016, 12, 31, 6) - dt.datetime(1949, 12, 31)
                                   ).total_seconds() / 86400.0
    sat.sgp4init(WGS72, "i", 25544, epoch_days_since_1949_12_31, 3.0e-5, 0.0, 0.0, 0.0007,
                 math.radians(60.0), math.radians(51.64), math.radians(300.0),
                 15.54 * 2 * math.pi / 1440.0, math.radians(120.0))
    return Satellite("ISS-LIKE", sat)


def _iss_at_epoch_midnight_overhead_at_the_leap_second() -> Satellite:
    """ISS-like elements dated 2016-12-31 00:00 UTC (the issue's case), placed so that the
    pass culminates near 80° over the test site at 23:59:55: the last hour of the day,
    where a second of Earth rotation matters most, is seen from a few hundred km."""
    sat = Satrec()
    epoch_days_since_1949_12_31 = (dt.datetime(2016, 12, 31) - dt.datetime(1949, 12, 31)
                                   ).total_seconds() / 86400.0
    sat.sgp4init(WGS72, "i", 25544, epoch_days_since_1949_12_31, 3.0e-5, 0.0, 0.0, 0.0007,
                 math.radians(60.0), math.radians(51.64), math.radians(194.0),
                 15.54 * 2 * math.pi / 1440.0, math.radians(30.0))
    return Satellite("ISS-LIKE", sat)


def _skyfield_held_at_the_leap_second(satrec, ts):
    """skyfield's EarthSatellite, except that inside the leap second SGP4 gets the held
    count (24:00:00.0 of the leap day), our documented convention; everywhere else it is
    skyfield's own (t.whole, TAI fraction − leap seconds), untouched."""
    from skyfield.api import EarthSatellite

    leap_day_end_jd = 2457754.5  # 2017-01-01 00:00 UTC

    class Held(EarthSatellite):
        def _position_and_velocity_TEME_km(self, t):
            whole = np.atleast_1d(t.whole)
            fraction = np.atleast_1d(t.tai_fraction - t._leap_seconds() / 86400.0)
            seconds = np.atleast_1d(t.utc.second)
            inside = seconds >= 60.0
            jd = np.where(inside, leap_day_end_jd, whole).astype(float)
            fraction = np.where(inside, 0.0, fraction + (whole - jd)).astype(float)
            e, r, v = self.model.sgp4_array(jd, fraction)
            r, v = r.T, v.T
            if np.ndim(t.whole) == 0:
                r, v = r[:, 0], v[:, 0]
            return r, v, None

    return Held.from_satrec(satrec, ts)


def _leap_day_stamps() -> list[str]:
    """The whole day every 97 s, its last two minutes every 1.3 s, and 23:59:60.x."""
    seconds = np.unique(np.r_[np.arange(0.0, 86400.0, 97.0), np.arange(86280.0, 86400.0, 1.3)])
    stamps = [f"2016-12-31T{int(x // 3600):02d}:{int(x % 3600 // 60):02d}:"
              f"{x % 60:06.3f}Z" for x in seconds]
    stamps += [f"2016-12-31T23:59:60.{k:03d}Z" for k in range(0, 1000, 50)]
    stamps += [f"2017-01-01T00:00:{x:06.3f}Z" for x in (0.0, 0.001, 0.004, 0.3, 1.0, 30.0)]
    return stamps


def test_satellite_over_the_whole_leap_day_matches_skyfield(site, eop, skyfield_ts, de421):
    from skyfield.api import EarthSatellite, wgs84

    sat = _iss_at_epoch_midnight_overhead_at_the_leap_second()
    stamps = _leap_day_stamps()
    times = UtcTimes.from_iso(stamps)
    obs = sat.observe(times, site.without_refraction(), eop)
    assert math.degrees(obs.el_rad.max()) > 75.0  # the pass at the leap second is seen high
    observer = de421["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    # light that left inside the leap second: those at 23:59:60.x and the first few ms after
    inside = np.array([":60." in s or s.startswith("2017-01-01T00:00:00.00") for s in stamps])
    assert inside.sum() == 23
    t = skyfield_ts.tt_jd(*times.tt())
    stock = EarthSatellite.from_satrec(sat.satrec, skyfield_ts)
    held = _skyfield_held_at_the_leap_second(sat.satrec, skyfield_ts)
    everywhere = np.ones(len(stamps), bool)
    for chosen, truth in ((~inside, stock), (everywhere, held)):
        alt, az, _ = observer.at(t[chosen]).observe(de421["earth"] + truth).apparent().altaz()
        err = sep_rad(az.radians, alt.radians, obs.az_rad[chosen], obs.el_rad[chosen])
        worst = int(np.argmax(err))
        assert err.max() < 0.01 * ONE_ARCSEC_RAD, (
            f"{np.asarray(stamps)[chosen][worst]}: {err.max() / ONE_ARCSEC_RAD:.4f} arcsec")


def test_the_held_count_keeps_the_satellite_continuous_through_the_leap_second(site, eop):
    sat = _iss_at_epoch_midnight_overhead_at_the_leap_second()
    stamps = ([f"2016-12-31T23:59:59.{k}Z" for k in range(10)]
              + [f"2016-12-31T23:59:60.{k}Z" for k in range(10)]
              + [f"2017-01-01T00:00:00.{k}Z" for k in range(10)])
    obs = sat.observe(UtcTimes.from_iso(stamps), site.without_refraction(), eop)
    steps = sep_rad(obs.az_rad[1:], obs.el_rad[1:], obs.az_rad[:-1], obs.el_rad[:-1])
    # 0.1 s apart: never a jump (POSIX would jump a second ahead, then run it again)
    assert steps.max() < 2.0 * np.median(steps)


def test_stars_tracked_through_the_leap_day_match_astropy(site, eop):
    from astropy import units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    from virtualstar.astro.stars import IcrsStar, observe_stars

    stamps = [f"2016-12-31T{h:02d}:{m:02d}:{s:02d}Z" for h in (22, 23) for m in range(0, 60, 3)
              for s in (0, 37)] + [f"2016-12-31T23:59:{s:02d}Z" for s in range(40, 61)]
    times = UtcTimes.from_iso(stamps)  # dense enough for the spline, as a track's are
    geo = site.without_refraction()
    vega = IcrsStar(279.2347, 38.7837, 200.94, 286.23, 130.23, -13.5, 2000.0, "Vega")
    obs = vega.observe(times, geo, eop)
    many_az, many_el = observe_stars([vega, IcrsStar(10.0, 60.0)], times, geo, eop)
    loc = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg,
                                      site.height_m * u.m)
    t_ap = Time(times.jd1, times.jd2, format="jd", scale="utc")
    ref = SkyCoord(279.2347 * u.deg, 38.7837 * u.deg, pm_ra_cosdec=200.94 * u.mas / u.yr,
                   pm_dec=286.23 * u.mas / u.yr, distance=(1000 / 130.23) * u.pc,
                   radial_velocity=-13.5 * u.km / u.s,
                   obstime=Time(2000.0, format="jyear", scale="tt")
                   ).apply_space_motion(new_obstime=t_ap).transform_to(
                       AltAz(obstime=t_ap, location=loc))
    assert sep_rad(ref.az.rad, ref.alt.rad, obs.az_rad, obs.el_rad).max() < ONE_MAS_RAD
    # the plan's many-star path, 600-s nodes: within its documented milliarcseconds
    assert sep_rad(ref.az.rad, ref.alt.rad, many_az[0], many_el[0]).max() < 5 * ONE_MAS_RAD


def test_mount_time_on_the_leap_day_is_the_posix_count():
    for text in ("2016-12-31T00:00:00", "2016-12-31T12:00:00", "2016-12-31T23:59:59.5",
                 "2017-01-01T00:00:00.5"):
        posix_us = round(dt.datetime.fromisoformat(text).replace(tzinfo=dt.UTC).timestamp() * 1e6)
        times = UtcTimes.from_iso([text])
        assert times.to_unix_us()[0] == posix_us
        back = UtcTimes.from_unix_us(posix_us)
        (a1, a2), (b1, b2) = back.tt(), times.tt()
        assert abs(((a1 - b1) + (a2 - b2))[0]) * 86400 < 2e-6  # the same instant, to 2 µs


def test_the_leap_second_itself_is_read_and_maps_to_the_next_posix_second():
    inside = UtcTimes.from_iso(["2016-12-31T23:59:60.5Z"])
    after = UtcTimes.from_iso(["2017-01-01T00:00:00.5Z"])
    (a1, a2), (b1, b2) = after.tai(), inside.tai()
    tai_gap_s = ((a1 - b1) + (a2 - b2))[0] * 86400
    assert tai_gap_s == pytest.approx(1.0, abs=1e-5)  # a real second passes between them
    assert inside.iso() == ["2016-12-31T23:59:60.500Z"]
    assert inside.to_unix_us()[0] == after.to_unix_us()[0]  # POSIX cannot tell them apart


def test_second_60_on_a_day_without_a_leap_second_is_refused():
    with pytest.raises(TimeParseError, match="no leap second"):
        UtcTimes.from_iso(["2016-12-30T23:59:60Z"])


def test_satellite_on_the_leap_day_matches_skyfield(site, eop, skyfield_ts, de421):
    from skyfield.api import EarthSatellite, wgs84

    sat = _iss_like_satellite_with_epoch_on_the_leap_day()
    # typed UTC stamps, as `vs where --at` reads them (ERFA's quasi-JD of a 86 401-s day)
    start = dt.datetime(2016, 12, 31)
    stamps = [start + dt.timedelta(seconds=s) for s in range(0, 86400, 5)]
    times = UtcTimes.from_iso([f"{t:%Y-%m-%dT%H:%M:%S}Z" for t in stamps])
    obs = sat.observe(times, site.without_refraction(), eop)
    up = obs.el_rad > 0.0
    assert up.sum() > 50
    observer = de421["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    es = EarthSatellite.from_satrec(sat.satrec, skyfield_ts)
    # skyfield's instants from the same calendar fields and its own leap-second table
    seconds_of_day = np.arange(0, 86400, 5)[up].astype(float)
    t = skyfield_ts.utc(2016, 12, 31, 0, 0, seconds_of_day)
    alt, az, _ = observer.at(t).observe(de421["earth"] + es).apparent().altaz()
    err = sep_rad(az.radians, alt.radians, obs.az_rad[up], obs.el_rad[up])
    assert err.max() < 0.01 * ONE_ARCSEC_RAD, err.max() / ONE_MAS_RAD


def test_the_servers_satellite_path_on_the_leap_day_matches_skyfield(site, eop, skyfield_ts,
                                                                      de421):
    """The VSS follows a target in mount time (POSIX µs) chunk by chunk through
    `TargetPath.observe`: the same fixed code, the same truth, up to 23:59:59.7."""
    from skyfield.api import EarthSatellite, wgs84

    from virtualstar.astro import MountLimits
    from virtualstar.server.trajectories import TargetPath

    sat = _iss_at_epoch_midnight_overhead_at_the_leap_second()
    geo = site.without_refraction()
    path = TargetPath(sat, geo, limits=MountLimits(el_min_deg=-90.0), eop=eop)
    first_us = int(UtcTimes.from_iso(["2016-12-31T23:50:00Z"]).to_unix_us()[0])
    t_us = first_us + np.arange(0, 600_000_000, 300_000, dtype=np.int64)  # to 23:59:59.7
    az, el = [], []
    for chunk in np.array_split(t_us, 60):  # 10-s chunks, as the feeder asks for them
        a, e, *_ = path.observe(chunk)
        az.append(a)
        el.append(e)
    az, el = np.concatenate(az), np.concatenate(el)
    up = el > 0.0
    assert math.degrees(el.max()) > 75.0 and up.sum() > 300
    observer = de421["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    t = skyfield_ts.tt_jd(*UtcTimes.from_unix_us(t_us[up]).tt())
    truth = EarthSatellite.from_satrec(sat.satrec, skyfield_ts)
    alt, taz, _ = observer.at(t).observe(de421["earth"] + truth).apparent().altaz()
    err = sep_rad(taz.radians, alt.radians, az[up], el[up])
    assert err.max() < 0.01 * ONE_ARCSEC_RAD, err.max() / ONE_ARCSEC_RAD
