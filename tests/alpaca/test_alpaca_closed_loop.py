"""Alpaca `Action("TrackSatellite", {"closed_loop": true})` run end to end, in lockstep.

alpyca (ASCOM's Python client, in a worker thread) drives the Alpaca façade over HTTP;
the façade, the VSS, the emulator and the guide camera share one lockstep loop. The
camera sees the ISS whose true elements are 2 s along and 40″ across off the ones
given to the VSS. Truth is the test's own: the emulator's encoders streamed over a
connection of the test's, against skyfield's place from the camera's truth elements.
"""

from __future__ import annotations

import asyncio
import json

import numpy as np
from alpaca.telescope import Telescope
from signal_recording import recording
from sky_truth import satellite_truth, sky_sep_arcsec
from vss_rig import run_lockstep_scenario

from catalogs import load_tle_file, sample_tle_path, select_satellite
from guide_camera import CameraConfig
from virtualstar.astro import UtcTimes, load_site
from virtualstar.launcher import satellite_camera

START = "2024-05-18T19:51:00Z"  # the ISS rising in the west over Poznań, at 10° elevation
ENCODERS = ["axis.az.position", "axis.el.position", "time.true_us"]
SETTLE_S = 20.0  # the loop's error counts from this long after the join
MEASURED_S = 30.0


def _us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


def test_track_satellite_action_with_closed_loop_follows_the_true_iss():
    from virtualstar.alpaca import serve_alpaca

    site = load_site()
    iss = select_satellite(load_tle_file(sample_tle_path("stations")), "ISS")
    camera = satellite_camera(iss.line1, iss.line2, site, along_s=2.0, across_arcsec=40.0,
                              at_us=_us(START) + 80_000_000, config=CameraConfig(seed=3))
    tle = "\n".join(["ISS (ZARYA)", iss.line1, iss.line2])

    async def scenario(vss, clock):
        service = await serve_alpaca(vss.client(), port=0, discovery_bind=None)
        scope = Telescope(service.url.removeprefix("http://"), 0)

        async def alpaca(fn, *args):
            """One alpyca call from a worker thread; mount time stands still meanwhile."""
            clock.freeze()
            try:
                return await asyncio.to_thread(fn, *args)
            finally:
                clock.thaw()

        try:
            await alpaca(setattr, scope, "Connected", True)
            op = json.loads(await alpaca(scope.Action, "TrackSatellite", json.dumps(
                {"tle": tle, "sat": "ISS", "closed_loop": True})))
            status = {}
            while (status.get("phase") or "") != "tracking":
                await clock.sleep(1.0)
                status = json.loads(await alpaca(scope.Action, "OperationStatus", ""))
            join = status["info"]["tracking_from_us"]
            async with recording(vss, ENCODERS, rate_hz=10.0, clock=clock) as rec:
                await clock.sleep_until_us(join + int((SETTLE_S + MEASURED_S) * 1e6))
            during = json.loads(await alpaca(scope.Action, "OperationStatus", ""))
            await alpaca(scope.AbortSlew)
        finally:
            await service.close()
        return op, join, rec, during

    op, join, rec, during = run_lockstep_scenario(START, scenario, camera=camera)
    assert op["kind"] == "track_satellite" and "ISS" in op["target"]
    assert during["id"] == op["id"]
    loop = during["info"]["closed_loop"]
    assert loop["kind"] == "satellite" and loop["state"] == "locked", loop
    assert loop["accepted"] > 300 and loop["refused"] == 0
    t = rec.t_us
    measured = t >= join + int(SETTLE_S * 1e6)
    assert measured.sum() >= 10 * MEASURED_S - 5  # 10 Hz
    enc_az = np.degrees(rec["axis.az.position"][measured]) % 360
    enc_el = np.degrees(rec["axis.el.position"][measured])
    true_us = rec["time.true_us"][measured].astype(np.int64)
    truth = satellite_truth(camera.truth.satrec, true_us, site)
    err = sky_sep_arcsec(enc_az, enc_el, *truth)
    assert np.sqrt(np.mean(err**2)) < 2.0, (np.sqrt(np.mean(err**2)), err.max())
    # open loop (the elements the VSS was given) would be this far off the true ISS
    nominal = satellite_truth((iss.line1, iss.line2), true_us, site)
    assert sky_sep_arcsec(*nominal, *truth).min() > 500.0
