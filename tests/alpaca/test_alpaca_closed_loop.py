"""Alpaca `Action("TrackSatellite", {"closed_loop": true})` run end to end, in lockstep.

alpyca (ASCOM's Python client, in a worker thread) drives the Alpaca façade over HTTP;
the façade, the VSS, the emulator and the guide camera share one lockstep loop (mount
time stands still while alpyca waits for an answer). The camera sees the ISS whose true
elements are 2 s along and 40″ across off the ones given to the VSS. Truth is the test's
own: the emulator's encoders streamed over a connection of the test's, against
skyfield's place from the camera's truth elements (tests/vss/closed_loop_truth.py).
"""

from __future__ import annotations

import asyncio
import json

from alpaca.telescope import Telescope
from closed_loop_truth import (
    ENCODERS,
    RISING_ISS_UTC,
    SETTLE_S,
    check_locked_on_the_true_iss,
    iss_tle_text,
    off_iss_camera,
)
from signal_recording import recording
from vss_rig import run_lockstep_scenario

from virtualstar.astro import UtcTimes, load_site

MEASURED_S = 30.0


def test_track_satellite_action_with_closed_loop_follows_the_true_iss():
    from virtualstar.alpaca import serve_alpaca

    site = load_site()
    start_us = int(UtcTimes.from_iso([RISING_ISS_UTC]).to_unix_us()[0])
    camera = off_iss_camera(site, at_us=start_us + 80_000_000, seed=3)

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
                {"tle": iss_tle_text(), "sat": "ISS", "closed_loop": True})))
            status = {}
            while status.get("phase") != "tracking":
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

    op, join, rec, during = run_lockstep_scenario(RISING_ISS_UTC, scenario, camera=camera)
    assert op["kind"] == "track_satellite" and "ISS" in op["target"]
    assert during["id"] == op["id"]  # the action's own track ran with the loop
    check_locked_on_the_true_iss(during["info"]["closed_loop"], rec,
                                 join + int(SETTLE_S * 1e6), rec.t_us[-1], camera, site,
                                 min_samples=int(10 * MEASURED_S) - 5)
