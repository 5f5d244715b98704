"""Shared fixtures: one site, the IERS table, and skyfield set up on the same IERS data."""

from __future__ import annotations

import pytest

from virtualstar.astro.bodies import skyfield_context
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
    return skyfield_context(eop).ts


@pytest.fixture(scope="session")
def de421(eop):
    """DE421 from skyfield-data, loaded offline."""
    return skyfield_context(eop).ephemeris
