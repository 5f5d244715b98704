"""Cable wrap, keyhole, slews, rise/set and satellite passes, against brute force."""

from __future__ import annotations

import math

import erfa
import numpy as np
import pytest
from astro_satdata import load_test_satellites

from virtualstar.astro.altaz import MountLimits, elevation_ok, plan_keyhole, unwrap_azimuth
from virtualstar.astro.events import find_events, satellite_passes
from virtualstar.astro.exceptions import UnreachablePath
from virtualstar.astro.site import Site
from virtualstar.astro.slew import plan_slew, plan_slew_to_target, trapezoid
from virtualstar.astro.stars import IcrsStar
from virtualstar.astro.targets import FixedAltAz
from virtualstar.astro.timescales import UtcTimes

ISS = load_test_satellites()["ISS (ZARYA)"]
DAY_START = UtcTimes.from_iso(["2024-05-18T00:00:00"])


def test_unwrap_keeps_a_path_crossing_north_continuous_and_inside_the_wrap():
    az = np.radians(np.r_[np.linspace(300, 359, 30), np.linspace(0, 60, 30)])
    mount = unwrap_azimuth(az)
    assert np.all(np.abs(np.diff(mount)) < math.radians(3))
    assert math.radians(-270) <= mount.min() and mount.max() <= math.radians(270)
    np.testing.assert_allclose(np.mod(mount, 2 * np.pi), az, atol=1e-12)
    assert math.degrees(mount[0]) == pytest.approx(-60)  # 300..420 would leave the wrap


def test_unwrap_takes_the_turn_of_the_wrap_nearest_the_mount():
    az = np.radians(np.linspace(200, 260, 30))
    assert math.degrees(unwrap_azimuth(az, current_az_rad=math.radians(250))[0]) == (
        pytest.approx(200))
    assert math.degrees(unwrap_azimuth(az, current_az_rad=math.radians(-80))[0]) == (
        pytest.approx(-160))


def test_unwrap_refuses_a_path_longer_than_the_wrap():
    az = np.radians(np.linspace(0, 600, 200)) % (2 * np.pi)
    with pytest.raises(UnreachablePath, match="cable wrap"):
        unwrap_azimuth(az, limits=MountLimits(wrap_min_deg=-200, wrap_max_deg=200))


def test_elevation_limits_mask():
    mask = elevation_ok(np.radians([-5, 10, 80, 89]), MountLimits(el_min_deg=5, el_max_deg=85))
    assert mask.tolist() == [False, True, True, False]


def _site_under_the_iss(t_iso: str, offset_deg: float) -> Site:
    """A site a little beside the ISS ground track, so that a pass culminates near zenith."""
    times = UtcTimes.from_iso([t_iso])
    r_km, _ = ISS.teme_km(times)
    theta = erfa.gmst82(times.jd1, times.jd2)[0]
    x, y, z = r_km[0]
    itrs = np.array([math.cos(theta) * x + math.sin(theta) * y,
                     -math.sin(theta) * x + math.cos(theta) * y, z]) * 1e3
    lon, lat, _ = erfa.gc2gd(1, itrs)
    return Site(lat_deg=math.degrees(lat) + offset_deg, lon_deg=math.degrees(lon),
                height_m=0.0, pressure_hpa=0.0)


def test_zenith_keyhole_plan_respects_the_rate_and_reports_its_error(eop):
    site = _site_under_the_iss("2024-05-18T03:00:00", 0.02)
    times = UtcTimes.from_iso(["2024-05-18T02:55:00"]).shifted(np.arange(0, 600, 0.1))
    obs = ISS.observe(times, site, eop)
    above = obs.el_rad > 0
    t = times.seconds_since(times.jd1[0], times.jd2[0])[above]
    el = obs.el_rad[above]
    assert math.degrees(el.max()) > 89.0
    az = unwrap_azimuth(obs.az_rad[above])
    plan = plan_keyhole(t, az, el, max_az_rate_deg_s=6.0)
    assert plan.limited and plan.max_true_az_rate_deg_s > 30.0
    assert np.abs(np.diff(plan.az_rad) / np.diff(t)).max() <= math.radians(6.0) * (1 + 1e-9)
    err_arcsec = np.degrees(erfa.seps(plan.az_rad, el, az, el)) * 3600
    assert plan.max_error_arcsec == pytest.approx(err_arcsec.max())
    # A naive follower (catch up at full rate) lags more than the planned path.
    naive = az.copy()
    for i in range(1, len(t)):
        step = math.radians(6.0) * (t[i] - t[i - 1])
        naive[i] = naive[i - 1] + np.clip(az[i] - naive[i - 1], -step, step)
    naive_err = np.degrees(erfa.seps(naive, el, az, el)).max() * 3600
    assert plan.max_error_arcsec < 0.75 * naive_err
    relaxed = plan_keyhole(t, az, el, max_az_rate_deg_s=1000.0)
    assert not relaxed.limited and relaxed.max_error_arcsec == 0.0


