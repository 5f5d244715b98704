"""Site configuration, UTC time handling and IERS Earth orientation."""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np
import pytest
from astropy.time import Time
from astropy.utils import iers

from virtualstar.astro.exceptions import EarthOrientationWarning, SiteError, TimeParseError
from virtualstar.astro.site import Site, load_site, parse_site_option
from virtualstar.astro.timescales import UtcTimes

iers.conf.auto_download = False


def test_default_site_file_loads_with_documented_values():
    site = load_site()
    assert -90 <= site.lat_deg <= 90 and site.refraction


def test_site_file_from_environment_replaces_default(tmp_path, monkeypatch):
    path = tmp_path / "s.toml"
    path.write_text("[site]\nlat_deg = -24.6\nlon_deg = -70.4\nheight_m = 2635\npressure_hpa = 0\n")
    monkeypatch.setenv("VIRTUALSTAR_SITE", str(path))
    site = load_site()
    assert (site.lat_deg, site.lon_deg, site.height_m) == (-24.6, -70.4, 2635)
    assert not site.refraction


@pytest.mark.parametrize(
    ("text", "fragment"),
    [("[site]\nlat_deg = 95\nlon_deg = 0\n", "lat_deg=95"),
     ("[site]\nlat_deg = 5\nlon_deg = 0\nhumidty = 0.5\n", "unknown keys ['humidty']"),
     ("[place]\nlat_deg = 5\n", "expected a [site] table"),
     ("[site]\nlat_deg = 5\n", "misses ['lon_deg']"),
     ("[site\n", "not valid TOML")],
)
def test_bad_site_file_names_the_problem(tmp_path, text, fragment):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SiteError) as info:
        load_site(path)
    assert fragment in str(info.value) and str(path) in str(info.value)


def test_site_option_parses_and_rejects_bad_layouts():
    assert parse_site_option("52.4, 16.9, 85") == (52.4, 16.9, 85.0)
    for bad in ("52.4", "a,b,c", "1,2,3,4"):
        with pytest.raises(SiteError, match="LAT,LON,HEIGHT_M"):
            parse_site_option(bad)


def test_site_rejects_humidity_given_in_percent():
    with pytest.raises(SiteError, match="humidity"):
        Site(lat_deg=0, lon_deg=0, humidity=60)


def test_site_itrs_position_matches_astropy_earth_location():
    from astropy.coordinates import EarthLocation

    site = Site(lat_deg=52.3967, lon_deg=16.8786, height_m=85.0)
    loc = EarthLocation.from_geodetic(16.8786, 52.3967, 85.0)
    np.testing.assert_allclose(site.itrs_position_m(),
                               [loc.x.value, loc.y.value, loc.z.value], atol=1e-6)


def test_mount_time_round_trips_through_julian_dates():
    t_us = np.array([0, 1_700_000_000_123_456, 1_719_792_000_000_001], dtype=np.int64)
    assert np.array_equal(UtcTimes.from_unix_us(t_us).to_unix_us(), t_us)


def test_utc_tt_and_iso_agree_with_astropy():
    times = UtcTimes.from_iso(["2016-12-31T23:59:59.5Z", "2024-03-15 21:30:00.25"])
    ref = Time(["2016-12-31T23:59:59.5", "2024-03-15T21:30:00.25"], scale="utc")
    tt1, tt2 = times.tt()
    np.testing.assert_allclose(((tt1 - ref.tt.jd1) + (tt2 - ref.tt.jd2)) * 86400, 0, atol=1e-9)
    assert times.iso() == ["2016-12-31T23:59:59.500Z", "2024-03-15T21:30:00.250Z"]


@pytest.mark.parametrize("bad", ["2024-13-01T00:00:00", "yesterday", "2024-03-15T25:00"])
def test_bad_utc_string_shows_expected_layout(bad):
    with pytest.raises(TimeParseError, match="ISO 8601"):
        UtcTimes.from_iso([bad])


