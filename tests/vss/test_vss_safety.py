"""The Sun zone and the horizon profile: refused targets, detoured slews, trimmed passes.

Truth comes from astropy (the Sun, planets, stars in its AltAz frame with the
site's weather) and skyfield (the ISS), independent of virtualstar.astro; the
mount's real path is read from the emulator over a connection of the test's own,
every half second of mount time, in lockstep.
"""

from __future__ import annotations

import asyncio
import logging
import math
import re

import astropy.units as u
import erfa
import numpy as np
import pytest
from astropy.coordinates import EarthLocation, SkyCoord, get_body
from astropy.time import Time
from astropy.utils import iers
from sky_truth import observed_frame
from vss_rig import run_lockstep_scenario, sample_encoders

from catalogs import bright_stars, load_tle_file, sample_tle_path
from virtualstar.astro import AvoidanceZones, Horizon, UtcTimes, load_site
from virtualstar.vss_client import VssRequestError

iers.conf.auto_download = False

NOON = "2024-06-21T11:00:00Z"  # Poznań: the Sun at el 61°, Elnath 9.3° and Venus 4.6° from it
SITE = load_site()
LOC = EarthLocation.from_geodetic(SITE.lon_deg * u.deg, SITE.lat_deg * u.deg, SITE.height_m * u.m)


def sun_altaz_rad(t_us) -> tuple[np.ndarray, np.ndarray]:
    t = Time(np.asarray(t_us) / 1e6, format="unix", scale="utc")
    aa = get_body("sun", t, LOC).transform_to(observed_frame(t_us, SITE))
    return np.atleast_1d(aa.az.rad), np.atleast_1d(aa.alt.rad)


def sun_separation_deg(az_rad, el_rad, t_us) -> np.ndarray:
    saz, sel = sun_altaz_rad(t_us)
    return np.degrees(erfa.seps(np.asarray(az_rad), np.asarray(el_rad), saz, sel))


def noon_us() -> int:
    return int(UtcTimes.from_iso([NOON]).to_unix_us()[0])


def shown_separation(message: str) -> float:
    return float(re.search(r"is ([0-9.]+)° from the Sun", message).group(1))


def targets_near_the_sun() -> list[tuple[str, dict, float]]:
    """(label, request target, astropy's separation from the Sun in degrees) at noon."""
    t = noon_us()
    tt = Time(t / 1e6, format="unix", scale="utc")
    frame = observed_frame(t, SITE)
    sun = get_body("sun", tt, LOC)
    sun_aa = sun.transform_to(frame)
    elnath = bright_stars().lookup("Elnath")
    star = SkyCoord(elnath.ra_deg * u.deg, elnath.dec_deg * u.deg).transform_to(frame)
    venus = get_body("venus", tt, LOC).transform_to(frame)
    fixed_az, fixed_el = sun_aa.az.deg + 12.0, sun_aa.alt.deg - 8.0
    fixed = SkyCoord(fixed_az * u.deg, fixed_el * u.deg, frame=frame)
    radec = (sun.ra.deg, sun.dec.deg - 15.0)  # apparent place: ICRS differs by ~20″
    radec_aa = SkyCoord(radec[0] * u.deg, radec[1] * u.deg).transform_to(frame)
    return [
        ("a bright star", {"star": "Elnath"}, star.separation(sun_aa).deg),
        ("a planet", {"star": "Venus"}, venus.separation(sun_aa).deg),
        ("RA/Dec", {"ra_deg": radec[0], "dec_deg": radec[1]}, radec_aa.separation(sun_aa).deg),
        ("a fixed az/el", {"altaz": f"{fixed_az:.4f} {fixed_el:.4f}"},
         fixed.separation(sun_aa).deg),
    ]


def test_targets_inside_the_sun_zone_are_refused_naming_the_separation_and_nothing_is_disturbed():
    cases = targets_near_the_sun()

    async def scenario(vss, clock):
        vs = vss.client()
        safe = await vs.request("slew", {"altaz": "0 60"})  # north, 60° from the Sun
        answers = []
        for _, target, _ in cases:
            for cmd in ("slew", "track"):
                if cmd == "track" and "altaz" in target:
                    continue
                with pytest.raises(VssRequestError) as err:
                    await vs.request(cmd, target)
                answers.append((cmd, target, err.value))
        status = await vs.request("status")
        return safe, answers, status

    safe, answers, status = run_lockstep_scenario(NOON, scenario)
    expected = {str(target): sep for _, target, sep in cases}
    assert len(answers) == 7
    for _cmd, target, error in answers:
        assert error.code == "exclusion_zone", error
        assert "inside the 30° Sun exclusion zone" in error.message
        assert shown_separation(error.message) == pytest.approx(expected[str(target)], abs=0.05)
    # the refused commands left the hold alone
    assert status["operation"]["id"] == safe["id"] and status["operation"]["phase"] == "done"


