"""J2000, JNow and sidereal time for the Alpaca and INDI façades, against astropy."""

from __future__ import annotations

import astropy.units as u
import pytest
from astropy.coordinates import FK5, TETE, SkyCoord
from astropy.time import Time

from virtualstar.astro import EarthOrientation, UtcTimes
from virtualstar.astro.equatorial import (
    icrs_to_j2000,
    icrs_to_jnow,
    j2000_to_icrs,
    jnow_to_icrs,
    local_sidereal_time_hours,
)

PLACES = [(250.0, 36.5), (0.5, -89.0), (101.287, -16.716), (359.9, 0.0), (83.63, 22.01)]
WHEN = ["2024-05-18T21:00:00Z", "2025-03-01T03:30:00Z"]


def _sep_arcsec(ra1, dec1, ra2, dec2) -> float:
    return SkyCoord(ra1 * u.deg, dec1 * u.deg).separation(
        SkyCoord(ra2 * u.deg, dec2 * u.deg)).arcsec


@pytest.mark.parametrize(("ra", "dec"), PLACES)
def test_j2000_is_astropys_fk5_at_equinox_j2000_and_comes_back(ra, dec):
    f = SkyCoord(ra * u.deg, dec * u.deg, frame="icrs").transform_to(FK5(equinox="J2000"))
    assert _sep_arcsec(*icrs_to_j2000(ra, dec), f.ra.deg, f.dec.deg) < 1e-4
    assert _sep_arcsec(*j2000_to_icrs(*icrs_to_j2000(ra, dec)), ra, dec) < 1e-6


@pytest.mark.parametrize("iso", WHEN)
@pytest.mark.parametrize(("ra", "dec"), PLACES)
def test_jnow_is_astropys_true_equator_and_equinox_of_date_and_comes_back(ra, dec, iso):
    t_us = int(UtcTimes.from_iso([iso]).to_unix_us()[0])
    te = SkyCoord(ra * u.deg, dec * u.deg, frame="icrs").transform_to(
        TETE(obstime=Time(t_us / 1e6, format="unix", scale="utc")))
    assert _sep_arcsec(*icrs_to_jnow(ra, dec, t_us), te.ra.deg, te.dec.deg) < 0.01
    assert _sep_arcsec(*jnow_to_icrs(*icrs_to_jnow(ra, dec, t_us), t_us), ra, dec) < 1e-4


@pytest.mark.parametrize("iso", WHEN)
@pytest.mark.parametrize("lon_deg", [16.88, -70.73, 0.0])
def test_local_sidereal_time_is_astropys_apparent_sidereal_time(iso, lon_deg):
    t_us = int(UtcTimes.from_iso([iso]).to_unix_us()[0])
    truth = Time(t_us / 1e6, format="unix", scale="utc").sidereal_time(
        "apparent", lon_deg * u.deg).hour
    lst = local_sidereal_time_hours(t_us, lon_deg, EarthOrientation.from_astropy_iers_data())
    assert abs((lst - truth + 12) % 24 - 12) * 3600 < 0.01  # seconds of time
