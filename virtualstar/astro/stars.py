"""Stars and fixed ICRS directions: catalog astrometry to observed az/el for arrays of times.

The expensive astrometry (ERFA `apco13`: precession-nutation, Earth position
and velocity, Earth rotation, polar motion) runs on a coarse time grid; there
`atciq` (space motion, parallax, light deflection, aberration) and `atioq`
(CIRS to topocentric horizon, diurnal effects, no refraction) give the exact
direction. A cubic spline of the north/east/up unit vector on that grid then
serves every requested time with its analytic derivative; the spline error is
measured in the tests against per-point `erfa.atco13` (≤ 0.01 mas on a 60 s
grid). The grid is absolute and its nodes are cached (node_grid.py): a track
sampled chunk by chunk computes each node once. Refraction is applied afterwards per point (see observed.py), because
interpolating the refracted direction would be far less accurate near the
horizon, where refraction curves strongly.
"""

from __future__ import annotations

import math
import threading
import warnings
from dataclasses import dataclass
from typing import Any

import erfa
import numpy as np
from scipy.interpolate import CubicSpline

from .constants import HIPPARCOS_EPOCH_JYEAR, J2000_JD, MAS_PER_RAD
from .earth_orientation import EarthOrientation
from .node_grid import spline_or_exact
from .observed import Observation, observe_enu
from .site import Site
from .timescales import UtcTimes

#: Spacing of the exact-astrometry grid, seconds (60 s keeps the spline error < 1 µas).
DEFAULT_GRID_STEP_S = 60.0
_DAYS_PER_JULIAN_YEAR = 365.25


