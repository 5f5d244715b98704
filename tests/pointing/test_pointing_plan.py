"""plan: stars spread evenly over the visible sky, at the places astropy computes; CSV RA/Dec."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

# Imported at collection: a later-collected tests/catalogs folder on sys.path must not shadow it.
from catalogs import bright_stars
from pointing_model import even_sky_positions, pick_spread
from pointing_model.cli import app

runner = CliRunner()
SITE_TOML = """[site]
name = "test site"
lat_deg = -30.2446
lon_deg = -70.7494
height_m = 2663.0
pressure_hpa = 743.0
temperature_c = 8.0
humidity = 0.3
wavelength_um = 0.55
"""
# A date with final IERS values: astropy (the reference) refuses predictions once its table is
# more than 30 days old by the wall clock, which would make these tests fail as time passes.
AT = "2024-11-22T03:00:00Z"
ASTROPY_AGREEMENT_ARCSEC = 0.05  # both are ERFA underneath; EOP interpolation differs


def _astropy_altaz(ra_deg, dec_deg, utc, stars=None):
    """Observed az/el by astropy; with `stars`, their proper motion and parallax too."""
    from astropy import units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    site = EarthLocation.from_geodetic(-70.7494 * u.deg, -30.2446 * u.deg, 2663.0 * u.m)
    frame = AltAz(obstime=Time(utc.rstrip("Z"), scale="utc"), location=site,
                  pressure=743.0 * u.hPa, temperature=8.0 * u.deg_C, relative_humidity=0.3,
                  obswl=0.55 * u.micron)
    if stars is None:
        coord = SkyCoord(ra=ra_deg * u.deg, dec=dec_deg * u.deg)
    else:
        coord = SkyCoord(
            ra=ra_deg * u.deg, dec=dec_deg * u.deg,
            pm_ra_cosdec=[s.pm_ra_cosdec_mas_yr for s in stars] * u.mas / u.yr,
            pm_dec=[s.pm_dec_mas_yr for s in stars] * u.mas / u.yr,
            distance=[1000.0 / max(s.parallax_mas, 1e-3) for s in stars] * u.pc,
            radial_velocity=[s.rv_km_s for s in stars] * u.km / u.s,
            obstime=Time(stars[0].epoch_jyear, format="jyear", scale="tt"))
        coord = coord.apply_space_motion(new_obstime=Time(utc.rstrip("Z"), scale="utc"))
    altaz = coord.transform_to(frame)
    return altaz.az.deg, altaz.alt.deg


def _sky_sep_arcsec(az1, el1, az2, el2):
    d_az = (np.asarray(az1) - az2 + 180.0) % 360.0 - 180.0
    return np.hypot(d_az * np.cos(np.radians(el2)), np.asarray(el1) - el2) * 3600.0


def test_plan_picks_visible_stars_at_the_places_astropy_computes(tmp_path):
    site = tmp_path / "site.toml"
    site.write_text(SITE_TOML)
    out = runner.invoke(app, ["plan", "--stars", "12", "--at", AT, "--site-file", str(site),
                              "--min-el", "25", "--json"])
    assert out.exit_code == 0, out.output
    plan = json.loads(out.stdout)
    assert len(plan) == 12 and len({p["name"] for p in plan}) == 12
    el = np.array([p["el_deg"] for p in plan])
    assert np.all((el >= 25.0) & (el <= 85.0))
    stars = [bright_stars().by_hip(p["hip"]) for p in plan]
    az_ref, el_ref = _astropy_altaz(np.array([s.ra_deg for s in stars]),
                                    np.array([s.dec_deg for s in stars]), AT, stars)
    sep = _sky_sep_arcsec([p["az_deg"] for p in plan], el, az_ref, el_ref)
    assert np.max(sep) < ASTROPY_AGREEMENT_ARCSEC


def test_pick_spread_leaves_no_two_chosen_stars_crowded():
    rng = np.random.default_rng(0)
    # 2000 random candidates uniform over the sky, as a catalogue would be
    cand_az = rng.uniform(0, 360, 2000)
    cand_el = np.degrees(np.arcsin(rng.uniform(-1, 1, 2000)))
    n = 30
    chosen = pick_spread(cand_az, cand_el, n, min_el_deg=20, max_el_deg=85)
    assert len(set(chosen.tolist())) == n
    az, el = np.radians(cand_az[chosen]), np.radians(cand_el[chosen])
    v = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    sep = np.degrees(np.arccos(np.clip(v @ v.T, -1, 1)))
    np.fill_diagonal(sep, 360.0)
    zone_sr = 2 * np.pi * (np.sin(np.radians(85)) - np.sin(np.radians(20)))
    ideal_deg = np.degrees(np.sqrt(zone_sr / n))  # side of one star's share of the zone
    assert sep.min(axis=1).min() > 0.4 * ideal_deg


def test_even_sky_positions_cover_equal_areas():
    az, el = even_sky_positions(1000, min_el_deg=20, max_el_deg=85)
    # equal areas: sin(el) uniform, azimuths uniform
    counts, _ = np.histogram(np.sin(np.radians(el)), bins=10)
    assert counts.min() >= 95 and counts.max() <= 105
    counts, _ = np.histogram(az, bins=12, range=(0, 360))
    assert counts.min() >= 75 and counts.max() <= 92


def test_plan_refuses_more_stars_than_are_visible(tmp_path):
    site = tmp_path / "site.toml"
    site.write_text(SITE_TOML)
    out = runner.invoke(app, ["plan", "--stars", "2000", "--at", AT, "--site-file", str(site)])
    assert out.exit_code == 2 and "were asked for" in out.output


def test_plan_refuses_a_bad_time():
    out = runner.invoke(app, ["plan", "--stars", "3", "--at", "2026-13-40"])
    assert out.exit_code == 2 and "2026-13-40" in out.output


def test_fit_of_a_csv_with_radec_rows_uses_the_observed_place(tmp_path):
    ia, ie = -120.0, 45.0
    ra = np.array([10.0, 60.0, 95.0, 120.0, 20.0, 30.0, 80.0, 110.0])
    dec = np.array([-20.0, -45.0, -10.0, -60.0, -50.0, -75.0, 5.0, -35.0])
    utcs = [f"2024-11-22T03:{m:02d}:00Z" for m in range(0, 40, 5)]
    az, el = zip(*(_astropy_altaz(r, d, t) for r, d, t in zip(ra, dec, utcs, strict=True)),
                 strict=True)
    az, el = np.array(az), np.array(el)
    assert np.all(el > 15)
    # IA: ΔA = −IA → encoder azimuth = observed + IA; IE: ΔE = +IE → encoder = observed − IE
    enc_az, enc_el = az + ia / 3600.0, el - ie / 3600.0
    lines = ["utc,ra_deg,dec_deg,enc_az_deg,enc_el_deg"] + [
        f"{t},{r},{d},{a:.9f},{e:.9f}" for t, r, d, a, e in zip(utcs, ra, dec, enc_az, enc_el,
                                                                strict=True)]
    site = tmp_path / "site.toml"
    site.write_text(SITE_TOML)
    path = tmp_path / "run.csv"
    path.write_text("\n".join(lines) + "\n")
    out = runner.invoke(app, ["fit", str(path), "--terms", "IA,IE", "--site-file", str(site),
                              "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    assert doc["terms"]["IA"]["value_arcsec"] == pytest.approx(ia, abs=ASTROPY_AGREEMENT_ARCSEC)
    assert doc["terms"]["IE"]["value_arcsec"] == pytest.approx(ie, abs=ASTROPY_AGREEMENT_ARCSEC)
    assert doc["sky_rms_arcsec"] < ASTROPY_AGREEMENT_ARCSEC
