"""The parts of the Alpaca/INDI backends that need no simulator: frames, URLs, capability choices."""

from __future__ import annotations

import math
import sys
from datetime import UTC, datetime
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from synthetic_pass import synthetic_pass_tle  # noqa: E402

from virtualstar.astro import EarthOrientation, Satellite, load_site, observe_mount_times  # noqa: E402
from virtualstar.astro.mount_frames import (  # noqa: E402
    apparent_radec_to_observed,
    hour_angle_rad,
    observed_to_apparent_radec,
)
from virtualstar.server.backends.alpaca import parse_alpaca_url  # noqa: E402
from virtualstar.server.backends.indi import parse_indi_url  # noqa: E402
from virtualstar.server.exceptions import BadRequest, Unsupported  # noqa: E402
from virtualstar.server.link_interface import MountCapabilities  # noqa: E402

ONE_MAS = 1e-3  # arcsec


def test_the_place_of_date_of_a_satellite_is_skyfields_apparent_place():
    from skyfield.api import EarthSatellite, wgs84

    from virtualstar.astro.bodies import skyfield_context

    site = load_site()
    eop = EarthOrientation.from_astropy_iers_data()
    t0 = 1_716_061_000.0  # 2024-05-18, inside the IERS table
    name, l1, l2 = synthetic_pass_tle(site.lat_deg, site.lon_deg, site.height_m, t0)
    t = t0 + np.array([-120.0, -30.0, 0.0, 45.0, 150.0])
    t_us = (t * 1e6).astype(np.int64)
    o = observe_mount_times(Satellite.from_tle(l1, l2, name), t_us, site, eop)
    ra, dec = observed_to_apparent_radec(o.az_rad, o.el_rad, t_us, site, eop)
    sf = skyfield_context(eop)
    earth = sf.ephemeris["earth"]
    here = earth + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    ts = sf.ts.from_datetimes([datetime.fromtimestamp(x, tz=UTC) for x in t])
    sra, sdec, _ = here.at(ts).observe(earth + EarthSatellite(l1, l2, name, sf.ts)) \
        .apparent().radec(epoch="date")
    d_ra = ((np.degrees(ra) - sra.hours * 15 + 180) % 360 - 180) * np.cos(dec) * 3600
    d_dec = (np.degrees(dec) - sdec.degrees) * 3600
    assert np.all(np.hypot(d_ra, d_dec) < 20 * ONE_MAS), np.hypot(d_ra, d_dec)


def test_observed_and_apparent_places_convert_both_ways():
    site = load_site()
    eop = EarthOrientation.from_astropy_iers_data()
    t_us = np.full(5, 1_716_061_000_000_000, np.int64)
    az = np.radians([10.0, 100.0, 190.0, 280.0, 359.0])
    el = np.radians([5.0, 20.0, 45.0, 70.0, 89.0])
    ra, dec = observed_to_apparent_radec(az, el, t_us, site, eop)
    az2, el2 = apparent_radec_to_observed(ra, dec, t_us, site, eop)
    d = np.hypot(((az2 - az + math.pi) % (2 * math.pi) - math.pi) * np.cos(el), el2 - el)
    assert np.all(np.degrees(d) * 3600 < ONE_MAS)
    # the hour angle of a place due south (northern site) is zero, to the polar motion and
    # diurnal aberration that separate the true equator from the site's meridian (0.1″)
    ra_s, _ = observed_to_apparent_radec(np.radians([180.0]), np.radians([30.0]), t_us[:1],
                                         site, eop)
    ha_arcsec = math.degrees(float(hour_angle_rad(ra_s, t_us[:1], site, eop)[0])) * 3600
    assert abs(ha_arcsec) < 0.5


def test_mount_urls_name_the_driver_and_bad_ones_say_what_is_expected():
    assert parse_alpaca_url("alpaca://127.0.0.1:11111/0") == ("127.0.0.1", 11111, 0)
    assert parse_alpaca_url("alpaca://mount/2") == ("mount", 11111, 2)
    assert parse_indi_url("indi://host:7624/Telescope%20Simulator") == (
        "host", 7624, "Telescope Simulator")
    for bad in ("alpaca://:11111/0", "alpaca://h:11111/x", "indi://host:7624/", "http://h/0"):
        with pytest.raises(BadRequest, match="expected"):
            (parse_indi_url if bad.startswith("indi") else parse_alpaca_url)(bad)
    from virtualstar.server.backends.alpaca import geometry_override

    assert geometry_override("alpaca://h:1/0?geometry=german") == "german"
    with pytest.raises(BadRequest, match="altaz, german or fork"):
        geometry_override("alpaca://h:1/0?geometry=dobson")


