"""Radial velocities of the bundled bright stars and the BSC5 cross-match that finds them."""

from __future__ import annotations

import csv
import functools
import importlib.util
import io
import math
import sys
from importlib import resources
from pathlib import Path

import astropy.units as u
import numpy as np
import pytest
from astropy.coordinates import SkyCoord
from astropy.time import Time

from catalogs import bright_stars

ONE_MAS_DEG = 1.0 / 3_600_000.0
ARCSEC_DEG = 1.0 / 3600.0

BUILDER_PATH = Path(__file__).resolve().parents[2] / "tools" / "build_bright_stars.py"

# Yale Bright Star Catalogue, 5th rev. ed., Hoffleit & Warren 1991 (CDS V/50), RadVel in km/s:
# HR 7001 Vega, HR 5340 Arcturus, HR 1457 Aldebaran, HR 2491 Sirius, HR 1708 Capella,
# HR 2061 Betelgeuse, HR 8728 Fomalhaut.
BSC5_RADVEL_KM_S = {91262: -14, 69673: -5, 21421: 54, 32349: -8, 24608: 30, 27989: 21,
                    113368: 7}
# Later, independent measurements (value, 1-sigma), km/s:
MODERN_RV_KM_S = {
    69673: (-5.19, 0.04),   # Arcturus, Pulkovo compilation, Gontcharov 2006, AstL 32, 759
    21421: (54.26, 0.03),   # Aldebaran, Gontcharov 2006 (CDS III/252)
    91262: (-13.9, 0.9),    # Vega, Evans 1967, IAU Symp. 30 (the value quoted in issue 4)
    27989: (21.91, 0.51),   # Betelgeuse, Famaey et al. 2005, A&A 430, 165
}
# BSC5 quotes whole km/s from measurements of the 1950s-80s, good to a few km/s.
BSC5_RV_TOLERANCE_KM_S = 3.0
MIN_FRACTION_WITH_RV = 0.95


