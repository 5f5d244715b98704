"""The bundled bright-star catalog: size, sanity of every row, spot values against publications."""

from __future__ import annotations

import math

import erfa
import pytest
from skyfield.named_stars import named_star_dict

from catalogs import HIPPARCOS_EPOCH_JYEAR, bright_stars

ONE_MAS_DEG = 1.0 / 3_600_000.0
V_LIMIT = 4.0

# van Leeuwen 2007, "Validation of the new Hipparcos reduction", A&A 474, 653; CDS I/311
# hip2.dat rows (RA/Dec in radians at J1991.25, plx and pm in mas, mas/yr).
HIP2_PUBLISHED = {
    91262: (4.8735545728, 0.6768909262, 130.23, 200.94, 286.23),  # Vega
    32349: (1.7678185359, -0.2916993748, 379.21, -546.01, -1223.07),  # Sirius
}
# Hipparcos Catalogue (ESA 1997, SP-1200) field H5, Johnson V.
HIP1997_VMAG = {91262: 0.03, 32349: -1.44, 30438: -0.62, 69673: -0.05}
# SIMBAD's ICRS position of Vega at epoch J2000 (quoted in issue 4), degrees.
VEGA_J2000_SIMBAD_DEG = (279.23473479, 38.78368896)

# Names whose Hipparcos-list (skyfield) HIP differs from the IAU WGSN assignment we keep:
# the IAU gave "Algenib" to gam Peg (not alf Per), "Gienah" to gam Crv (not eps Cyg),
# "Markab" to alf Peg (not kap Vel) and "Toliman" to alf Cen B (not A).
IAU_OVERRIDES = {"Algenib": 1067, "Gienah": 59803, "Markab": 113963, "Toliman": 71681}


def test_bundled_catalog_holds_at_least_300_stars_all_brighter_than_v4():
    stars = list(bright_stars())
    assert len(stars) >= 300
    assert all(s.vmag is not None and s.vmag <= V_LIMIT for s in stars)


def test_bundled_catalog_holds_most_stars_of_the_hipparcos_common_name_list():
    cat = bright_stars()
    hips = {s.hip for s in cat}
    bright_named = {h for h in named_star_dict.values() if h in hips}
    assert len(bright_named) >= 80


def test_bundled_rows_are_unique_and_within_physical_ranges():
    stars = list(bright_stars())
    assert len({s.hip for s in stars}) == len(stars)
    names = [s.name for s in stars if s.name]
    assert len(set(names)) == len(names)
    for s in stars:
        assert 0.0 <= s.ra_deg < 360.0 and -90.0 <= s.dec_deg <= 90.0, s
        assert 0.0 < s.parallax_mas < 800.0, s  # Rigil Kentaurus has 755 mas
        assert math.hypot(s.pm_ra_cosdec_mas_yr, s.pm_dec_mas_yr) < 4000.0, s
        assert -1.5 < s.vmag <= V_LIMIT, s
        assert s.epoch_jyear == HIPPARCOS_EPOCH_JYEAR
        assert s.rv_known or s.rv_km_s == 0.0, s
        assert abs(s.rv_km_s) < 150.0, s  # the fastest V <= 4 star in BSC5 recedes at 99 km/s
        assert s.bayer or s.flamsteed or s.hip


@pytest.mark.parametrize("hip", sorted(HIP2_PUBLISHED))
def test_astrometry_equals_the_published_hipparcos_2007_row(hip):
    ra_rad, dec_rad, plx, pmra, pmdec = HIP2_PUBLISHED[hip]
    star = bright_stars().by_hip(hip)
    assert abs(star.ra_deg - math.degrees(ra_rad)) < ONE_MAS_DEG
    assert abs(star.dec_deg - math.degrees(dec_rad)) < ONE_MAS_DEG
    assert (star.parallax_mas, star.pm_ra_cosdec_mas_yr, star.pm_dec_mas_yr) == (plx, pmra, pmdec)


@pytest.mark.parametrize("hip", sorted(HIP1997_VMAG))
def test_v_magnitude_equals_the_hipparcos_1997_value(hip):
    assert bright_stars().by_hip(hip).vmag == HIP1997_VMAG[hip]


def test_vega_propagated_to_j2000_agrees_with_simbad_within_5_mas():
    vega = bright_stars().lookup("Vega")
    ra, dec = math.radians(vega.ra_deg), math.radians(vega.dec_deg)
    mas = math.radians(ONE_MAS_DEG)
    pmr = vega.pm_ra_cosdec_mas_yr * mas / math.cos(dec)  # erfa wants dRA/dt
    pmd = vega.pm_dec_mas_yr * mas
    jd1991 = erfa.epj2jd(vega.epoch_jyear)
    jd2000 = erfa.epj2jd(2000.0)
    ra2, dec2, *_ = erfa.pmsafe(ra, dec, pmr, pmd, vega.parallax_mas / 1000.0, 0.0,
                                *jd1991, *jd2000)
    d_ra_mas = (math.degrees(ra2) - VEGA_J2000_SIMBAD_DEG[0]) * math.cos(dec2) / ONE_MAS_DEG
    d_dec_mas = (math.degrees(dec2) - VEGA_J2000_SIMBAD_DEG[1]) / ONE_MAS_DEG
    assert math.hypot(d_ra_mas, d_dec_mas) < 5.0


def test_common_names_point_to_the_same_hip_as_skyfield():
    cat = bright_stars()
    hips = {s.hip for s in cat}
    checked = 0
    for name, hip in named_star_dict.items():
        if hip not in hips:
            continue
        assert cat.lookup(name).hip == IAU_OVERRIDES.get(name, hip), name
        checked += 1
    assert checked >= 80


def test_catalog_is_loaded_once_and_shared():
    assert bright_stars() is bright_stars()