def test_a_slew_whose_straight_path_crosses_the_sun_goes_around_it():
    t0 = noon_us()
    saz, sel = (math.degrees(float(x[0])) for x in sun_altaz_rad(t0))
    east, west = f"{saz - 85.0:.3f} 45", f"{saz + 85.0:.3f} 45"

    async def scenario(vss, clock):
        vs = vss.client()
        await vs.request("slew", {"altaz": east})
        slew = asyncio.ensure_future(vs.request("slew", {"altaz": west}))
        samples = await sample_encoders(vss, clock, 0.5, until=slew)
        return await slew, samples

    op, samples = run_lockstep_scenario(NOON, scenario)
    assert op["phase"] == "done" and op["info"]["landing_error_arcsec"] < 1.0
    assert len(op["info"]["detour_deg"]) >= 1
    t, az, el = samples.t_us, samples.az_rad, samples.el_rad
    assert len(t) > 20
    sep = sun_separation_deg(az, el, t)
    assert sep.min() >= 30.0, sep.min()
    # the straight path would have passed within 16° of the Sun (at el 45°, the Sun at 61°)
    assert abs(sel - 61.0) < 1.0


def test_an_operator_override_points_near_the_sun_and_is_logged_and_broadcast(caplog):
    async def scenario(vss, clock):
        vs = vss.client()
        op = await vs.request("slew", {"star": "Elnath", "allow_sun": True})
        event = await vs.next_event("safety_override", 5.0)
        await vs.request("stop")
        return op, event

    with caplog.at_level(logging.WARNING, logger="virtualstar.server"):
        op, event = run_lockstep_scenario(NOON, scenario)
    assert op["phase"] == "tracking" and op["info"]["allow_sun"] is True
    assert event["target"] == "Elnath" and event["zones"] == ["sun"]
    assert any("safety override" in r.message and "Elnath" in r.message for r in caplog.records)


def _iss_pass_near_the_sun(radius_deg: float):
    """Find with skyfield an ISS pass over Poznań that comes within `radius_deg` of the Sun
    but spends at least 90 s outside that zone above 10°; return (rise µs, ...)."""
    from virtualstar.astro import EarthOrientation
    from virtualstar.astro.bodies import skyfield_context

    sf = skyfield_context(EarthOrientation.from_astropy_iers_data())
    from skyfield.api import EarthSatellite, wgs84

    rec = next(r for r in load_tle_file(sample_tle_path("stations")) if "ISS" in r.name)
    sat = EarthSatellite(rec.line1, rec.line2, rec.name, sf.ts)
    topos = wgs84.latlon(SITE.lat_deg, SITE.lon_deg, SITE.height_m)
    earth, sun = sf.ephemeris["earth"], sf.ephemeris["sun"]
    t, kinds = sat.find_events(topos, sf.ts.utc(2024, 5, 17), sf.ts.utc(2024, 5, 20),
                               altitude_degrees=10.0)
    rises = [t[i] for i in range(len(kinds) - 2) if kinds[i] == 0 and kinds[i + 2] == 2]
    for rise in rises:
        grid = sf.ts.tt_jd(rise.tt + np.arange(0, 700) / 86400.0)
        alt, az, _ = (sat - topos).at(grid).altaz()
        s_alt, s_az, _ = (earth + topos).at(grid).observe(sun).apparent().altaz()
        up = alt.degrees > 10.0
        if up.sum() < 120:
            continue
        sep = np.degrees(erfa.seps(az.radians, alt.radians, s_az.radians, s_alt.radians))
        inside = up & (sep < radius_deg)
        if inside.any() and (up & ~inside).sum() >= 90:
            start = int(round(rise.utc_datetime().timestamp() * 1e6))
            return start, int(start + up.sum() * 1e6), sat, sf, topos
    pytest.skip("no ISS pass near the Sun in the bundled TLE's days")


