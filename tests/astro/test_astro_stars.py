"""Stars: interpolated trajectories against per-point ERFA, astropy and skyfield."""

from __future__ import annotations

import dataclasses

import erfa
import numpy as np
import pytest
from astro_testkit import ONE_MAS_RAD, atco13_azel, sep_rad

from virtualstar.astro.stars import IcrsStar
from virtualstar.astro.timescales import UtcTimes

# Hipparcos-epoch astrometry (ESA 1997): two bright stars and a fast, close one.
VEGA = IcrsStar(279.23410832, 38.78299311, 201.02, 287.46, 128.93, -13.5, 1991.25, "Vega")
ARCTURUS = IcrsStar(213.91811403, 19.18726997, -1093.45, -1999.40, 88.85, -5.2, 1991.25, "Arcturus")
CYG61 = IcrsStar(316.72474640, 38.74941558, 4107.40, 3143.72, 287.18, -65.7, 1991.25, "61 Cyg A")
STARS = [VEGA, ARCTURUS, CYG61]
NIGHT_START_JD = (2460384.5, 0.80)  # 2024-03-15 19:12 UTC, IERS values final


def _night(n: int, hours: float = 10.0, start_h: float = 0.0) -> UtcTimes:
    return UtcTimes.from_jd(np.full(n, NIGHT_START_JD[0]),
                            NIGHT_START_JD[1] + np.linspace(start_h, start_h + hours, n) / 24)


@pytest.mark.parametrize("refraction", [False, True])
def test_interpolated_star_trajectory_matches_per_point_atco13_within_0_01_mas(site, eop,
                                                                              refraction):
    use_site = site if refraction else site.without_refraction()
    times = _night(20_000)
    pick = np.arange(0, len(times), 97)
    for star in STARS:
        obs = star.observe(times, use_site, eop)
        az, el = atco13_azel(star, times[pick], site, eop, use_site.pressure_hpa)
        up = el > np.radians(3.0)  # ERFA's refraction model is frozen below ~2.9°
        err = sep_rad(az[up], el[up], obs.az_rad[pick][up], obs.el_rad[pick][up])
        assert err.max() < 0.01 * ONE_MAS_RAD, (star.name, err.max() / ONE_MAS_RAD)


def test_star_rates_are_the_derivative_of_position(site, eop):
    times = _night(3001, hours=0.5, start_h=8.0)  # Vega high: away from ERFA's 2.9° kink
    obs = VEGA.observe(times, site, eop)
    dt = np.diff(times.seconds_since(times.jd1[0], times.jd2[0]))
    az_rate_fd = np.diff(np.unwrap(obs.az_rad)) / dt
    el_rate_fd = np.diff(obs.el_rad) / dt
    np.testing.assert_allclose(az_rate_fd, 0.5 * (obs.az_rate_rad_s[1:] + obs.az_rate_rad_s[:-1]),
                               atol=1e-10)
    np.testing.assert_allclose(el_rate_fd, 0.5 * (obs.el_rate_rad_s[1:] + obs.el_rate_rad_s[:-1]),
                               atol=1e-10)


def test_sparse_times_are_computed_exactly(site, eop):
    times = UtcTimes.from_iso(["2024-03-15T21:00:00", "2024-06-01T01:00:00"])
    obs = ARCTURUS.observe(times, site.without_refraction(), eop)
    az, el = atco13_azel(ARCTURUS, times, site, eop, 0.0)
    assert sep_rad(az, el, obs.az_rad, obs.el_rad).max() < 0.01 * ONE_MAS_RAD


def test_stars_match_astropy_altaz_within_1_mas(site, eop):
    import astropy.units as u
    from astropy.coordinates import AltAz, Distance, EarthLocation, SkyCoord
    from astropy.time import Time

    times = _night(6, hours=9.0)
    t_ap = Time(times.jd1, times.jd2, format="jd", scale="utc")
    loc = EarthLocation.from_geodetic(site.lon_deg, site.lat_deg, site.height_m)
    for refraction in (False, True):
        use_site = site if refraction else site.without_refraction()
        frame = AltAz(obstime=t_ap, location=loc, pressure=use_site.pressure_hpa * u.hPa,
                      temperature=site.temperature_c * u.deg_C, relative_humidity=site.humidity,
                      obswl=site.wavelength_um * u.um)
        for star in STARS:
            coo = SkyCoord(ra=star.ra_deg * u.deg, dec=star.dec_deg * u.deg,
                           pm_ra_cosdec=star.pm_ra_cosdec_mas_yr * u.mas / u.yr,
                           pm_dec=star.pm_dec_mas_yr * u.mas / u.yr,
                           distance=Distance(parallax=star.parallax_mas * u.mas),
                           radial_velocity=star.rv_km_s * u.km / u.s,
                           obstime=Time(star.epoch_jyear, format="jyear", scale="tt"))
            ref = coo.apply_space_motion(new_obstime=t_ap).transform_to(frame)
            obs = star.observe(times, use_site, eop)
            err = sep_rad(ref.az.rad, ref.alt.rad, obs.az_rad, obs.el_rad)
            assert err.max() < ONE_MAS_RAD, (star.name, refraction, err / ONE_MAS_RAD)