@functools.cache
def _builder():
    """Import tools/build_bright_stars.py (tools/ is not a package)."""
    spec = importlib.util.spec_from_file_location("build_bright_stars", BUILDER_PATH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while being built
    spec.loader.exec_module(module)
    return module


def _rv_table() -> list[dict]:
    text = resources.files("catalogs").joinpath("data", "bright_star_rv.csv").read_text("utf-8")
    body = "".join(line for line in text.splitlines(keepends=True) if not line.startswith("#"))
    return list(csv.DictReader(io.StringIO(body)))


@pytest.mark.parametrize("hip", sorted(BSC5_RADVEL_KM_S))
def test_radial_velocity_equals_the_published_bsc5_value(hip):
    star = bright_stars().by_hip(hip)
    assert star.rv_known
    assert star.rv_km_s == BSC5_RADVEL_KM_S[hip]


@pytest.mark.parametrize("hip", sorted(MODERN_RV_KM_S))
def test_radial_velocity_agrees_with_a_later_independent_measurement(hip):
    value, sigma = MODERN_RV_KM_S[hip]
    star = bright_stars().by_hip(hip)
    assert abs(star.rv_km_s - value) <= BSC5_RV_TOLERANCE_KM_S + 3.0 * sigma


def test_more_than_95_percent_of_bundled_stars_have_a_radial_velocity():
    stars = list(bright_stars())
    with_rv = [s for s in stars if s.rv_known]
    assert len(with_rv) / len(stars) > MIN_FRACTION_WITH_RV
    assert all(s.rv_km_s == 0.0 for s in stars if not s.rv_known)


def test_rv_table_has_one_accepted_match_per_star_and_the_catalog_uses_its_values():
    cat = bright_stars()
    table = _rv_table()
    assert sorted(int(r["hip"]) for r in table) == sorted(s.hip for s in cat)
    matched = [r for r in table if r["hr"]]
    assert len({r["hr"] for r in matched}) == len(matched)  # no BSC5 entry used twice
    for r in table:
        star = cat.by_hip(int(r["hip"]))
        if not r["rv_km_s"]:
            assert not star.rv_known and star.rv_km_s == 0.0
            continue
        assert star.rv_known and star.rv_km_s == float(r["rv_km_s"])
        sep, dv = float(r["sep_arcsec"]), abs(float(r["dv_mag"]))
        assert (sep <= 30.0 and dv <= 0.3) or (sep <= 5.0 and dv <= 1.5), r


def test_alpha_centauri_components_get_their_own_bsc5_entries():
    rows = {int(r["hip"]): r for r in _rv_table()}
    assert rows[71683]["hr"] == "5459"  # Rigil Kentaurus = alf1 Cen = alf Cen A
    assert rows[71681]["hr"] == "5460"  # Toliman = alf2 Cen = alf Cen B


def test_carry_to_j2000_agrees_with_astropy_space_motion_within_a_mas():
    build = _builder()
    # Barnard's-star-like motion, a nearly stationary star, and one near the pole.
    ra = np.array([269.45, 10.0, 37.95])
    dec = np.array([4.69, -30.0, 89.26])
    pmra = np.array([-801.5, 1.0, 44.0])
    pmdec = np.array([10362.5, -2.0, -11.7])
    plx = np.array([548.3, 2.0, 7.5])
    ra2, dec2 = build.carry_to_j2000(ra, dec, pmra, pmdec, plx)
    start = SkyCoord(ra=ra * u.deg, dec=dec * u.deg, pm_ra_cosdec=pmra * u.mas / u.yr,
                     pm_dec=pmdec * u.mas / u.yr, distance=(1000.0 / plx) * u.pc,
                     radial_velocity=np.zeros(3) * u.km / u.s,
                     obstime=Time(1991.25, format="jyear", scale="tt"))
    ref = start.apply_space_motion(new_obstime=Time(2000.0, format="jyear", scale="tt"))
    sep = SkyCoord(ra2 * u.deg, dec2 * u.deg).separation(SkyCoord(ref.ra, ref.dec))
    assert np.all(sep.deg < ONE_MAS_DEG)


def _bsc(build, hr, ra_deg, dec_deg, vmag, rv=0):
    return build.Bsc5Star(hr=hr, name="", ra_deg=ra_deg, dec_deg=dec_deg, vmag=vmag,
                          rv_km_s=rv, rv_note="")


def test_cross_match_gives_each_component_of_a_pair_the_entry_of_its_magnitude():
    build = _builder()
    # Like alf Cen: each star lies nearer to the other's catalogue entry.
    bsc = [_bsc(build, 1, 0.0, 0.0, -0.01, -22), _bsc(build, 2, 8.0 * ARCSEC_DEG, 0.0, 1.33, -21)]
    ra = np.array([7.0, 1.0]) * ARCSEC_DEG
    matches = build.match_bsc5(ra, np.zeros(2), np.array([-0.01, 1.35]), bsc)
    assert [m.index for m in matches] == [0, 1]
    assert matches[0].sep_arcsec == pytest.approx(7.0, abs=1e-6)


def test_cross_match_accepts_combined_light_only_for_a_close_pair():
    build = _builder()
    bsc = [_bsc(build, 1, 0.0, 0.0, 2.0), _bsc(build, 2, 1.0, 0.0, 2.0)]
    # Hipparcos V = 1.2 for both: combined light 0.8 mag brighter than the BSC5 component.
    ra = np.array([3.0 * ARCSEC_DEG, 1.0 + 20.0 * ARCSEC_DEG])
    matches = build.match_bsc5(ra, np.zeros(2), np.array([1.2, 1.2]), bsc)
    assert matches[0] is not None and matches[0].index == 0
    assert matches[0].dv_mag == pytest.approx(-0.8)
    assert matches[1] is None  # 20 arcsec away: the magnitude must agree to 0.3 mag


def test_cross_match_leaves_a_star_with_no_entry_within_30_arcsec_unmatched():
    build = _builder()
    bsc = [_bsc(build, 1, 0.0, 0.0, 3.0)]
    matches = build.match_bsc5(np.array([31.0 * ARCSEC_DEG]), np.zeros(1), np.array([3.0]), bsc)
    assert matches == [None]


def _catalog_line(fields: dict[tuple[int, int], str]) -> str:
    """Place text at 1-based inclusive byte ranges, as the CDS V/50 ReadMe describes them."""
    line = [" "] * 197
    for (first, last), text in fields.items():
        assert len(text) == last - first + 1
        line[first - 1:last] = text
    return "".join(line).rstrip()


def test_bsc5_parser_reads_position_magnitude_and_radial_velocity():
    build = _builder()
    star = _catalog_line({(1, 4): "7001", (5, 14): " 3Alp Lyr ", (76, 77): "18",
                          (78, 79): "36", (80, 83): "56.3", (84, 84): "+", (85, 86): "38",
                          (87, 88): "47", (89, 90): "01", (103, 107): " 0.03",
                          (167, 170): "-014", (171, 174): "V   "})
    no_rv = _catalog_line({(1, 4): "   2", (76, 77): "00", (78, 79): "05", (80, 83): "03.8",
                           (84, 84): "-", (85, 86): "00", (87, 88): "30", (89, 90): "11",
                           (103, 107): " 6.29"})
    nova = _catalog_line({(1, 4): "  92", (5, 14): "NOVA 1572 "})
    vega, second = build.parse_bsc5("\n".join([star, nova, no_rv]))
    assert (vega.hr, vega.name, vega.rv_km_s, vega.rv_note) == (7001, "3Alp Lyr", -14, "V")
    assert vega.ra_deg == pytest.approx(15.0 * (18 + 36 / 60 + 56.3 / 3600), abs=1e-12)
    assert vega.dec_deg == pytest.approx(38 + 47 / 60 + 1 / 3600, abs=1e-12)
    assert vega.vmag == 0.03
    assert second.hr == 2 and second.rv_km_s is None
    assert second.dec_deg == pytest.approx(-(30 / 60 + 11 / 3600), abs=1e-12)
    assert math.isclose(second.vmag, 6.29)


def test_bsc5_parser_names_the_line_it_cannot_read():
    build = _builder()
    bad = _catalog_line({(1, 4): "  12", (76, 77): "0x", (78, 79): "05", (80, 83): "03.8",
                         (84, 84): "+", (85, 86): "00", (87, 88): "30", (89, 90): "11",
                         (103, 107): " 6.29"})
    with pytest.raises(ValueError, match="line 1"):
        build.parse_bsc5(bad)
