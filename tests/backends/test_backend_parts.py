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

