"""A track sampled chunk by chunk on the absolute, cached node grid: against per-point ERFA
(atco13, one call from ICRS to observed) and astropy, through a leap second too."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from astro_testkit import ONE_MAS_RAD, atco13_azel, sep_rad

from virtualstar.astro import SolarSystemBody, enu_to_azel
from virtualstar.astro.node_grid import NODE_CACHE
from virtualstar.astro.stars import IcrsStar
from virtualstar.astro.timescales import UtcTimes

# Hipparcos-epoch astrometry (ESA 1997); 61 Cyg A moves fast and is close
VEGA = IcrsStar(279.23410832, 38.78299311, 201.02, 287.46, 128.93, -13.5, 1991.25, "Vega")
CYG61 = IcrsStar(316.72474640, 38.74941558, 4107.40, 3143.72, 287.18, -65.7, 1991.25, "61 Cyg A")
POINT_STEP_US = 50_000  # the feeder's 20 Hz grid
CHUNK_S = 5.0  # the feeder's lead


def _us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


def _chunks(start_us: int, seconds: float, rng) -> list[np.ndarray]:
    """Mount times as a track asks for them: 5-s chunks of the 20 Hz grid from random
    starts, and single instants between (a correction's, the closed loop's)."""
    out = []
    for first in np.sort(rng.integers(start_us, start_us + int(seconds * 1e6), 40)):
        n = int(CHUNK_S * 1e6) // POINT_STEP_US
        out.append(first + np.arange(n, dtype=np.int64) * POINT_STEP_US)
        out.append(np.array([first + rng.integers(0, 10_000_000)], np.int64))
    return out


def _track(star, chunks, site, eop):
    obs = [star.observe(UtcTimes.from_unix_us(t), site, eop) for t in chunks]
    return (np.concatenate([o.az_rad for o in obs]), np.concatenate([o.el_rad for o in obs]),
            np.concatenate([o.az_rate_rad_s for o in obs]),
            np.concatenate([o.el_rate_rad_s for o in obs]))


@pytest.mark.parametrize("star", [VEGA, CYG61], ids=lambda s: s.name)
def test_a_track_sampled_chunk_by_chunk_matches_per_point_atco13_within_0_01_mas(site, eop,
                                                                                 star):
    rng = np.random.default_rng(26)
    chunks = _chunks(_us("2024-03-15T19:30:00Z"), 6 * 3600.0, rng)
    az, el, _, _ = _track(star, chunks, site, eop)
    t = np.concatenate(chunks)
    ref_az, ref_el = atco13_azel(star, UtcTimes.from_unix_us(t), site, eop, site.pressure_hpa)
    up = ref_el > np.radians(3.0)  # ERFA's refraction model is frozen below ~2.9°
    assert up.sum() > len(t) // 3
    err = sep_rad(ref_az[up], ref_el[up], az[up], el[up])
    assert err.max() < 0.01 * ONE_MAS_RAD, err.max() / ONE_MAS_RAD


def test_single_instants_have_the_rates_of_per_point_atco13(site, eop):
    geo = site.without_refraction()
    rng = np.random.default_rng(3)
    t = _us("2024-03-15T22:00:00Z") + np.sort(rng.integers(0, 3 * 3600_000_000, 12))
    h_us = 500_000
    for one in t:
        obs = VEGA.observe(UtcTimes.from_unix_us(np.array([one])), geo, eop)
        around = UtcTimes.from_unix_us(np.array([one - h_us, one, one + h_us]))
        ref_az, ref_el = atco13_azel(VEGA, around, geo, eop, 0.0)
        assert sep_rad(ref_az[1], ref_el[1], obs.az_rad[0], obs.el_rad[0]) < 0.01 * ONE_MAS_RAD
        d_az = (np.unwrap(ref_az)[2] - np.unwrap(ref_az)[0]) / (2 * h_us / 1e6)
        d_el = (ref_el[2] - ref_el[0]) / (2 * h_us / 1e6)
        # a central difference over ±0.5 s is itself good to ~1e-12 rad/s here
        assert abs(obs.az_rate_rad_s[0] - d_az) < 1e-10
        assert abs(obs.el_rate_rad_s[0] - d_el) < 1e-10


def test_cached_nodes_give_exactly_what_fresh_ones_give(site, eop):
    rng = np.random.default_rng(5)
    chunks = _chunks(_us("2024-06-01T21:00:00Z"), 3600.0, rng)
    first = _track(VEGA, chunks, site, eop)
    again = _track(VEGA, chunks, site, eop)  # every node from the cache now
    NODE_CACHE.clear()
    fresh = [_track(VEGA, [c], site, eop) for c in reversed(chunks)][::-1]  # other batches
    fresh = tuple(np.concatenate(parts) for parts in zip(*fresh, strict=True))
    for a, b, c in zip(first, again, fresh, strict=True):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_a_track_computes_each_node_once(site, eop):
    # a star of its own: nodes no other test has cached
    star = dataclasses.replace(VEGA, name="Vega, counted")
    start = _us("2024-06-02T21:00:00Z")
    before = NODE_CACHE.computed
    for k in range(720):  # an hour in the feeder's 5-s chunks
        t = start + k * 5_000_000 + np.arange(100, dtype=np.int64) * POINT_STEP_US
        star.observe(UtcTimes.from_unix_us(t), site, eop)
    # 60 one-minute nodes in the hour, and the two the spline keeps beyond each end
    assert NODE_CACHE.computed - before <= 60 + 2 * 3 + 2 * 8  # whole blocks of 8 at the ends


def test_chunks_through_the_leap_second_match_atco13_and_astropy(site, eop):
    from astropy import units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    geo = site.without_refraction()
    # mount time is POSIX: 23:59:60.x reads as 00:00:00.x of the next day; the instants
    # around the leap second as UtcTimes (ERFA's quasi-JD), whose 23:59:60 exists
    stamps = [f"2016-12-31T23:59:{s:02d}.{d}Z" for s in range(50, 61) for d in range(0, 10, 2)]
    stamps += [f"2017-01-01T00:00:0{s}.{d}Z" for s in range(10) for d in range(0, 10, 2)]
    times = UtcTimes.from_iso(stamps)
    for lo in range(0, len(stamps), 17):  # chunks that straddle the leap second
        part = times[lo:lo + 17]
        obs = CYG61.observe(part, geo, eop)
        ref_az, ref_el = atco13_azel(CYG61, part, geo, eop, 0.0)
        assert sep_rad(ref_az, ref_el, obs.az_rad, obs.el_rad).max() < 0.01 * ONE_MAS_RAD
    loc = EarthLocation.from_geodetic(site.lon_deg * u.deg, site.lat_deg * u.deg,
                                      site.height_m * u.m)
    t_ap = Time(times.jd1, times.jd2, format="jd", scale="utc")
    ref = SkyCoord(CYG61.ra_deg * u.deg, CYG61.dec_deg * u.deg,
                   pm_ra_cosdec=CYG61.pm_ra_cosdec_mas_yr * u.mas / u.yr,
                   pm_dec=CYG61.pm_dec_mas_yr * u.mas / u.yr,
                   distance=(1000 / CYG61.parallax_mas) * u.pc,
                   radial_velocity=CYG61.rv_km_s * u.km / u.s,
                   obstime=Time(CYG61.epoch_jyear, format="jyear", scale="tt")
                   ).apply_space_motion(new_obstime=t_ap).transform_to(
                       AltAz(obstime=t_ap, location=loc))
    obs = CYG61.observe(times, geo, eop)
    assert sep_rad(ref.az.rad, ref.alt.rad, obs.az_rad, obs.el_rad).max() < ONE_MAS_RAD


def test_the_moon_in_chunks_matches_skyfield_per_point_within_0_01_mas(site, eop):
    moon = SolarSystemBody("moon")
    geo = site.without_refraction()
    rng = np.random.default_rng(9)
    for t in _chunks(_us("2024-03-15T19:30:00Z"), 2 * 3600.0, rng)[:12]:
        times = UtcTimes.from_unix_us(t)
        enu, _ = moon.topocentric_enu(times, geo, eop)
        exact = moon.exact_enu(times, geo, eop)  # skyfield at each instant
        a1, e1, _, _ = enu_to_azel(enu, enu)
        a2, e2, _, _ = enu_to_azel(exact, exact)
        assert sep_rad(a1, e1, a2, e2).max() < 0.01 * ONE_MAS_RAD
