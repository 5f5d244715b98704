"""A day that ends in a leap second (2016-12-31, 86 401 s): UTC in, positions right.

Mount time counts POSIX seconds (86 400 a day); ERFA's quasi-JD scales the day fraction by
the day's real length; SGP4 counts UTC continuously. Skyfield, computed here, is the truth.
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
