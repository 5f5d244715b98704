"""Shared fixtures: one site, the IERS table, and skyfield set up on the same IERS data."""

from __future__ import annotations

import pytest

from virtualstar.astro.earth_orientation import EarthOrientation
from virtualstar.astro.site import Site


@pytest.fixture(scope="session")
def site() -> Site:
    return Site(lat_deg=52.3967, lon_deg=16.8786, height_m=85.0, pressure_hpa=1005.0,
                temperature_c=10.0, humidity=0.6, wavelength_um=0.55, name="test")


@pytest.fixture(scope="session")
def eop() -> EarthOrientation:
    return EarthOrientation.from_astropy_iers_data()


@pytest.fixture(scope="session")
def skyfield_ts(eop):
    """A skyfield Timescale whose UT1 and polar motion come from the astropy-iers-data table."""
    from skyfield.data import iers as sf_iers
    from skyfield.timelib import Timescale

    daily_tt, daily_delta_t, leap_dates, leap_offsets = sf_iers.build_timescale_arrays(
        eop.mjd, eop.ut1_utc_s)
    ts = Timescale((daily_tt, daily_delta_t), leap_dates, leap_offsets)
    sf_iers.install_polar_motion_table(
        ts, {"utc_mjd": eop.mjd, "x_arcseconds": eop.xp_arcsec, "y_arcseconds": eop.yp_arcsec})
    return ts


@pytest.fixture(scope="session")
def de421():
    import warnings

    from skyfield.api import Loader
    from skyfield_data import get_skyfield_data_path

    warnings.filterwarnings("ignore", message="The file finals2000A.all has expired")

    return Loader(get_skyfield_data_path(), verbose=False)("de421.bsp")
