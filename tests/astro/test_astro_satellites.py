"""Satellites: SGP4 verification data, and observed directions against skyfield."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pytest
from astro_satdata import load_test_satellites
from astro_testkit import ONE_ARCSEC_RAD, ONE_MAS_RAD, sep_rad
from sgp4.api import Satrec

from virtualstar.astro.exceptions import SatelliteError
from virtualstar.astro.satellites import Satellite
from virtualstar.astro.timescales import UtcTimes

SATS = load_test_satellites()


def _read_tcppver() -> dict[int, np.ndarray]:
    """Vallado's reference output: satnum -> rows (tsince_min, x, y, z, vx, vy, vz)."""
    text = resources.files("sgp4").joinpath("tcppver.out").read_text()
    blocks: dict[int, list[list[float]]] = {}
    current: list[list[float]] = []
    for line in text.splitlines():
        if line.strip().endswith("xx"):
            current = blocks.setdefault(int(line.split()[0]), [])
        elif line.strip():
            current.append([float(v) for v in line.split()[:7]])
    return {k: np.array(v) for k, v in blocks.items()}


def test_sgp4_reproduces_vallado_verification_output():
    """Every row of tcppver.out from SGP4-VER.TLE, through our Satellite.teme_km."""
    reference = _read_tcppver()
    tle = resources.files("sgp4").joinpath("SGP4-VER.TLE").read_text().splitlines()
    checked = 0
    for line1, line2 in zip(tle, tle[1:], strict=False):
        if not (line1.startswith("1 ") and line2.startswith("2 ")):
            continue
        sat = Satellite("ver", Satrec.twoline2rv(line1, line2))
        rows = reference[sat.satrec.satnum]
        days = rows[:, 0] / 1440.0
        # SGP4's time is a continuous UTC count (POSIX-like): build the instants that way,
        # so that those on a day ending in a leap second are the ones Vallado propagated to
        epoch_days, epoch_sec = sat.epoch.posix_days()
        times = UtcTimes.from_posix_days(np.full(days.shape, epoch_days[0]),
                                         epoch_sec[0] + days * 86400.0)
        err, r, v = sat.satrec.sgp4_array(*times.posix_jd())
        ok = err == 0  # the file lists the rows up to the error Vallado reports
        assert ok.sum() >= len(rows) - 1
        if not ok.any():
            continue
        r_ref, v_ref = rows[ok, 1:4], rows[ok, 4:7]
        if ok.all():
            r, v = sat.teme_km(times)
        else:
            r, v = r[ok], v[ok]
        np.testing.assert_allclose(r, r_ref, atol=1e-6 * np.maximum(1.0, np.abs(r_ref)).max())
        np.testing.assert_allclose(v, v_ref, atol=1e-8 * np.maximum(1.0, np.abs(v_ref)).max())
        checked += ok.sum()
    assert checked > 500


def test_sgp4_failure_raises_with_the_sgp4_message():
    sat = SATS["ISS (ZARYA)"]
    years_later = UtcTimes.from_iso(["2034-05-18T00:00:00"])
    with pytest.raises(SatelliteError, match="ISS"):
        sat.teme_km(years_later)


def _skyfield_altaz(sat: Satellite, times: UtcTimes, site, ts, de421):
    from skyfield.api import EarthSatellite, wgs84

    t = ts.tt_jd(*times.tt())  # two-part TT: a single float would cost ~70 mas on a LEO
    es = EarthSatellite.from_satrec(sat.satrec, ts)
    observer = de421["earth"] + wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    alt, az, _ = observer.at(t).observe(de421["earth"] + es).apparent().altaz()
    return az.radians, alt.radians


@pytest.mark.parametrize(("name", "start_iso"), [("ISS (ZARYA)", "2024-05-18T00:00:00"),
                                                 ("CSS (TIANHE)", "2024-05-18T00:00:00"),
                                                 ("SEASAT 1", "2021-07-24T00:00:00")])
def test_satellite_matches_skyfield_within_0_01_arcsec(name, start_iso, site, eop, skyfield_ts,
                                                       de421):
    sat = SATS[name]
    start = UtcTimes.from_iso([start_iso])
    times = start.shifted(np.linspace(0.0, 86400.0, 4000))
    obs = sat.observe(times, site.without_refraction(), eop)
    up = obs.el_rad > 0.0
    assert up.sum() > 20
    az, el = _skyfield_altaz(sat, times[up], site, skyfield_ts, de421)
    err = sep_rad(az, el, obs.az_rad[up], obs.el_rad[up])
    assert err.max() < 0.01 * ONE_ARCSEC_RAD, err.max() / ONE_MAS_RAD