def test_a_satellite_pass_is_tracked_only_outside_the_sun_zone():
    radius = 55.0  # a wide zone: the May evening passes come within 47° of the setting Sun
    start_us, _, sat, sf, topos = _iss_pass_near_the_sun(radius)
    tle = sample_tle_path("stations").read_text()

    async def scenario(vss, clock):
        op = await vss.server.call("track", {"tle": tle, "sat": "ISS"})
        # the pass is over within half an hour of mount time
        samples = await sample_encoders(vss, clock, 1.0, reads=1800, tracking_only=True)
        return op, samples, await vss.server.call("wait")

    start_iso = UtcTimes.from_unix_us(start_us - 120_000_000).iso(3)[0]
    op, samples, done = run_lockstep_scenario(
        start_iso, scenario, zones=AvoidanceZones(sun_radius_deg=radius))
    assert done["phase"] == "done", done
    tracked = (done["info"]["tracking_to_us"] - done["info"]["tracking_from_us"]) / 1e6
    assert tracked >= 30.0
    assert "zone_stop" in op["info"] or op["info"]["pass_in_progress"]  # trimmed at one end
    t, az, el = samples.t_us, samples.az_rad, samples.el_rad
    # the Sun from skyfield (an independent ephemeris path from the VSS's)
    from datetime import UTC, datetime

    grid = sf.ts.from_datetimes([datetime.fromtimestamp(x / 1e6, UTC) for x in t])
    s_alt, s_az, _ = (sf.ephemeris["earth"] + topos).at(grid).observe(
        sf.ephemeris["sun"]).apparent().altaz()
    sep = np.degrees(erfa.seps(az, el, s_az.radians, s_alt.radians))
    assert sep.min() >= radius - 0.5, sep.min()  # the refraction of a low Sun aside


def test_the_horizon_profile_refuses_a_place_behind_it_and_stops_a_track_before_it():
    """A wall 40° high in the east; a star setting in the west meets a 1.5°-higher bump."""
    start = "2024-05-18T19:40:00Z"
    t0 = int(UtcTimes.from_iso([start]).to_unix_us()[0])
    frame = observed_frame(t0, SITE)
    # a bright star low in the west, setting
    cands = []
    for name in ("Regulus", "Procyon", "Pollux", "Castor", "Alphard", "Capella"):
        s = bright_stars().lookup(name)
        aa = SkyCoord(s.ra_deg * u.deg, s.dec_deg * u.deg).transform_to(frame)
        if 200 < aa.az.deg < 320 and 15 < aa.alt.deg < 35:
            cands.append((name, aa.az.deg, aa.alt.deg))
    name, az, el = cands[0]
    bump = el - 1.0  # it sinks below this within minutes
    horizon = Horizon(az_deg=(45.0, 50.0, 130.0, 135.0, az - 40.0, az - 35.0, az + 35.0, az + 40.0),
                      el_deg=(5.0, 40.0, 40.0, 5.0, 5.0, bump, bump, 5.0))

    async def scenario(vss, clock):
        vs = vss.client()
        with pytest.raises(VssRequestError) as behind:
            await vs.request("slew", {"altaz": "90 30"})
        op = await vs.request("track", {"star": name, "duration_s": 3600.0, "wait": True})
        return behind.value, op

    behind, op = run_lockstep_scenario(start, scenario, zones=AvoidanceZones(horizon=horizon))
    assert behind.code == "unreachable"
    assert "below the horizon limit 40.00° there" in behind.message
    info = op["info"]
    assert op["phase"] == "done" and "below the horizon limit" in info["ended"]
    stop_t = info["tracking_to_us"]
    stop_aa = SkyCoord(bright_stars().lookup(name).ra_deg * u.deg,
                       bright_stars().lookup(name).dec_deg * u.deg).transform_to(observed_frame(stop_t, SITE))
    assert stop_aa.alt.deg >= bump - 0.01  # it stopped before the star sank behind the bump
    assert (stop_t - info["tracking_from_us"]) / 1e6 < 1800.0


