"""Sun, Moon and planets from the JPL DE421 ephemeris bundled in skyfield-data.

skyfield computes the topocentric apparent place (light time, deflection,
aberration, precession-nutation) on a coarse time grid; Earth orientation
(UT1-UTC, polar motion) is installed into skyfield from *our* astropy-iers-data
table, never from skyfield-data's finals2000A.all (it ends in 2025 and is
0.2 s off in UT1 afterwards). As for stars, a cubic spline of the unrefracted
horizon-frame unit vector serves every requested time and its rates.
"""

from __future__ import annotations

import atexit
import functools
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .earth_orientation import EarthOrientation
from .exceptions import UnknownTarget
from .node_grid import spline_or_exact
from .observed import Observation, observe_enu
from .site import Site
from .stars import DEFAULT_GRID_STEP_S
from .timescales import UtcTimes

#: Names accepted for solar-system bodies → DE421 segment names.
BODY_SEGMENTS = {
    "sun": "sun",
    "moon": "moon",
    "mercury": "mercury",
    "venus": "venus",
    "mars": "mars",
    "jupiter": "jupiter barycenter",
    "saturn": "saturn barycenter",
    "uranus": "uranus barycenter",
    "neptune": "neptune barycenter",
    "pluto": "pluto barycenter",
}


@dataclass(frozen=True)
class SkyfieldContext:
    """A skyfield Timescale on our IERS table plus the DE421 ephemeris."""

    ts: Any
    ephemeris: Any


@functools.lru_cache(maxsize=4)
def skyfield_context(eop: EarthOrientation) -> SkyfieldContext:
    """Return skyfield set up offline: DE421 from skyfield-data, UT1/polar motion from `eop`."""
    from skyfield.api import Loader
    from skyfield.data import iers as sf_iers
    from skyfield.timelib import Timescale
    from skyfield_data import get_skyfield_data_path

    daily_tt, daily_delta_t, leap_dates, leap_offsets = sf_iers.build_timescale_arrays(
        eop.mjd, eop.ut1_utc_s)
    ts = Timescale((daily_tt, daily_delta_t), leap_dates, leap_offsets)
    sf_iers.install_polar_motion_table(
        ts, {"utc_mjd": eop.mjd, "x_arcseconds": eop.xp_arcsec, "y_arcseconds": eop.yp_arcsec})
    with warnings.catch_warnings():
        # skyfield-data warns that *its* finals2000A.all expired: we do not use it.
        warnings.filterwarnings("ignore", message="The file finals2000A.all has expired")
        ephemeris = Loader(get_skyfield_data_path(), verbose=False)("de421.bsp")
    atexit.register(ephemeris.close)  # the kernel keeps its file open while cached
    return SkyfieldContext(ts, ephemeris)


#: The Sun below this (civil twilight's end): the sky is dark enough to see a satellite.
DARK_SUN_EL_DEG = -6.0


def satellite_sunlit(satrec: Any, times: UtcTimes, eop: EarthOrientation) -> np.ndarray:
    """Whether a satellite (its sgp4 `Satrec`) is out of the Earth's shadow at `times`
    (skyfield's `is_sunlit`, DE421's Sun)."""
    from skyfield.api import EarthSatellite

    ctx = skyfield_context(eop)
    sat = EarthSatellite.from_satrec(satrec, ctx.ts)
    return np.asarray(sat.at(ctx.ts.tt_jd(*times.tt())).is_sunlit(ctx.ephemeris), bool)


@dataclass(frozen=True)
class SolarSystemBody:
    """The Sun, the Moon or a planet (by name, case-insensitive)."""

    name: str

    def __post_init__(self) -> None:
        if self.name.lower() not in BODY_SEGMENTS:
            raise UnknownTarget(f"unknown solar-system body {self.name!r}; "
                                f"expected one of {', '.join(BODY_SEGMENTS)}")

    def topocentric_enu(self, times: UtcTimes, site: Site, eop: EarthOrientation | None = None,
                        *, grid_step_s: float = DEFAULT_GRID_STEP_S
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Return unrefracted (N,3) north/east/up unit vectors and their rates (1/s)."""
        eop = eop or EarthOrientation.from_astropy_iers_data()
        return spline_or_exact(lambda t: self.exact_enu(t, site, eop), times, grid_step_s,
                               key=("body", self, site.lat_deg, site.lon_deg, site.height_m, eop))

    def observe(self, times: UtcTimes, site: Site, eop: EarthOrientation | None = None,
                *, grid_step_s: float = DEFAULT_GRID_STEP_S) -> Observation:
        """Return observed az/el and rates at `times` (refraction per the site)."""
        enu, rate = self.topocentric_enu(times, site, eop, grid_step_s=grid_step_s)
        return observe_enu(enu, rate, site)

    def exact_enu(self, times: UtcTimes, site: Site, eop: EarthOrientation) -> np.ndarray:
        """Return skyfield's topocentric apparent direction per point as (N,3) ENU vectors."""
        from skyfield.api import wgs84

        ctx = skyfield_context(eop)
        eop.interpolate(times.jd1, times.jd2)  # only to warn about predicted/missing IERS
        t = ctx.ts.tt_jd(*times.tt())
        observer = ctx.ephemeris["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg,
                                                         site.height_m)
        target = ctx.ephemeris[BODY_SEGMENTS[self.name.lower()]]
        alt, az, _ = observer.at(t).observe(target).apparent().altaz()
        ca = np.cos(alt.radians)
        return np.stack([ca * np.cos(az.radians), ca * np.sin(az.radians),
                         np.sin(alt.radians)], axis=-1)