def test_trapezoid_and_triangle_profiles_have_known_durations():
    long = trapezoid(0.0, math.radians(90), math.radians(10), math.radians(5))
    assert long.duration_s == pytest.approx(11.0)  # 2 s ramps (10 deg each) + 7 s cruise
    short = trapezoid(0.0, math.radians(-10), math.radians(10), math.radians(5))
    assert short.duration_s == pytest.approx(2 * math.sqrt(2.0))
    for prof in (long, short):
        t = np.linspace(0, prof.duration_s, 20001)
        pos, rate = prof.position(t), prof.rate(t)
        assert pos[-1] == pytest.approx(prof.start_rad + prof.distance_rad)
        assert np.abs(rate).max() <= math.radians(10) * (1 + 1e-12)
        dt = t[1] - t[0]  # a ramp end inside a step makes the mean rate differ by < a·dt
        np.testing.assert_allclose(np.diff(pos) / np.diff(t), 0.5 * (rate[1:] + rate[:-1]),
                                   atol=math.radians(5) * dt)
        assert np.abs(np.diff(rate) / np.diff(t)).max() <= math.radians(5) * (1 + 1e-6)


def test_two_axis_slew_lasts_as_long_as_the_slower_axis_and_can_synchronise():
    limits = MountLimits(az_max_rate_deg_s=10, el_max_rate_deg_s=5, az_max_accel_deg_s2=5,
                         el_max_accel_deg_s2=5)
    plan = plan_slew(0.0, math.radians(10), math.radians(90), math.radians(60), limits)
    assert plan.duration_s == pytest.approx(11.0)  # az: 11 s; el: 50 deg at 5 deg/s → 11 s
    sync = plan_slew(0.0, math.radians(10), math.radians(30), math.radians(20), limits,
                     synchronise=True)
    assert sync.az.duration_s == pytest.approx(sync.el.duration_s)
    t, az, el = sync.sample(0.01)
    assert az[-1] == pytest.approx(math.radians(30)) and el[-1] == pytest.approx(math.radians(20))


def test_slew_to_a_moving_target_arrives_where_the_target_is(site, eop):
    star = IcrsStar(279.2341, 38.7830, name="Vega")
    start = UtcTimes.from_iso(["2024-05-18T22:00:00"])
    plan, arrival_s = plan_slew_to_target(star, site, start, 0.0, math.radians(20),
                                          MountLimits(az_max_rate_deg_s=2, el_max_rate_deg_s=2),
                                          eop)
    there = star.observe(start.shifted(arrival_s), site, eop)
    assert plan.duration_s == pytest.approx(arrival_s, abs=1e-3)
    assert plan.az.position(arrival_s) % (2 * math.pi) == pytest.approx(there.az_rad[0],
                                                                         abs=1e-6)
    assert plan.el.position(arrival_s) == pytest.approx(there.el_rad[0], abs=1e-6)


def _crossings(t, el, level):
    i = np.flatnonzero(np.sign(el[:-1] - level) != np.sign(el[1:] - level))
    return t[i] + (level - el[i]) / (el[i + 1] - el[i]) * (t[i + 1] - t[i])


def test_star_rise_culmination_set_match_a_one_second_scan(site, eop):
    star = IcrsStar(213.9153, 19.1824, name="Arcturus")
    events = find_events(star, site, DAY_START, 86400.0, eop=eop)
    t = np.arange(0.0, 86400.0, 1.0)
    obs = star.observe(DAY_START.shifted(t), site, eop)
    brute = _crossings(t, obs.el_rad, 0.0)
    ours = [ev for ev in events if ev.kind in ("rise", "set")]
    found = [ev.utc.seconds_since(DAY_START.jd1[0], DAY_START.jd2[0])[0] for ev in ours]
    np.testing.assert_allclose(found, brute, atol=0.01)
    culm = [ev for ev in events if ev.kind == "culmination"]
    assert len(culm) == 1
    assert culm[0].el_deg == pytest.approx(math.degrees(obs.el_rad.max()), abs=1e-6)
    assert abs(culm[0].az_deg - 180.0) < 0.1  # upper culmination on the meridian, south


