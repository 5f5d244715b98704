"""`vs where` and `vs passes` through Typer's CliRunner."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from astro_satdata import TLE_PATH, load_test_satellites
from typer.testing import CliRunner

from virtualstar.astro import UtcTimes, resolve_target, satellite_passes
from virtualstar.astro.site import Site
from virtualstar.cli.main import app

runner = CliRunner()
SITE_ARGS = ["--site", "52.4,16.9,85", "--pressure-hpa", "1000", "--temperature-c", "5",
             "--humidity", "0.5"]
SITE = Site(lat_deg=52.4, lon_deg=16.9, height_m=85, pressure_hpa=1000, temperature_c=5,
            humidity=0.5)
JSON_FIELDS = {"utc", "az_deg", "el_deg", "ra_deg", "dec_deg", "az_rate_deg_s", "el_rate_deg_s"}


def _run(*args: str):
    return runner.invoke(app, list(args))


def test_where_star_json_has_one_object_per_time_with_the_library_values(eop):
    at = ["2024-05-18T21:00:00Z", "2024-05-18T23:30:00Z"]
    result = _run("where", "Vega", "--at", at[0], "--at", at[1], *SITE_ARGS, "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    assert len(rows) == 2 and all(set(r) >= JSON_FIELDS for r in rows)
    obs = resolve_target("Vega").observe(UtcTimes.from_iso(at), SITE, eop)
    np.testing.assert_allclose([r["az_deg"] for r in rows], np.degrees(obs.az_rad), atol=1e-9)
    np.testing.assert_allclose([r["el_deg"] for r in rows], np.degrees(obs.el_rad), atol=1e-9)
    np.testing.assert_allclose([r["el_rate_deg_s"] for r in rows],
                               np.degrees(obs.el_rate_rad_s), atol=1e-12)
    assert rows[0]["culmination_utc"].startswith("2024-05-19T01:")  # Vega transits ~01:41


def test_where_no_refraction_lowers_the_elevation():
    args = ["where", "83.633 22.0145", "--at", "2024-01-10T20:00:00", *SITE_ARGS, "--json"]
    wet = json.loads(_run(*args).stdout)[0]
    dry = json.loads(_run(*args, "--no-refraction").stdout)[0]
    assert wet["el_deg"] - dry["el_deg"] == pytest.approx(0.01, abs=0.01)
    assert wet["az_deg"] == pytest.approx(dry["az_deg"], abs=1e-9)
    assert wet["ra_deg"] == pytest.approx(dry["ra_deg"], abs=1e-9)


def test_where_planet_prints_a_table_with_events():
    result = _run("where", "moon", "--at", "2024-03-15T20:00:00", *SITE_ARGS)
    assert result.exit_code == 0, result.output
    assert "moon" in result.stdout and "az_deg" in result.stdout and "rise" in result.stdout


def test_where_satellite_from_a_tle_file():
    result = _run("where", "--tle", str(TLE_PATH), "--sat", "CSS (TIANHE)", "--at",
                  "2024-05-18T19:55:00", *SITE_ARGS, "--json")
    assert result.exit_code == 0, result.output
    row = json.loads(result.stdout)[0]
    assert row["target"] == "CSS (TIANHE)" and set(row) >= JSON_FIELDS
    assert row["rise_utc"] is not None


def test_passes_json_lists_the_library_passes(eop):
    result = _run("passes", "--tle", str(TLE_PATH), "--from", "2024-05-18T00:00:00",
                  "--to", "2024-05-19T00:00:00", "--min-el", "10", *SITE_ARGS, "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    ref = satellite_passes(load_test_satellites()["ISS (ZARYA)"], SITE,
                           UtcTimes.from_iso(["2024-05-18"]), UtcTimes.from_iso(["2024-05-19"]),
                           min_el_deg=10, eop=eop)
    assert [r["culmination_el_deg"] for r in rows] == [round(p.culmination.el_deg, 3)
                                                       for p in ref]
    assert all(r["culmination_el_deg"] >= 10 for r in rows) and len(rows) >= 2
    assert not math.isnan(rows[0]["rise_az_deg"])


def test_a_pass_already_up_at_the_search_start_is_judged_from_that_start(tmp_path):
    """The part of a cut pass inside the window counts whole: above a flat 5° profile it is
    from the window's first second, not from its culmination."""
    whole = _run("passes", "--tle", str(TLE_PATH), "--from", "2024-05-18T00:00:00",
                 "--to", "2024-05-19T00:00:00", "--min-el", "10", *SITE_ARGS, "--json")
    p = json.loads(whole.stdout)[0]
    culm = UtcTimes.from_iso([p["culmination_utc"]]).to_unix_us()[0]
    start_us = (int(UtcTimes.from_iso([p["rise_utc"]]).to_unix_us()[0]) + int(culm)) // 2
    start = UtcTimes.from_unix_us(np.array([start_us // 1_000_000 * 1_000_000])).iso(0)[0]
    profile = tmp_path / "flat.txt"
    profile.write_text("0 5\n180 5\n")
    cut = _run("passes", "--tle", str(TLE_PATH), "--from", start, "--to",
               "2024-05-19T00:00:00", "--min-el", "10", "--horizon", str(profile), *SITE_ARGS,
               "--json")
    assert cut.exit_code == 0, cut.output
    row = json.loads(cut.stdout)[0]
    assert row["rise_utc"] is None and row["culmination_utc"] == p["culmination_utc"]
    first_us = UtcTimes.from_iso([row["above_horizon_from_utc"]]).to_unix_us()[0]
    assert first_us == start_us // 1_000_000 * 1_000_000  # the window's first second
    assert row["above_horizon_to_utc"] is not None


@pytest.mark.parametrize(
    ("args", "fragment"),
    [(["where", "Vegaa"], "did you mean: Vega"),
     (["where", "25h00m00s +10d"], "bad RA"),
     (["where"], "give a TARGET"),
     (["where", "Vega", "--at", "yesterday"], "ISO 8601"),
     (["where", "Vega", "--site", "95,0,0"], "lat_deg"),
     (["where", "Vega", "--site", "52;16"], "LAT,LON,HEIGHT_M"),
     (["where", "Vega", "--humidity", "60"], "humidity"),
     (["where", "--tle", "/nonexistent.tle"], "/nonexistent.tle: no such file"),
     (["where", "--tle", "/dev/zero"], "/dev/zero is a character device, not a regular file"),
     (["where", "--tle", str(TLE_PATH), "--sat", "Hubble"], "Hubble"),
     (["passes", "--tle", str(TLE_PATH), "--from", "2024-05-18", "--to", "2024-05-17"],
      "not after"),
     (["passes", "--tle", str(TLE_PATH), "--from", "2024-05-18", "--to", "2024-05-19",
       "--min-el", "95"], "--min-el")],
)
def test_bad_arguments_fail_with_a_clear_message(args, fragment):
    result = _run(*args)
    assert result.exit_code != 0
    assert fragment in result.stderr


def test_help_texts_tell_what_to_type():
    assert "05h34m31.94s" in _run("where", "--help").stdout
    assert "--min-el" in _run("passes", "--help").stdout


def test_where_warns_on_stale_elements_and_still_answers():
    result = _run("where", "--tle", str(TLE_PATH), "--at", "2024-07-01T00:00:00", *SITE_ARGS,
                  "--json")
    assert result.exit_code == 0, result.output
    assert "warning:" in result.stderr and "TLE epoch" in result.stderr
    row = json.loads(result.stdout)[0]
    assert row["target"] == "ISS (ZARYA)" and 300 < row["range_km"] < 15000


def test_where_beyond_the_iers_table_says_what_it_costs_stars_without_raw_erfa_lines():
    import subprocess
    import sys

    # a fresh process: the table's warnings are said once per process
    done = subprocess.run(
        [sys.executable, "-c", "from virtualstar.cli.main import main; main()",
         "where", "Vega", "--at", "2030-06-01T22:00:00Z", *SITE_ARGS],
        capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "ERFA" not in done.stderr and "dubious year" not in done.stderr, done.stderr
    warnings = [ln for ln in done.stderr.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 1, done.stderr
    assert "outside the IERS table" in warnings[0] and "stars" in warnings[0]
    assert "2030-06-01T22:00:00" in done.stdout


def test_passes_flag_the_sunlit_passes_seen_from_a_dark_site_as_a_shadow_cylinder_says():
    """A second implementation of 'visible': the ISS outside the Earth's cylindrical shadow
    (sgp4 TEME positions, astropy's Sun) while the Sun is 6° below the site's horizon."""
    import json

    import astropy.units as u
    import numpy as np
    from astropy.coordinates import AltAz, EarthLocation, get_body
    from astropy.time import Time
    from sgp4.api import Satrec
    from typer.testing import CliRunner

    from catalogs import load_tle_file, sample_tle_path
    from virtualstar.cli.main import app

    res = CliRunner().invoke(app, ["passes", "--tle", str(sample_tle_path("stations")), "--sat",
                                   "ISS", "--from", "2024-05-18T12:00:00Z", "--to",
                                   "2024-05-19T06:00:00Z", "--min-el", "10", "--json"])
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)
    rec = next(r for r in load_tle_file(sample_tle_path("stations")) if "ISS" in r.name)
    sat = Satrec.twoline2rv(rec.line1, rec.line2)
    site = EarthLocation.from_geodetic(16.8786 * u.deg, 52.3967 * u.deg, 85 * u.m)
    for row in rows:
        # every second from rise to set, as the flag is defined (sunlit and dark at once)
        t0 = Time(row["rise_utc"].rstrip("Z"), scale="utc")
        span_s = (Time(row["set_utc"].rstrip("Z"), scale="utc") - t0).sec
        t = t0 + np.arange(0.0, span_s, 1.0) * u.s
        _, r_km, _ = sat.sgp4_array(t.jd1, t.jd2)  # TEME, close enough to GCRS for a shadow
        sun = get_body("sun", t)
        s_xyz = sun.cartesian.xyz.to(u.km).value.T
        s_hat = s_xyz / np.linalg.norm(s_xyz, axis=1)[:, None]
        along = np.sum(r_km * s_hat, axis=1)
        off_axis = np.linalg.norm(r_km - along[:, None] * s_hat, axis=1)
        lit = (along > 0) | (off_axis > 6378.137)
        dark = sun.transform_to(AltAz(obstime=t, location=site)).alt.deg < -6.0
        k = int(np.argmin(np.abs((t - Time(row["culmination_utc"].rstrip("Z"),
                                            scale="utc")).sec)))
        assert row["observer_in_darkness"] == bool(dark[k]), row
        assert row["sunlit"] == bool(lit.any()), row
        assert row["visible"] == bool((lit & dark).any()), row
    assert any(r["visible"] for r in rows) and any(not r["visible"] for r in rows)