def test_light_time_aberration_and_earth_orientation_each_matter(site, eop, skyfield_ts, de421):
    """The skyfield agreement above is not luck: dropping any correction breaks it."""
    from skyfield.api import wgs84

    sat = SATS["ISS (ZARYA)"]
    times = UtcTimes.from_iso(["2024-05-18T00:00:00"]).shifted(np.linspace(0, 86400, 4000))
    obs = sat.observe(times, site.without_refraction(), eop)
    up = obs.el_rad > np.radians(10)
    t = skyfield_ts.tt_jd(*times[up].tt())
    from skyfield.api import EarthSatellite

    geometric = (EarthSatellite.from_satrec(sat.satrec, skyfield_ts)
                 - wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)).at(t).altaz()
    err = sep_rad(geometric[1].radians, geometric[0].radians, obs.az_rad[up], obs.el_rad[up])
    assert err.max() > 1.0 * ONE_ARCSEC_RAD  # light time + diurnal aberration
    shifted_eop = type(eop)(eop.mjd, eop.ut1_utc_s + 0.001, eop.xp_arcsec, eop.yp_arcsec,
                            eop.measured_until_mjd)
    moved = sat.observe(times[up], site.without_refraction(), shifted_eop)
    err_ut1 = sep_rad(moved.az_rad, moved.el_rad, obs.az_rad[up], obs.el_rad[up])
    assert err_ut1.max() > 0.05 * ONE_ARCSEC_RAD  # 1 ms of UT1 is visible on a LEO


def test_satellite_rates_are_the_derivative_of_position(site, eop):
    sat = SATS["ISS (ZARYA)"]
    times = UtcTimes.from_iso(["2024-05-18T00:00:00"]).shifted(np.arange(0, 86400, 0.5))
    obs = sat.observe(times, site, eop)
    up = np.flatnonzero(obs.el_rad[:-1] > np.radians(5))
    d_az = (obs.az_rad[up + 1] - obs.az_rad[up] + math.pi) % (2 * math.pi) - math.pi
    d_el = obs.el_rad[up + 1] - obs.el_rad[up]
    mid_az_rate = 0.5 * (obs.az_rate_rad_s[up] + obs.az_rate_rad_s[up + 1])
    mid_el_rate = 0.5 * (obs.el_rate_rad_s[up] + obs.el_rate_rad_s[up + 1])
    np.testing.assert_allclose(d_az / 0.5, mid_az_rate, atol=2e-6, rtol=1e-3)
    np.testing.assert_allclose(d_el / 0.5, mid_el_rate, atol=2e-6, rtol=1e-3)


def test_refraction_lifts_a_low_satellite_by_the_erfa_amount(site, eop):
    import erfa

    sat = SATS["ISS (ZARYA)"]
    times = UtcTimes.from_iso(["2024-05-18T00:00:00"]).shifted(np.arange(0, 86400, 5.0))
    dry = sat.observe(times, site.without_refraction(), eop)
    wet = sat.observe(times, site, eop)
    low = (dry.el_rad > np.radians(5)) & (dry.el_rad < np.radians(30))
    refa, refb = erfa.refco(site.pressure_hpa, site.temperature_c, site.humidity,
                            site.wavelength_um)
    # A second implementation of ERFA atioq's refraction step (A tan z + B tan^3 z with
    # its Newton-Raphson correction, applied to the horizon vector).
    r, z = np.cos(dry.el_rad[low]), np.sin(dry.el_rad[low])
    tz = r / z
    w = refb * tz * tz
    d = (refa + w) * tz / (1.0 + (refa + 3.0 * w) / (z * z))
    cosdel = 1.0 - d * d / 2.0
    expected = np.arctan2(cosdel * z + d * r, r * (cosdel - d * z / r))
    np.testing.assert_allclose(wet.el_rad[low], expected, atol=0.01 * ONE_MAS_RAD, rtol=0)
    np.testing.assert_array_equal(wet.az_rad, dry.az_rad)


def test_omm_elements_give_the_same_orbit_as_the_tle():
    from sgp4 import exporter

    sat = SATS["CSS (TIANHE)"]
    fields = exporter.export_omm(sat.satrec, "CSS (TIANHE)")
    again = Satellite.from_omm(fields)
    times = UtcTimes.from_iso(["2024-05-18T03:00:00"]).shifted(np.arange(0, 600, 60.0))
    np.testing.assert_allclose(again.teme_km(times)[0], sat.teme_km(times)[0], atol=1e-3)
    with pytest.raises(SatelliteError, match="OMM"):
        Satellite.from_omm({"OBJECT_NAME": "x"})


def test_strided_time_selections_propagate():
    times = UtcTimes.from_iso(["2024-05-18T00:00:00"]).shifted(np.arange(0.0, 100.0))
    r_every, _ = SATS["ISS (ZARYA)"].teme_km(times)
    r_some, _ = SATS["ISS (ZARYA)"].teme_km(times[::7])
    np.testing.assert_array_equal(r_some, r_every[::7])


def test_result_does_not_depend_on_how_the_julian_date_is_split(site, eop):
    sat = SATS["ISS (ZARYA)"]
    # Across midnight, where UT1-UTC changes slope: the hourly nodes must sit on UTC hours.
    times = UtcTimes.from_iso(["2024-05-18T23:20:00"]).shifted(np.arange(0.0, 4800.0, 10.0))
    odd_split = UtcTimes(times.jd1 + 0.3125, times.jd2 - 0.3125)  # exact in binary; not midnight
    a = sat.observe(times, site, eop)
    b = sat.observe(odd_split, site, eop)
    assert sep_rad(a.az_rad, a.el_rad, b.az_rad, b.el_rad).max() < 0.01 * ONE_MAS_RAD