def test_fixed_target_never_moves(site):
    obs = FixedAltAz(120.0, 45.0).observe(DAY_START.shifted(np.arange(3.0)), site)
    assert np.all(np.degrees(obs.az_rad) == pytest.approx(120.0))
    assert not obs.az_rate_rad_s.any() and not obs.el_rate_rad_s.any()


def test_satellite_passes_match_a_one_second_scan(site, eop):
    end = DAY_START.shifted(86400.0)
    passes = satellite_passes(ISS, site, DAY_START, end, min_el_deg=10.0, eop=eop)
    t = np.arange(0.0, 86400.0, 1.0)
    obs = ISS.observe(DAY_START.shifted(t), site, eop)
    rises = _crossings(t, obs.el_rad, math.radians(10.0))
    assert len(passes) == len(rises) // 2 and len(passes) >= 2
    for p, (t_rise, t_set) in zip(passes, rises.reshape(-1, 2), strict=True):
        s = DAY_START.jd1[0], DAY_START.jd2[0]
        assert p.rise.utc.seconds_since(*s)[0] == pytest.approx(t_rise, abs=0.05)
        assert p.set.utc.seconds_since(*s)[0] == pytest.approx(t_set, abs=0.05)
        inside = (t >= t_rise) & (t <= t_set)
        assert p.culmination.el_deg == pytest.approx(math.degrees(obs.el_rad[inside].max()),
                                                     abs=0.01)


def test_a_pass_search_computes_each_instant_once(site, eop):
    """The root search asks for a bracket's ends again (and an event's place at its root):
    each instant is computed once, so a `vs track --tle` answers sooner, the same passes."""
    asked: list[float] = []

    class Counted:
        satrec = ISS.satrec  # a satellite: its scan step

        def observe(self, times, site_, eop_):
            asked.extend(times.seconds_since(DAY_START.jd1[0], DAY_START.jd2[0]).tolist())
            return ISS.observe(times, site_, eop_)

    events = find_events(Counted(), site, DAY_START, 86400.0, horizon_deg=10.0, eop=eop)
    single = asked[4321:]  # after the one vectorised scan of 20-s steps
    assert len(asked) - len(single) == 4321
    assert len(single) == len(set(single))
    assert [(e.kind, e.el_deg) for e in events] == [
        (e.kind, e.el_deg) for e in find_events(ISS, site, DAY_START, 86400.0,
                                                horizon_deg=10.0, eop=eop)]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_keyhole_path_reaches_the_known_optimum_of_the_max_azimuth_error(seed):
    """For a rate limit L the least possible max |command - az| is
    max over s < t of (|az(t) - az(s)| - L (t - s)) / 2; the plan attains it."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 60, 300))
    az = np.cumsum(rng.normal(0, 0.05, 300)) + 2.0 * np.tanh((t - 30) / 2)
    rate_deg_s = 3.0
    lim = math.radians(rate_deg_s)
    gap = np.abs(az[:, None] - az[None, :]) - lim * np.abs(t[:, None] - t[None, :])
    optimum = max(gap.max(), 0.0) / 2
    plan = plan_keyhole(t, az, np.zeros_like(t), rate_deg_s)
    assert np.abs(plan.az_rad - az).max() == pytest.approx(optimum, rel=1e-9)
    assert np.abs(np.diff(plan.az_rad) / np.diff(t)).max() <= lim * (1 + 1e-9)


def test_horizon_profile_interpolates_through_north():
    from virtualstar.astro.altaz import Horizon

    trees = Horizon(az_deg=(350.0, 10.0, 180.0), el_deg=(20.0, 10.0, 5.0))
    el = np.degrees(trees.min_el_rad(np.radians([0.0, 350.0, 95.0, 359.0])))
    np.testing.assert_allclose(el, [15.0, 20.0, 7.5, 15.5])
    mask = trees.visible(np.radians([0.0, 0.0]), np.radians([14.0, 16.0]))
    assert mask.tolist() == [False, True]