def test_a_goto_only_mount_is_refused_a_track_with_a_clear_code():
    from virtualstar.server import rate_procedures

    station = SimpleNamespace(link=SimpleNamespace(capabilities=MountCapabilities(
        backend="alpaca", geometry="german", rate_axes=False)))
    with pytest.raises(Unsupported) as err:
        rate_procedures.require_rates(station)
    assert err.value.code == "unsupported" and "only takes gotos" in str(err.value)


def test_capabilities_name_the_native_axes_of_each_geometry():
    assert MountCapabilities(backend="indi", geometry="german").native_axes == ("ra", "dec")
    assert MountCapabilities(backend="alpaca", geometry="altaz").native_axes == ("az", "el")
    with pytest.raises(ValueError, match="altaz, german, fork"):
        MountCapabilities(backend="x", geometry="dobson")


def test_vs_server_refuses_signals_for_an_astcom_mount():
    from typer.testing import CliRunner

    from virtualstar.cli.main import app

    out = CliRunner().invoke(app, ["server", "--mount", "ws://127.0.0.1:1", "--signals",
                                   "ws://127.0.0.1:0"])
    assert out.exit_code == 2 and "alpaca:// or indi://" in out.output



def _plan_pass(tmp_path, geometry: str):
    """`vs plan` of a program whose one target is an ISS-like pass culminating 70° high, ~45°
    of azimuth off the meridian (it crosses the meridian some 20° from culmination)."""
    from typer.testing import CliRunner

    from virtualstar.cli.main import app

    culm_s = 1_790_000_000.0
    name, l1, l2 = synthetic_pass_tle(-30.0, 0.0, 1500.0, culm_s)
    (tmp_path / "pass.tle").write_text(f"{name}\n{l1}\n{l2}\n")
    (tmp_path / "site.toml").write_text("[site]\nlat_deg = -30.0\nlon_deg = 0.0\n"
                                        "height_m = 1500.0\n")
    (tmp_path / "program.toml").write_text(
        '[program]\nname = "flip"\n\n[defaults]\nmin_el_deg = 20\nsun_max_el_deg = 90\n'
        'moon_min_sep_deg = 0\n\n[[target]]\ntle_file = "pass.tle"\nsat = "ISS-LIKE"\n')
    iso = [datetime.fromtimestamp(culm_s + d, tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
           for d in (-900, 900)]
    out = CliRunner().invoke(app, [
        "plan", str(tmp_path / "program.toml"), "--from", iso[0], "--to", iso[1], "--site-file",
        str(tmp_path / "site.toml"), "--mount-geometry", geometry, "--json"])
    assert out.exit_code == 0, out.output
    import json

    blocks = json.loads(out.output)["blocks"]
    assert len(blocks) == 1, blocks
    return blocks[0], (name, l1, l2)


def _hour_angles_deg(tle, t_s: np.ndarray) -> np.ndarray:
    """skyfield's hour angle of date of the satellite at the site (-30°, 0°, 1500 m), degrees."""
    from skyfield.api import EarthSatellite, wgs84

    from virtualstar.astro.bodies import skyfield_context

    sf = skyfield_context(EarthOrientation.from_astropy_iers_data())
    sat = EarthSatellite(tle[1], tle[2], tle[0], sf.ts)
    here = sf.ephemeris["earth"] + wgs84.latlon(-30.0, 0.0, 1500.0)
    ts = sf.ts.from_datetimes([datetime.fromtimestamp(float(x), tz=UTC) for x in t_s])
    ra, _dec, _ = here.at(ts).observe(sf.ephemeris["earth"] + sat).apparent().radec(epoch="date")
    return ((ts.gast * 15.0 + 0.0 - ra.hours * 15.0) + 180.0) % 360.0 - 180.0


def test_vs_plan_cuts_a_pass_to_one_side_of_the_meridian_for_a_german_mount(tmp_path):
    """A German mount would flip in the middle of a pass that crosses the meridian: `vs plan
    --mount-geometry german` plans only its longest stretch on one side (skyfield's hour
    angle keeps its sign all through the block), an alt-az plan keeps the whole pass."""
    whole, tle = _plan_pass(tmp_path, "altaz")
    german, _ = _plan_pass(tmp_path, "german")
    t_whole = np.linspace(whole["start_us"], whole["end_us"], 200) / 1e6
    ha_whole = _hour_angles_deg(tle, t_whole)
    assert ha_whole.min() < 0 < ha_whole.max(), "the test pass must cross the meridian"
    t = np.linspace(german["start_us"], german["end_us"], 200) / 1e6
    ha = _hour_angles_deg(tle, t)
    assert np.all(ha > -0.05) or np.all(ha < 0.05), np.round(ha, 2)  # one side (a 1-s step)
    assert german["end_us"] - german["start_us"] < whole["end_us"] - whole["start_us"]
    assert german["end_us"] - german["start_us"] >= 30e6  # the longer side is kept
    assert german["constraints"].get("meridian_cut") and "meridian_cut" not in whole["constraints"]