def test_ut1_and_polar_motion_match_astropy_lookups(eop):
    ref = Time(np.linspace(60000.0, 60800.0, 57), format="mjd", scale="utc")
    dut1, xp, yp = eop.interpolate(ref.jd1, ref.jd2)
    np.testing.assert_allclose(dut1, ref.delta_ut1_utc, atol=1e-12)
    table = iers.earth_orientation_table.get()
    ax, ay = table.pm_xy(ref)
    np.testing.assert_allclose(xp, ax.to_value("rad"), atol=1e-18)
    np.testing.assert_allclose(yp, ay.to_value("rad"), atol=1e-18)


def test_ut1_interpolation_bridges_a_leap_second(eop):
    before = UtcTimes.from_iso(["2016-12-31T12:00:00"])
    after = UtcTimes.from_iso(["2017-01-01T12:00:00"])
    d0 = eop.interpolate(before.jd1, before.jd2)[0][0]
    d1 = eop.interpolate(after.jd1, after.jd2)[0][0]
    assert d1 - d0 == pytest.approx(1.0, abs=0.01)


def test_predicted_and_missing_earth_orientation_warn(eop):
    eop = dataclasses.replace(eop)  # a table of its own: each table warns once per kind
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        eop.interpolate(np.array([2460400.5]), np.array([0.25]))  # measured: silent
    jd = 2400000.5 + eop.measured_until_mjd + 30
    with pytest.warns(EarthOrientationWarning, match="predicted"):
        eop.interpolate(np.array([jd]), np.array([0.0]))
    with pytest.warns(EarthOrientationWarning, match="outside the IERS table"):
        eop.interpolate(np.array([2400000.5 + eop.mjd[-1] + 400]), np.array([0.0]))


def test_a_table_warns_once_per_kind_however_often_it_is_asked(eop):
    eop = dataclasses.replace(eop)
    predicted = np.array([2400000.5 + eop.measured_until_mjd + 30])
    beyond = np.array([2400000.5 + eop.mjd[-1] + 400])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(5):
            eop.interpolate(predicted, np.zeros(1))
            eop.interpolate(beyond, np.zeros(1))
    kinds = [str(w.message).split(":")[0] for w in caught
             if issubclass(w.category, EarthOrientationWarning)]
    assert len(kinds) == 2 and len(set(kinds)) == 2


def test_the_iers_table_is_cached_as_arrays_and_read_back_without_astropy(tmp_path,
                                                                         monkeypatch):
    import subprocess
    import sys

    from virtualstar.astro import earth_orientation as eo

    monkeypatch.setenv(eo.CACHE_ENV_VAR, str(tmp_path))
    truth = eo._read_astropy_table()  # astropy's own reading of astropy-iers-data
    path = eo.eop_cache_path()
    assert path is not None and path.parent == tmp_path
    eo._write_cache(path, truth)
    again = eo._read_cache(path)
    for name in ("mjd", "ut1_utc_s", "xp_arcsec", "yp_arcsec"):
        assert np.array_equal(getattr(again, name), getattr(truth, name))
    assert again.measured_until_mjd == truth.measured_until_mjd
    # a later process takes the table from the cache and never imports astropy
    code = ("import sys\nfrom virtualstar.astro import EarthOrientation\n"
            "e = EarthOrientation.from_astropy_iers_data()\n"
            "print(len(e.mjd), any(m.startswith('astropy.') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, eo.CACHE_ENV_VAR: str(tmp_path)}, timeout=120)
    assert out.stdout.split() == [str(len(truth.mjd)), "False"], out.stderr
    # an empty cache is filled by a child process: this one never imports astropy either
    fresh = tmp_path / "fresh"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, eo.CACHE_ENV_VAR: str(fresh)}, timeout=300)
    assert out.stdout.split() == [str(len(truth.mjd)), "False"], out.stderr
    assert (fresh / path.name).is_file()
    # a damaged cache is read around: astropy's table again
    path.write_bytes(b"not an npz")
    assert eo._read_cache(path) is None
