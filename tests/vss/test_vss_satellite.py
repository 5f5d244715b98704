"""A satellite pass straight over the site: keyhole, cable wrap, the whole pass tracked.

The site is put under the ISS ground track (its sub-satellite point from
skyfield at a chosen instant), so the pass culminates within a degree of the
zenith, where the azimuth rate exceeds what the mount can do. The server must
plan the keyhole, follow the pass to its end without a fault, and the encoders
must stay on the satellite (skyfield's position, independent of
virtualstar.astro) within the keyhole error the server reports.
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from sky_truth import iss_truth, sky_sep_arcsec, skyfield_iss
from skyfield.api import wgs84
from typer.testing import CliRunner
from vss_rig import Rig, run_lockstep_scenario, sample_encoders

from catalogs import sample_tle_path
from virtualstar.astro import Site, UtcTimes
from virtualstar.cli.main import app
from virtualstar.vss_client import VssRequestError, call_server

runner = CliRunner()
OVERHEAD_UTC = (2024, 5, 18, 20, 0, 0)
HORIZON_DEG = 40.0  # track only the high part of the pass: the test stays short


@pytest.fixture(scope="module")
def zenith():
    sat, sf = skyfield_iss()
    t = sf.ts.utc(*OVERHEAD_UTC)
    sub = wgs84.subpoint_of(sat.at(t))
    site = Site(lat_deg=sub.latitude.degrees, lon_deg=sub.longitude.degrees, height_m=0.0,
                pressure_hpa=0.0, name="under the ISS")
    overhead_us = int(UtcTimes.from_iso(["2024-05-18T20:00:00Z"]).to_unix_us()[0])
    rig = Rig(start_us=overhead_us - 200_000_000, site=site, horizon_deg=HORIZON_DEG).start()
    yield rig, site
    rig.close()


def test_a_pass_through_the_zenith_is_tracked_to_its_end_through_the_keyhole(zenith):
    rig, site = zenith
    res = runner.invoke(app, ["track", "--tle", str(sample_tle_path("stations")), "--sat", "ISS",
                              "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)["info"]
    assert info["culmination_el_deg"] > 88.0
    assert info["keyhole"] is True
    # sample the encoders during the pass (mount time from the same read)
    names = ["axis.az.position", "axis.el.position", "axis.az.error_arcsec",
             "axis.el.error_arcsec", "traj.ref_az", "traj.ref_el"]
    samples = []
    deadline = time.monotonic() + 90.0
    while time.monotonic() < deadline:
        values, t_us = rig.run(rig.mount_read(names))
        if info["pass_start_us"] + 2e6 < t_us < info["pass_end_us"] - 2e6:
            samples.append((t_us, *(values[n] for n in names)))
        if t_us > info["pass_end_us"]:
            break
        time.sleep(0.05)
    op = call_server(rig.url, "wait")  # the track ends at set, then the mount comes to rest
    assert op["phase"] == "done", op
    assert op["info"]["ended"] == "the pass ended"
    # the encoders followed the keyhole's demand; the sky saw the keyhole: reported apart
    assert op["info"]["following_rms_arcsec"] < 2.0
    assert op["info"]["planned_deviation"] == ["keyhole"]
    assert op["info"]["outcome"] == "degraded"
    assert op["info"]["tracking_peak_arcsec"] > 60.0  # on target: the keyhole is not hidden
    assert len(samples) >= 10
    t_us, az, el, az_err, el_err, ref_az, ref_el = (np.array(c) for c in zip(*samples,
                                                                               strict=True))
    # skyfield's apparent direction: light time and aberration, like a real observation
    true_az, true_el = iss_truth(t_us, site)  # the site has no air: no refraction
    sep = sky_sep_arcsec(np.degrees(az), np.degrees(el), true_az, true_el)
    ref_sep = sky_sep_arcsec(np.degrees(ref_az), np.degrees(ref_el), true_az, true_el)
    servo = np.hypot(az_err * np.cos(el), el_err)  # the mount's own following error
    # the commanded path is the satellite's, except inside the keyhole, where it stays
    # within the deviation the server announced ...
    far = true_el < 60.0
    assert far.sum() >= 5
    assert ref_sep[far].max() < 0.5, ref_sep[far]
    assert ref_sep.max() <= info["keyhole_max_error_arcsec"] + 0.5
    # ... and the encoders sit on the commanded path within the mount's following error
    assert np.all(sep <= ref_sep + servo + 0.5), (sep, ref_sep, servo)
    assert np.median(sep[far]) < 0.5
    underruns = rig.run(rig.mount_read(["traj.underruns"]))[0]["traj.underruns"]
    assert underruns == 0


def _pass_events(site: Site, start: tuple, end: tuple) -> dict[str, int]:
    """Rise, culmination and set (µs) of the ISS above 5° from skyfield (geometric, no refraction)."""
    sat, sf = skyfield_iss()
    topos = wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)
    t, kinds = sat.find_events(topos, sf.ts.utc(*start), sf.ts.utc(*end), altitude_degrees=5.0)
    out = {}
    for ti, k in zip(t, kinds, strict=True):
        out[("rise", "culmination", "set")[k]] = int(round(ti.utc_datetime().timestamp() * 1e6))
    return out


def test_a_pass_already_past_culmination_is_joined_where_it_is_and_tracked_to_its_set():
    """The server starts 40 s after culmination: it joins that pass, not the next one."""
    site = Site(lat_deg=52.4064, lon_deg=16.9252, height_m=85.0, pressure_hpa=0.0,
                name="Poznań without refraction")
    events = _pass_events(site, (2024, 5, 18, 19, 40), (2024, 5, 18, 20, 5))
    start_us = events["culmination"] + 40_000_000
    tle = sample_tle_path("stations").read_text()

    async def scenario(vss, clock):
        op = await vss.server.call("track", {"tle": tle, "sat": "ISS"})
        samples = await sample_encoders(vss, clock, 5.0, reads=1000, tracking_only=True)
        done = await vss.server.call("wait")
        return op, samples, done

    start_iso = UtcTimes.from_unix_us(start_us).iso(3)[0]
    op, samples, done = run_lockstep_scenario(start_iso, scenario, site=site)
    info = op["info"]
    assert info["pass_in_progress"] is True
    assert info["pass_start_us"] - start_us < 60_000_000  # joined within a minute
    # it stops before the set, by the run-out after its end (half a 2-s ramp and 1 s)
    assert 0 <= events["set"] - info["pass_end_us"] < 4_000_000
    assert done["phase"] == "done" and done["info"]["ended"] == "the pass ended"
    assert done["info"]["tracking_to_us"] >= events["set"] - 4_000_000
    assert done["info"]["tracking_rms_arcsec"] < 2.0
    # the encoders sit on skyfield's ISS all along the part of the pass that was left
    joined = done["info"]["tracking_from_us"]  # before it: the run-up onto the path
    after = samples.t_us >= joined
    sep = sky_sep_arcsec(samples.az_deg[after], samples.el_deg[after],
                         *iss_truth(samples.t_us[after], site))
    assert len(sep) >= 20
    assert np.median(sep) < 1.0 and sep.max() < 5.0, sep


def test_elements_years_older_than_the_mount_time_are_refused_with_the_hint_vs_where_gives():
    tle = sample_tle_path("stations").read_text()

    async def scenario(vss, clock):
        vs = vss.client()
        with pytest.raises(VssRequestError) as err:
            await vs.request("track", {"tle": tle, "sat": "ISS"})
        ping = await vs.request("ping")
        return err.value, ping

    error, ping = run_lockstep_scenario("2026-11-25T20:00:00Z", scenario)
    assert error.code == "stale_tle"
    assert "days after the TLE epoch" in error.message and "load fresh elements" in error.message
    assert "vs where --tle" in error.message
    assert ping == {"pong": True}  # the server keeps serving


def test_track_wait_shows_the_wait_for_the_pass_in_mount_time_when_piped():
    """`vs track --tle ... --wait` into a pipe: a line per phase, the first ones saying how
    long until the pass starts (mount time, read from the server), then the summary."""
    sat, sf = skyfield_iss()
    sub = wgs84.subpoint_of(sat.at(sf.ts.utc(*OVERHEAD_UTC)))
    site = Site(lat_deg=sub.latitude.degrees, lon_deg=sub.longitude.degrees, height_m=0.0,
                pressure_hpa=0.0, name="under the ISS")
    overhead_us = int(UtcTimes.from_iso(["2024-05-18T20:00:00Z"]).to_unix_us()[0])
    rig = Rig(start_us=overhead_us - 300_000_000, site=site, horizon_deg=60.0).start()
    try:
        res = runner.invoke(app, ["track", "--tle", str(sample_tle_path("stations")), "--sat",
                                  "ISS", "--server", rig.url, "--wait"])
    finally:
        rig.close()
    assert res.exit_code == 0, res.output
    lines = res.stderr.splitlines()
    planned = next(x for x in lines if ": pass planned" in x)
    assert planned.startswith("track_satellite ISS (ZARYA): pass planned — the pass starts in ")
    assert "culmination 8" in planned or "culmination 9" in planned
    phases = [x.split(": ", 1)[1].split(" —")[0] for x in lines
              if x.startswith("track_satellite ISS")]
    assert {"pass planned", "waiting", "tracking"} <= set(phases), lines
    assert phases.index("pass planned") < phases.index("waiting") < phases.index("tracking")
    assert any("of the pass left" in x for x in lines if ": tracking" in x)
    assert "error on target RMS" in res.stdout  # the summary table once the pass ended


def test_the_wait_line_counts_down_in_mount_time():
    from virtualstar.cli.wait_display import wait_text

    op = {"kind": "track", "target": "ISS\u202e", "phase": "waiting",
          "info": {"pass_start_utc": "2024-05-18T20:00:00.000Z",
                   "pass_end_utc": "2024-05-18T20:04:30.000Z",
                   "pass_rise_utc": "2024-05-18T19:58:00.000Z", "culmination_el_deg": 87.25}}
    at = int(UtcTimes.from_iso(["2024-05-18T19:47:25Z"]).to_unix_us()[0])
    assert wait_text(op, at) == (
        "track ISS\\u202e: waiting — the pass starts in 12 min 35 s; rise 19:58:00, tracked "
        "20:00:00–20:04:30 UTC, culmination 87.2°; mount time 19:47:25")
    assert wait_text({**op, "phase": "tracking"}, at + 780_000_000).startswith(
        "track ISS\\u202e: tracking — 4 min 05 s of the pass left;")
    assert wait_text(op, None) == ("track ISS\\u202e: waiting — rise 19:58:00, tracked "
                                   "20:00:00–20:04:30 UTC, culmination 87.2°")
