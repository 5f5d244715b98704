"""The frames an equatorial mount reports and turns in, from and to our observed az/el (ERFA).

A German or fork mount driven through ASCOM Alpaca or INDI reports and takes the
topocentric apparent right ascension and declination of date (INDI's
``EQUATORIAL_EOD_COORD``; an Alpaca driver whose ``EquatorialSystem`` is 1, and in
practice most that say otherwise): no refraction, which the mount's own model or
nobody applies. The VSS computes every target as observed az/el (refracted with the
site's weather), so this module converts both ways at mount times:

* `observed_to_apparent_radec`: observed az/el → unrefracted (the refraction table
  inverted by fixed-point iteration, < 1 µas after 3 rounds above 3°) → the horizon
  vector → ITRS → GCRS (IAU 2006/2000A, UT1 and polar motion from the IERS table) →
  true equator and equinox of date (`observed.topocentric_apparent_radec`).
* `apparent_radec_to_observed`: the inverse, refraction applied again.
* `hour_angle_rad`: local apparent hour angle of a right ascension of date.

Radians in, radians out; `t_us` are int64 mount times (µs since 1970, UTC).
"""

from __future__ import annotations

import math
import warnings

import erfa
import numpy as np

from .earth_orientation import EarthOrientation
from .observed import (
    enu_to_azel,
    observe_enu,
    refraction_table,
    topocentric_apparent_radec,
)
from .site import Site
from .timescales import UtcTimes

__all__ = ["apparent_radec_to_observed", "hour_angle_rad", "observed_to_apparent_radec",
           "unrefract_el"]


def unrefract_el(el_rad: np.ndarray, site: Site) -> np.ndarray:
    """Return the geometric elevation whose refracted elevation is `el_rad` (site weather)."""
    el = np.asarray(el_rad, float)
    if not site.refraction:
        return el
    table = refraction_table(site.pressure_hpa, site.temperature_c, site.humidity,
                             site.wavelength_um)
    geo = el.copy()
    for _ in range(4):
        refracted, _rate = table.apply(geo, np.zeros_like(geo))
        geo = geo - (refracted - el)
    return geo


def observed_to_apparent_radec(az_rad: np.ndarray, el_rad: np.ndarray, t_us: np.ndarray,
                               site: Site, eop: EarthOrientation) -> tuple[np.ndarray, np.ndarray]:
    """Return topocentric apparent (RA, Dec) of date, radians, of observed directions."""
    t = np.atleast_1d(np.asarray(t_us, np.int64))
    geo = unrefract_el(np.atleast_1d(el_rad), site)
    return topocentric_apparent_radec(np.atleast_1d(np.asarray(az_rad, float)), geo,
                                      UtcTimes.from_unix_us(t), site, eop)


def apparent_radec_to_observed(ra_rad: np.ndarray, dec_rad: np.ndarray, t_us: np.ndarray,
                               site: Site, eop: EarthOrientation) -> tuple[np.ndarray, np.ndarray]:
    """Return observed (az, el), radians (az in [0, 2π), el refracted), of apparent RA/Dec."""
    t = np.atleast_1d(np.asarray(t_us, np.int64))
    ra = np.atleast_1d(np.asarray(ra_rad, float))
    dec = np.atleast_1d(np.asarray(dec_rad, float))
    times = UtcTimes.from_unix_us(t)
    dut1, xp, yp = eop.interpolate(times.jd1, times.jd2, warn=False)
    tt1, tt2 = times.tt()
    ut11, ut12 = times.ut1(dut1)
    true = erfa.s2c(ra, dec)
    gcrs_to_itrs = erfa.c2t06a(tt1, tt2, ut11, ut12, xp, yp)
    gcrs_to_true = erfa.pnm06a(tt1, tt2)
    gcrs = np.einsum("nji,nj->ni", gcrs_to_true, true)  # the transpose: true → GCRS
    itrs = np.einsum("nij,nj->ni", gcrs_to_itrs, gcrs)
    enu = itrs @ site.enu_matrix().T  # ITRS → (north, east, up)
    if site.refraction:
        obs = observe_enu(enu, np.zeros_like(enu), site)
        return obs.az_rad, obs.el_rad
    az, el, _, _ = enu_to_azel(enu, np.zeros_like(enu))
    return az, el


def hour_angle_rad(ra_rad: np.ndarray, t_us: np.ndarray, site: Site,
                   eop: EarthOrientation) -> np.ndarray:
    """Return the local apparent hour angle (rad, −π..π) of right ascensions of date."""
    t = UtcTimes.from_unix_us(np.atleast_1d(np.asarray(t_us, np.int64)))
    dut1, _xp, _yp = eop.interpolate(t.jd1, t.jd2, warn=False)
    ut1 = t.ut1(dut1)
    tt1, tt2 = t.tt()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        gst = erfa.gst06a(ut1[0], ut1[1], tt1, tt2)  # as local_sidereal_time_hours, vectorised
    ha = gst + site.lon_rad - np.asarray(ra_rad, float)
    return (ha + math.pi) % (2 * math.pi) - math.pi