def test_stars_match_skyfield_within_10_mas_without_refraction(site, eop, skyfield_ts, de421):
    from skyfield.api import Star, wgs84

    times = _night(8, hours=9.0)
    tt1, tt2 = times.tt()
    t_sf = skyfield_ts.tt_jd(tt1, tt2)
    observer = de421["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    # skyfield and ERFA (hence astropy) treat the light time of a radial velocity differently:
    # 37 mas for 61 Cyg A (-66 km/s at 3.5 pc) over 33 years, 0.2 mas with rv = 0.
    # The astropy test above covers radial velocity.
    for star in [VEGA, ARCTURUS, dataclasses.replace(CYG61, rv_km_s=0.0)]:
        ep = erfa.epj2jd(star.epoch_jyear)
        sf_star = Star(ra_hours=star.ra_deg / 15, dec_degrees=star.dec_deg,
                       ra_mas_per_year=star.pm_ra_cosdec_mas_yr,
                       dec_mas_per_year=star.pm_dec_mas_yr, parallax_mas=star.parallax_mas,
                       radial_km_per_s=star.rv_km_s, epoch=ep[0] + ep[1])
        alt, az, _ = observer.at(t_sf).observe(sf_star).apparent().altaz()
        obs = star.observe(times, site.without_refraction(), eop)
        err = sep_rad(az.radians, alt.radians, obs.az_rad, obs.el_rad)
        assert err.max() < 10 * ONE_MAS_RAD, (star.name, err / ONE_MAS_RAD)


def test_topocentric_apparent_radec_matches_astropy_tete_within_1_mas(site, eop):
    import astropy.units as u
    from astropy.coordinates import TETE, Distance, EarthLocation, SkyCoord
    from astropy.time import Time

    from virtualstar.astro.observed import topocentric_apparent_radec

    times = _night(4, hours=8.0)
    t_ap = Time(times.jd1, times.jd2, format="jd", scale="utc")
    loc = EarthLocation.from_geodetic(site.lon_deg, site.lat_deg, site.height_m)
    obs = VEGA.observe(times, site.without_refraction(), eop)
    ra, dec = topocentric_apparent_radec(obs.az_rad, obs.el_rad, times, site, eop)
    coo = SkyCoord(ra=VEGA.ra_deg * u.deg, dec=VEGA.dec_deg * u.deg,
                   pm_ra_cosdec=VEGA.pm_ra_cosdec_mas_yr * u.mas / u.yr,
                   pm_dec=VEGA.pm_dec_mas_yr * u.mas / u.yr,
                   distance=Distance(parallax=VEGA.parallax_mas * u.mas),
                   radial_velocity=VEGA.rv_km_s * u.km / u.s,
                   obstime=Time(VEGA.epoch_jyear, format="jyear", scale="tt"))
    ref = coo.apply_space_motion(new_obstime=t_ap).transform_to(TETE(obstime=t_ap, location=loc))
    assert sep_rad(ref.ra.rad, ref.dec.rad, ra, dec).max() < ONE_MAS_RAD


def _erfa_refraction_second_implementation(el, refa, refb):
    """ERFA atioq's refraction step, written out again for the test (A tan z + B tan^3 z,
    Newton-Raphson corrected, sin(el) floored at 0.05 as atioq does)."""
    r, z = np.cos(el), np.maximum(np.sin(el), 0.05)
    tz = r / z
    w = refb * tz * tz
    d = (refa + w) * tz / (1.0 + (refa + 3.0 * w) / (z * z))
    cosdel = 1.0 - d * d / 2.0
    return np.arctan2(cosdel * np.sin(el) + d * r, r * (cosdel - d * z / r))


def test_refraction_table_reproduces_erfa_to_a_microarcsecond_above_3_deg(site):
    from virtualstar.astro.observed import refraction_table

    refa, refb = erfa.refco(site.pressure_hpa, site.temperature_c, site.humidity,
                            site.wavelength_um)
    table = refraction_table(site.pressure_hpa, site.temperature_c, site.humidity,
                             site.wavelength_um)
    el = np.radians(np.linspace(3.0, 90.0, 200_001))
    ours, _ = table.apply(el, np.zeros_like(el))
    truth = _erfa_refraction_second_implementation(el, refa, refb)
    assert np.abs(ours - truth).max() < 0.001 * ONE_MAS_RAD
    low = np.radians(np.linspace(-1.0, 3.0, 20_001))
    ours_low, _ = table.apply(low, np.zeros_like(low))
    truth_low = _erfa_refraction_second_implementation(low, refa, refb)
    assert np.abs(ours_low - truth_low).max() < 0.01 * ONE_MAS_RAD


def test_many_stars_at_once_match_per_point_atco13_within_5_mas(site, eop):
    """observe_stars (all stars in one ERFA call, 600-s spline nodes: a night's plan) is
    held to exact per-point ERFA, star by star."""
    from virtualstar.astro.stars import observe_stars

    times = _night(601)
    az, el = observe_stars(STARS, times, site, eop)
    assert az.shape == el.shape == (len(STARS), len(times))
    for k, star in enumerate(STARS):
        taz, tel = atco13_azel(star, times, site, eop, site.pressure_hpa)
        up = tel > np.radians(3.0)
        assert up.sum() > 50
        err = sep_rad(taz[up], tel[up], az[k][up], el[k][up])
        assert err.max() < 5 * ONE_MAS_RAD, (star.name, err.max() / ONE_MAS_RAD)
