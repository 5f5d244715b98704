"""From a topocentric direction in the local horizon frame to observed az/el and rates.

Every target type produces the unrefracted topocentric apparent direction as
unit vectors in the local (north, east, up) frame of the site plus their time
derivatives; this module turns them into azimuth (north through east),
elevation and their rates, and applies ERFA's refraction model.

Refraction depends on the geometric elevation only, so the exact ERFA model
(`erfa.refco` constants applied by `erfa.atioq`) is tabulated once per weather
on a fine elevation grid and interpolated with a cubic spline; the
interpolation error is measured in the tests (< 0.001 mas above 3° elevation, 0.01° knots).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import erfa
import numpy as np
from scipy.interpolate import CubicSpline

from .site import Site

# ERFA's refraction model freezes sin(el) at 0.05 below this elevation (atioq's
# SELMIN), which puts a kink in the refraction curve: the table is split there.
_EL_KINK_RAD = math.asin(0.05)
_EL_TABLE_MIN_RAD = math.radians(-10.0)
_TABLE_STEP_RAD = math.radians(0.01)


@dataclass(frozen=True)
class Observation:
    """Observed positions and rates for an array of times (radians, rad/s).

    az_rad: azimuth north through east in [0, 2π); el_rad: elevation (refracted
    when the site's refraction is on); rates are time derivatives per UTC second.
    """

    az_rad: np.ndarray
    el_rad: np.ndarray
    az_rate_rad_s: np.ndarray
    el_rate_rad_s: np.ndarray

    def __len__(self) -> int:
        return self.az_rad.shape[0]


def enu_to_azel(
    enu: np.ndarray, enu_rate: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Convert (N,3) north/east/up vectors and their rates to az, el, az rate, el rate.

    Vectors need not be unit length. Radians and rad/s; az in [0, 2π).
    """
    n, e, u = enu[:, 0], enu[:, 1], enu[:, 2]
    dn, de, du = enu_rate[:, 0], enu_rate[:, 1], enu_rate[:, 2]
    h2 = n * n + e * e
    h = np.sqrt(h2)
    r2 = h2 + u * u
    az = np.arctan2(e, n)
    az += np.where(az < 0.0, 2.0 * np.pi, 0.0)
    el = np.arctan2(u, h)
    az_rate = (n * de - e * dn) / h2
    el_rate = (du * h2 - u * (n * dn + e * de)) / (r2 * h)
    return az, el, az_rate, el_rate


def observe_enu(enu: np.ndarray, enu_rate: np.ndarray, site: Site) -> Observation:
    """Turn unrefracted (N,3) horizon-frame vectors and rates into an Observation.

    Applies refraction when the site's pressure is above zero.
    """
    az, el, az_rate, el_rate = enu_to_azel(enu, enu_rate)
    if site.refraction:
        table = refraction_table(site.pressure_hpa, site.temperature_c, site.humidity,
                                 site.wavelength_um)
        el, el_rate = table.apply(el, el_rate)
    return Observation(az, el, az_rate, el_rate)


def erfa_refracted_elevation(el_rad: np.ndarray, refa: float, refb: float) -> np.ndarray:
    """Return ERFA's observed (refracted) elevation for geometric elevations, radians.

    Runs `erfa.atioq` on a CIRS-to-observed context placed at the pole with no
    Earth rotation, polar motion or diurnal aberration, so that the only thing
    atioq does is its refraction step on the given elevation.
    """
    astrom = np.zeros((), dtype=erfa.dt_eraASTROM)
    astrom["sphi"] = 1.0
    astrom["refa"] = refa
    astrom["refb"] = refb
    _, zob, *_ = erfa.atioq(np.zeros_like(el_rad), el_rad, astrom)
    return np.pi / 2 - zob


@dataclass(frozen=True)
class RefractionTable:
    """Splines of refracted minus geometric elevation against geometric elevation."""

    low: CubicSpline
    high: CubicSpline

    def apply(self, el_rad: np.ndarray, el_rate_rad_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return refracted elevation and its rate for geometric elevation and rate."""
        el_c = np.clip(el_rad, _EL_TABLE_MIN_RAD, np.pi / 2)
        high = el_c >= _EL_KINK_RAD
        if high.all():
            delta = self.high(el_c)
            slope = self.high(el_c, 1)
        else:
            delta = np.where(high, self.high(el_c), self.low(el_c))
            slope = np.where(high, self.high(el_c, 1), self.low(el_c, 1))
        return el_rad + delta, el_rate_rad_s * (1.0 + slope)


@functools.lru_cache(maxsize=16)
def refraction_table(pressure_hpa: float, temperature_c: float, humidity: float,
                     wavelength_um: float) -> RefractionTable:
    """Tabulate ERFA's refraction (refco constants, atioq's formula) for one weather."""
    refa, refb = erfa.refco(pressure_hpa, temperature_c, humidity, wavelength_um)

    def spline(lo: float, hi: float) -> CubicSpline:
        n = max(8, int(math.ceil((hi - lo) / _TABLE_STEP_RAD)) + 1)
        el = np.linspace(lo, hi, n)
        return CubicSpline(el, erfa_refracted_elevation(el, refa, refb) - el)

    return RefractionTable(low=spline(_EL_TABLE_MIN_RAD, _EL_KINK_RAD),
                           high=spline(_EL_KINK_RAD, np.pi / 2))


def topocentric_apparent_radec(az_rad: np.ndarray, el_rad: np.ndarray, times, site: Site,
                               eop) -> tuple[np.ndarray, np.ndarray]:
    """Return topocentric apparent RA/Dec (true equator and equinox of date), radians.

    az_rad/el_rad: the *unrefracted* observed direction. The horizon vector is
    taken to the ITRS, then to the GCRS with ERFA's IAU 2006/2000A
    celestial-to-terrestrial matrix (UT1, polar motion from `eop`), then to
    the true equator and equinox of date.
    """
    dut1, xp, yp = eop.interpolate(times.jd1, times.jd2)
    tt1, tt2 = times.tt()
    ut11, ut12 = times.ut1(dut1)
    ce = np.cos(el_rad)
    enu = np.stack([ce * np.cos(az_rad), ce * np.sin(az_rad), np.sin(el_rad)], axis=-1)
    itrs = enu @ site.enu_matrix()  # rows: ENU → ITRS (transpose of the ITRS→ENU matrix)
    gcrs_to_itrs = erfa.c2t06a(tt1, tt2, ut11, ut12, xp, yp)
    gcrs_to_true = erfa.pnm06a(tt1, tt2)
    gcrs = np.einsum("nji,nj->ni", gcrs_to_itrs, itrs)
    true = np.einsum("nij,nj->ni", gcrs_to_true, gcrs)
    ra, dec = erfa.c2s(true)
    return erfa.anp(ra), dec
