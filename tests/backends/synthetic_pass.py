"""A satellite whose pass culminates over a site at a chosen instant: an ISS-like TLE made now.

The simulators run on the host clock, so a test that tracks "the ISS" needs a pass
happening while it runs. This builds elements for an ISS-like orbit (420 km, 51.6°,
near-circular) with the epoch at the culmination, placed so the pass culminates at
the chosen elevation, and writes them as a TLE (sgp4's exporter). The truth of every
check stays skyfield's: it propagates the same TLE independently of the VSS.
"""

from __future__ import annotations

import math

import numpy as np
from sgp4.api import WGS72, Satrec
from sgp4.exporter import export_tle

EARTH_RADIUS_KM = 6378.135  # WGS72, as SGP4
MU_KM3_S2 = 398600.8
ALTITUDE_KM = 420.0
INCLINATION_DEG = 51.6


def skyfield_times(ts, unix_s):
    """Skyfield times of POSIX seconds (UTC without leap seconds, as mount time): through
    datetimes, since ``ts.utc(1970, 1, 1, 0, 0, s)`` would count the leap seconds since 1970."""
    from datetime import UTC, datetime

    return ts.from_datetimes([datetime.fromtimestamp(float(x), tz=UTC)
                              for x in np.atleast_1d(unix_s)])


def _gmst_rad(unix_s: float) -> float:
    jd = unix_s / 86400.0 + 2440587.5
    t = (jd - 2451545.0) / 36525.0
    g = 280.46061837 + 360.98564736629 * (jd - 2451545.0) + 0.000387933 * t * t
    return math.radians(g % 360.0)


def _satrec(epoch_unix_s: float, raan_rad: float, u_rad: float) -> Satrec:
    a = EARTH_RADIUS_KM + ALTITUDE_KM
    n_rad_min = math.sqrt(MU_KM3_S2 / a**3) * 60.0
    epoch_days = epoch_unix_s / 86400.0 + 2440587.5 - 2433281.5  # days since 1949-12-31 00:00
    sat = Satrec()
    sat.sgp4init(WGS72, "i", 99999, epoch_days, 1e-5, 0.0, 0.0, 0.0005, 0.0,
                 math.radians(INCLINATION_DEG), u_rad % (2 * math.pi), n_rad_min,
                 raan_rad % (2 * math.pi))
    return sat


def synthetic_pass_tle(site_lat_deg: float, site_lon_deg: float, height_m: float,
                       culmination_unix_s: float, max_el_deg: float = 70.0,
                       name: str = "ISS-LIKE",
                       away_from_az_deg: float | None = None) -> tuple[str, str, str]:
    """Return (name, line1, line2) of a pass over the site culminating near the given time
    (at least 90° of azimuth from `away_from_az_deg` at culmination, when given)."""
    from skyfield.api import EarthSatellite, load, wgs84

    ts = load.timescale(builtin=True)
    site = wgs84.latlon(site_lat_deg, site_lon_deg, height_m)
    inc = math.radians(INCLINATION_DEG)
    u0 = math.asin(max(-1.0, min(1.0, math.sin(math.radians(site_lat_deg)) / math.sin(inc))))
    theta = _gmst_rad(culmination_unix_s) + math.radians(site_lon_deg)
    raan0 = theta - math.atan2(math.cos(inc) * math.sin(u0), math.cos(u0))
    times = skyfield_times(ts, culmination_unix_s + np.arange(-400.0, 400.0, 2.0))
    best = None
    for shift_deg in np.arange(-6.0, 6.01, 0.1):
        sat = _satrec(culmination_unix_s, raan0 + math.radians(shift_deg), u0)
        l1, l2 = export_tle(sat)
        es = EarthSatellite(l1, l2, name, ts)
        alt_a, az_a, _ = (es - site).at(times).altaz()
        alt = alt_a.degrees
        k = int(np.argmax(alt))
        score = abs(alt[k] - max_el_deg) + abs(k * 2.0 - 400.0) / 100.0
        if away_from_az_deg is not None:
            off = abs((az_a.degrees[k] - away_from_az_deg + 180.0) % 360.0 - 180.0)
            score += 100.0 if off < 90.0 else 0.0
        if best is None or score < best[0]:
            best = (score, l1, l2)
    return name, best[1], best[2]
