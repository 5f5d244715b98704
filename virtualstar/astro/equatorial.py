"""The equatorial systems observers' software speaks, from and to our ICRS (ERFA throughout).

* J2000 (ASCOM `EquatorialSystem` 2): FK5 at equinox and epoch J2000, ERFA `h2fk5`/`fk52h`
  (the frame bias, ~20 mas, between ICRS and FK5).
* JNow (INDI `EQUATORIAL_EOD_COORD`, ASCOM `EquatorialSystem` 1): geocentric apparent
  place on the true equator and equinox of date. ERFA's `atci13`/`atic13` give the CIRS
  place (light deflection, annual aberration, precession-nutation); the equinox-based
  right ascension is the CIRS one minus the equation of the origins (`eo06a`).
* Local apparent sidereal time: ERFA `gst06a` (UT1 from the IERS table, TT) plus the
  site's east longitude.

All functions take and return degrees (hours for sidereal time) at mount times
(`t_us`, µs since 1970 UTC), as the façades need them; radians stay inside.
"""

from __future__ import annotations

import math
import warnings

import erfa
import numpy as np

from .earth_orientation import EarthOrientation
from .timescales import UtcTimes

__all__ = ["icrs_to_j2000", "icrs_to_jnow", "j2000_to_icrs", "jnow_to_icrs",
           "local_sidereal_time_hours"]


def icrs_to_j2000(ra_deg: float, dec_deg: float) -> tuple[float, float]:
    """Return FK5 J2000 (RA, Dec) degrees of an ICRS direction."""
    ra, dec, *_ = erfa.h2fk5(math.radians(ra_deg), math.radians(dec_deg), 0.0, 0.0, 0.0, 0.0)
    return math.degrees(float(ra)) % 360.0, math.degrees(float(dec))


def j2000_to_icrs(ra_deg: float, dec_deg: float) -> tuple[float, float]:
    """Return ICRS (RA, Dec) degrees of an FK5 J2000 direction."""
    ra, dec, *_ = erfa.fk52h(math.radians(ra_deg), math.radians(dec_deg), 0.0, 0.0, 0.0, 0.0)
    return math.degrees(float(ra)) % 360.0, math.degrees(float(dec))


def _tt(t_us: int) -> tuple[float, float]:
    tt1, tt2 = UtcTimes.from_unix_us(int(t_us)).tt()
    return float(tt1[0]), float(tt2[0])


def icrs_to_jnow(ra_deg: float, dec_deg: float, t_us: int) -> tuple[float, float]:
    """Return the apparent (true equator and equinox of date) RA, Dec degrees at `t_us`."""
    tt1, tt2 = _tt(t_us)
    ri, di, eo = erfa.atci13(math.radians(ra_deg), math.radians(dec_deg), 0.0, 0.0, 0.0, 0.0,
                             tt1, tt2)
    return math.degrees(float(ri - eo)) % 360.0, math.degrees(float(di))


def jnow_to_icrs(ra_deg: float, dec_deg: float, t_us: int) -> tuple[float, float]:
    """Return the ICRS RA, Dec degrees of an apparent (JNow) direction at `t_us`."""
    tt1, tt2 = _tt(t_us)
    eo = erfa.eo06a(tt1, tt2)
    rc, dc, _eo = erfa.atic13(math.radians(ra_deg) + eo, math.radians(dec_deg), tt1, tt2)
    return math.degrees(float(rc)) % 360.0, math.degrees(float(dc))


def local_sidereal_time_hours(t_us: int, lon_deg: float, eop: EarthOrientation) -> float:
    """Return the local apparent sidereal time (hours, 0..24) at `t_us` and east longitude."""
    t = UtcTimes.from_unix_us(int(t_us))
    dut1, _xp, _yp = eop.interpolate(t.jd1, t.jd2, warn=False)
    ut1 = t.ut1(dut1)
    tt1, tt2 = t.tt()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        gst = erfa.gst06a(ut1[0], ut1[1], tt1[0], tt2[0])
    return (math.degrees(float(np.ravel(gst)[0])) + lon_deg) / 15.0 % 24.0