@dataclass(frozen=True)
class IcrsStar:
    """A star (or any distant ICRS direction) with optional space motion.

    ra_deg/dec_deg: ICRS at epoch_jyear (Julian year, TT); pm in mas/yr with
    the RA component multiplied by cos(dec); parallax in mas; rv in km/s.
    """

    ra_deg: float
    dec_deg: float
    pm_ra_cosdec_mas_yr: float = 0.0
    pm_dec_mas_yr: float = 0.0
    parallax_mas: float = 0.0
    rv_km_s: float = 0.0
    epoch_jyear: float = 2000.0
    name: str = ""

    @classmethod
    def from_catalog(cls, star: Any) -> IcrsStar:
        """Build from a catalog record (the `catalogs.Star` fields; missing values → 0)."""

        def num(field: str, default: float = 0.0) -> float:
            value = getattr(star, field, None)
            return default if value is None or not math.isfinite(float(value)) else float(value)

        return cls(
            ra_deg=float(star.ra_deg),
            dec_deg=float(star.dec_deg),
            pm_ra_cosdec_mas_yr=num("pm_ra_cosdec_mas_yr"),
            pm_dec_mas_yr=num("pm_dec_mas_yr"),
            parallax_mas=num("parallax_mas"),
            rv_km_s=num("rv_km_s"),
            epoch_jyear=num("epoch_jyear", HIPPARCOS_EPOCH_JYEAR),
            name=str(getattr(star, "name", "") or ""),
        )

    @property
    def has_space_motion(self) -> bool:
        return any((self.pm_ra_cosdec_mas_yr, self.pm_dec_mas_yr, self.parallax_mas,
                    self.rv_km_s))

    def observe(self, times: UtcTimes, site: Site, eop: EarthOrientation | None = None,
                *, grid_step_s: float = DEFAULT_GRID_STEP_S) -> Observation:
        """Return observed az/el and rates at `times` (refraction per the site)."""
        enu, rate = self.topocentric_enu(times, site, eop, grid_step_s=grid_step_s)
        return observe_enu(enu, rate, site)

    def topocentric_enu(self, times: UtcTimes, site: Site, eop: EarthOrientation | None = None,
                        *, grid_step_s: float = DEFAULT_GRID_STEP_S
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Return unrefracted (N,3) north/east/up unit vectors and their rates (1/s)."""
        eop = eop or EarthOrientation.from_astropy_iers_data()
        return spline_or_exact(lambda t: exact_enu(self, t, site, eop), times, grid_step_s,
                               key=("star", self, site.lat_deg, site.lon_deg, site.height_m, eop))


def exact_enu(star: IcrsStar, times: UtcTimes, site: Site, eop: EarthOrientation) -> np.ndarray:
    """Return exact unrefracted north/east/up unit vectors, (N,3), per point with ERFA.

    apco13 (astrometry context, no refraction) + atciq (ICRS→CIRS with space
    motion, parallax, deflection, aberration) + atioq (CIRS→horizon).
    """
    astrom = _astrometry_context(times, site, eop)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        ra, dec, px_arcsec = _star_at_dates(star, times)
        ri, di = erfa.atciq(ra, dec, 0.0, 0.0, px_arcsec, 0.0, astrom)
    aob, zob, *_ = erfa.atioq(ri, di, astrom)
    sz = np.sin(zob)
    return np.stack([sz * np.cos(aob), sz * np.sin(aob), np.cos(zob)], axis=-1)


def observe_stars(stars: list[IcrsStar], times: UtcTimes, site: Site, eop: EarthOrientation,
                  *, grid_step_s: float = 600.0) -> tuple[np.ndarray, np.ndarray]:
    """Return observed azimuth and elevation (rad, shape (n_stars, n_times)) of many stars.

    For a night's plan: ERFA (apco13 once, then atciq + atioq for every star at once)
    every `grid_step_s`, one cubic spline through all the stars' unit vectors, refraction
    per the site. A star's direction is smooth: 600-s nodes give milliarcseconds.
    """
    s = times.si_seconds_since(float(times.jd1[0]), float(times.jd2[0]))
    k1 = math.ceil(float(s.max()) / grid_step_s) + 2
    s_nodes = np.arange(-2, k1 + 1) * grid_step_s
    nodes = times[0].si_shifted(s_nodes)
    astrom = _astrometry_context(nodes, site, eop)
    ra, dec, px = _stars_at_dates(stars, nodes)  # (n_stars, n_nodes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        ri, di = erfa.atciq(ra, dec, 0.0, 0.0, px, 0.0, astrom)
    aob, zob, *_ = erfa.atioq(ri, di, astrom)
    sz = np.sin(zob)
    enu = np.stack([sz * np.cos(aob), sz * np.sin(aob), np.cos(zob)], axis=-1)  # (n, k, 3)
    n = len(stars)
    spline = CubicSpline(s_nodes, enu.transpose(1, 0, 2).reshape(len(s_nodes), n * 3), axis=0)
    at = spline(s).reshape(len(s), n, 3).transpose(1, 0, 2).reshape(-1, 3)
    obs = observe_enu(at, np.zeros_like(at), site)
    return obs.az_rad.reshape(n, len(s)), obs.el_rad.reshape(n, len(s))


_ASTROM_CACHE: dict[tuple, tuple[EarthOrientation, Any]] = {}
_ASTROM_CACHE_SIZE = 4
_ASTROM_LOCK = threading.Lock()


def _astrometry_context(times: UtcTimes, site: Site, eop: EarthOrientation) -> Any:
    """Return ERFA's star-independent context (apco13) for these times and site.

    It is the costly part of observing a star (~46 ms for 600 times) and the same for
    every star: many stars on one time grid (a night's plan) reuse it.
    """
    key = (np.asarray(times.jd1).tobytes(), np.asarray(times.jd2).tobytes(), site, id(eop))
    with _ASTROM_LOCK:  # the server plans in a thread beside its own trajectories
        hit = _ASTROM_CACHE.get(key)
    if hit is not None and hit[0] is eop:
        return hit[1]
    dut1, xp, yp = eop.interpolate(times.jd1, times.jd2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year" for future dates
        astrom, _ = erfa.apco13(times.jd1, times.jd2, dut1, site.lon_rad, site.lat_rad,
                                site.height_m, xp, yp, 0.0, 0.0, 0.0, 0.0)
    with _ASTROM_LOCK:
        while len(_ASTROM_CACHE) >= _ASTROM_CACHE_SIZE:
            _ASTROM_CACHE.pop(next(iter(_ASTROM_CACHE)))
        _ASTROM_CACHE[key] = (eop, astrom)
    return astrom


def _star_at_dates(star: IcrsStar, times: UtcTimes) -> tuple[Any, Any, Any]:
    """Return ICRS RA, Dec (rad) and parallax (arcsec) moved to the epoch of each time."""
    if not star.has_space_motion:
        return math.radians(star.ra_deg), math.radians(star.dec_deg), 0.0
    ra, dec, px = _stars_at_dates([star], times)
    return ra[0], dec[0], px[0]


def _stars_at_dates(stars: list[IcrsStar], times: UtcTimes
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ICRS RA, Dec (rad) and parallax (arcsec) of each star moved to the epoch of
    each time, each (n_stars, n_times); a star without a parallax keeps none."""
    col = np.newaxis
    ra = np.radians([st.ra_deg for st in stars])[:, col]
    dec = np.radians([st.dec_deg for st in stars])[:, col]
    px = np.array([st.parallax_mas / 1000.0 for st in stars])[:, col]
    pmr = np.array([st.pm_ra_cosdec_mas_yr for st in stars])[:, col] / MAS_PER_RAD / np.cos(dec)
    pmd = np.array([st.pm_dec_mas_yr for st in stars])[:, col] / MAS_PER_RAD
    rv = np.array([st.rv_km_s or 0.0 for st in stars])[:, col]
    ep1 = J2000_JD + (np.array([st.epoch_jyear for st in stars])[:, col] - 2000.0) \
        * _DAYS_PER_JULIAN_YEAR
    tt1, tt2 = times.tt()  # TT stands in for TDB: 1.7 ms is nothing for space motion
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)  # px = 0: ERFA assumes a distance
        ra2, dec2, _, _, px2, _ = erfa.pmsafe(ra, dec, pmr, pmd, px, rv, ep1, 0.0, tt1, tt2)
    return ra2, dec2, np.where(px > 0, px2, 0.0)
