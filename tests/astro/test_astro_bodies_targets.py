"""Sun, Moon, planets against astropy on the same DE421; target names and RA/Dec parsing."""

from __future__ import annotations

import numpy as np
import pytest
from astro_testkit import ONE_MAS_RAD, sep_rad

from virtualstar.astro.bodies import SolarSystemBody
from virtualstar.astro.exceptions import CoordinateParseError, UnknownTarget
from virtualstar.astro.observed import enu_to_azel
from virtualstar.astro.satellites import Satellite
from virtualstar.astro.stars import IcrsStar
from virtualstar.astro.targets import (
    FixedAltAz,
    Target,
    observe_mount_times,
    parse_radec,
    resolve_target,
)
from virtualstar.astro.timescales import UtcTimes

NIGHT = UtcTimes.from_iso(["2024-03-15T18:00:00"])


@pytest.mark.filterwarnings("ignore:The file finals2000A.all has expired")
@pytest.mark.parametrize("name", ["moon", "sun", "mars", "jupiter"])
def test_bodies_match_astropy_with_de421_within_5_mas(name, site, eop):
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, get_body, solar_system_ephemeris
    from astropy.time import Time
    from skyfield_data import get_skyfield_data_path

    times = NIGHT.shifted(np.linspace(0, 14 * 3600, 5))
    obs = SolarSystemBody(name).observe(times, site.without_refraction(), eop)
    t = Time(times.jd1, times.jd2, format="jd", scale="utc")
    loc = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg,
                                      site.height_m * u.m)
    with solar_system_ephemeris.set(f"{get_skyfield_data_path()}/de421.bsp"):
        ref = get_body(name, t, loc).transform_to(AltAz(obstime=t, location=loc))
    err = sep_rad(ref.az.rad, ref.alt.rad, obs.az_rad, obs.el_rad)
    assert err.max() < 5 * ONE_MAS_RAD, err / ONE_MAS_RAD


def test_moon_spline_matches_exact_skyfield_within_0_01_mas(site, eop):
    moon = SolarSystemBody("Moon")
    times = NIGHT.shifted(np.linspace(0, 6 * 3600, 3000))
    enu, _ = moon.topocentric_enu(times, site, eop)
    pick = np.arange(0, 3000, 150)
    exact = moon.exact_enu(times[pick], site, eop)
    a1, e1, _, _ = enu_to_azel(enu[pick], enu[pick])
    a2, e2, _, _ = enu_to_azel(exact, exact)
    assert sep_rad(a1, e1, a2, e2).max() < 0.01 * ONE_MAS_RAD


@pytest.mark.parametrize(
    "text",
    ["05h34m31.94s +22d00m52.2s", "05:34:31.94 +22:00:52.2", "05 34 31.94 +22 00 52.2",
     "05h 34m 31.94s +22d 00m 52.2s", "83.633083 22.0145", "83.633083, 22.0145"],
)
def test_radec_forms_give_the_crab_nebula(text):
    ra, dec = parse_radec(text)
    assert ra == pytest.approx(83.633083, abs=1e-6) and dec == pytest.approx(22.0145, abs=1e-6)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [("25h00m00s +10d", "bad RA"), ("83.6 95", "bad Dec"), ("83.6", "cannot read"),
     ("12h30m", "cannot read"), ("1 2 3", "cannot read")],
)
def test_bad_radec_says_what_is_wrong_and_shows_the_forms(text, fragment):
    with pytest.raises(CoordinateParseError) as info:
        parse_radec(text)
    assert fragment in str(info.value) and "05h34m31.94s" in str(info.value)


def test_names_resolve_to_stars_bodies_or_coordinates():
    vega = resolve_target("vega")
    assert isinstance(vega, IcrsStar) and vega.parallax_mas > 100 and vega.epoch_jyear == 1991.25
    assert resolve_target("HIP 91262") == vega
    assert isinstance(resolve_target("Mars"), SolarSystemBody)
    assert isinstance(resolve_target("10.68 41.27"), IcrsStar)
    with pytest.raises(UnknownTarget, match="did you mean"):
        resolve_target("Vegaa")
    with pytest.raises(UnknownTarget, match="expected one of"):
        SolarSystemBody("vulcan")


def test_every_target_kind_answers_the_server_call(site, eop):
    from astro_satdata import load_test_satellites

    t_us = np.int64(1_716_000_000_000_000) + np.arange(0, 10_000_000, 1_000_000, dtype=np.int64)
    sat: Satellite = load_test_satellites()["ISS (ZARYA)"]
    for target in (resolve_target("Vega"), resolve_target("83.633 22.0145"),
                   SolarSystemBody("moon"), FixedAltAz(10.0, 45.0), sat):
        assert isinstance(target, Target)
        obs = observe_mount_times(target, t_us, site, eop)
        assert len(obs) == len(t_us) and np.isfinite(obs.az_rate_rad_s).all()