def test_a_satellite_pass_is_joined_only_once_it_is_above_the_horizon_profile():
    """A 35° wall in the west, where the ISS rises: the track waits until it clears it."""
    wall = Horizon(az_deg=(0.0, 200.0, 205.0, 335.0, 340.0), el_deg=(5.0, 5.0, 35.0, 35.0, 5.0))
    tle = sample_tle_path("stations").read_text()

    async def scenario(vss, clock):
        op = await vss.server.call("track", {"tle": tle, "sat": "ISS"})
        samples = await sample_encoders(vss, clock, 1.0, reads=1800, tracking_only=True)
        return op, samples, await vss.server.call("wait")

    op, samples, done = run_lockstep_scenario("2024-05-18T19:45:00Z", scenario,
                                              zones=AvoidanceZones(horizon=wall))
    assert done["phase"] == "done"
    az, el = samples.az_deg, samples.el_deg
    floor = np.interp(az % 360.0, wall.az_deg, wall.el_deg, period=360.0)
    assert (el >= floor - 0.01).all(), (el - floor).min()
    assert (el < 35.0).any() and (az % 360.0 < 200.0).any()  # it did track low in the east


def test_where_and_passes_show_the_sun_separation_astropy_and_skyfield_agree_on(tmp_path):
    import json

    from typer.testing import CliRunner

    from virtualstar.cli.main import app

    runner = CliRunner()
    res = runner.invoke(app, ["where", "Elnath", "--at", NOON, "--json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)[0]
    t = noon_us()
    elnath = bright_stars().lookup("Elnath")
    star = SkyCoord(elnath.ra_deg * u.deg, elnath.dec_deg * u.deg).transform_to(observed_frame(t, SITE))
    sun = get_body("sun", Time(t / 1e6, format="unix"), LOC).transform_to(observed_frame(t, SITE))
    assert row["sun_separation_deg"] == pytest.approx(star.separation(sun).deg, abs=0.02)
    horizon = tmp_path / "horizon.txt"
    horizon.write_text("0 5\n200 5\n205 35\n335 35\n340 5\n")
    res = runner.invoke(app, ["passes", "--tle", str(sample_tle_path("stations")), "--sat", "ISS",
                              "--from", "2024-05-18T19:40:00Z", "--to", "2024-05-18T20:10:00Z",
                              "--horizon", str(horizon), "--json"])
    assert res.exit_code == 0, res.output
    p = json.loads(res.stdout)[0]
    assert 40.0 < p["sun_min_separation_deg"] < 60.0  # the setting Sun in the north-west
    rise = int(UtcTimes.from_iso([p["rise_utc"]]).to_unix_us()[0])
    above = int(UtcTimes.from_iso([p["above_horizon_from_utc"]]).to_unix_us()[0])
    assert above > rise + 60_000_000  # it rises in the west, behind the 35° wall


def test_a_hold_the_sun_is_about_to_reach_is_left_for_the_park_position():
    """With no look-ahead on holds, a place 31° ahead of the Sun is accepted; the watchdog
    must move the mount away before the Sun's zone reaches it."""
    t0 = noon_us()
    # the place the Sun will be at t0 + Δ, Δ chosen so that it is 31° from the Sun now
    dts = np.arange(1.0, 4.0, 0.01) * 3600e6
    saz, sel = sun_altaz_rad(t0 + dts.astype(np.int64))
    naz, nel = sun_altaz_rad(np.array([t0]))
    sep = np.degrees(erfa.seps(saz, sel, naz[0], nel[0]))
    k = int(np.argmin(np.abs(sep - 31.0)))
    place = f"{math.degrees(saz[k]):.4f} {math.degrees(sel[k]):.4f}"

    async def scenario(vss, clock):
        vs = vss.client()
        held = await vs.request("slew", {"altaz": place})
        await clock.sleep(30.0)
        # 15 minutes: the Sun closes in at ~0.25°/min
        samples = await sample_encoders(vss, clock, 30.0, reads=30)
        return held, samples, await vs.request("status")

    held, samples, status = run_lockstep_scenario(NOON, scenario, hold_lookahead_s=0.0)
    assert held["phase"] == "done"
    assert status["operation"]["kind"] == "evade" and status["operation"]["phase"] == "done"
    t, az, el = samples.t_us, samples.az_rad, samples.el_rad
    assert sun_separation_deg(az, el, t).min() >= 30.0
    assert abs(math.degrees(el[-1]) - 85.0) < 0.01  # parked (the stow position)
