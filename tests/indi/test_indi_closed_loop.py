"""INDI `VS_CLOSED_LOOP` On, then `SAT_TRACKING_STAT` Track: a satellite track guided by
the guide camera, end to end, in lockstep.

The driver (`IndiTelescope`, what `vs-indi` runs under indiserver) is given the INDI XML
a client sends and reaches the VSS over its WebSocket, as under indiserver; the VSS,
the emulator and the camera share one lockstep loop. The camera sees the ISS whose true
elements are 2 s along and 40″ across off the ones given to the driver. Truth is the
test's own: the emulator's encoders against skyfield's place from the camera's truth
elements (tests/vss/closed_loop_truth.py). (indiserver itself runs in
test_indi_driver.py, inside a network namespace and not in lockstep.)
"""

from __future__ import annotations

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


def _switch(name: str, **members: str) -> str:
    ones = "".join(f'<oneSwitch name="{k}">{v}</oneSwitch>' for k, v in members.items())
    return f'<newSwitchVector device="VirtualStar" name="{name}">{ones}</newSwitchVector>'


def test_vs_closed_loop_on_guides_a_satellite_track_onto_the_true_iss():
    from virtualstar.indi.driver import IndiTelescope
    from virtualstar.indi.protocol import Reader

    site = load_site()
    start_us = int(UtcTimes.from_iso([RISING_ISS_UTC]).to_unix_us()[0])
    camera = off_iss_camera(site, at_us=start_us + 80_000_000, seed=4)

    async def scenario(vss, clock):
        driver = IndiTelescope(lambda xml: None, vss.url, None)
        reader = Reader()

        async def client(xml: str) -> None:
            for request in reader.feed(xml.encode()):
                await driver.handle(request)

        await client(_switch("CONNECTION", CONNECT="On"))
        await client(_switch("VS_CLOSED_LOOP", CLOSED_LOOP_ON="On"))
        await client('<newTextVector device="VirtualStar" name="SAT_TLE_TEXT">'
                     f'<oneText name="TLE">{iss_tle_text()}</oneText></newTextVector>')
        await client(_switch("SAT_TRACKING_STAT", SAT_TRACK="On"))
        states = {name: driver.props[name].state
                  for name in ("CONNECTION", "VS_CLOSED_LOOP", "SAT_TRACKING_STAT")}
        c = vss.client()
        status = await c.request("status")
        while (status["operation"] or {}).get("phase") != "tracking":
            await clock.sleep(1.0)
            status = await c.request("status")
        join = status["operation"]["info"]["tracking_from_us"]
        async with recording(vss, ENCODERS, rate_hz=10.0, clock=clock) as rec:
            await clock.sleep_until_us(join + int((SETTLE_S + MEASURED_S) * 1e6))
        during = await c.request("status")
        await client(_switch("SAT_TRACKING_STAT", SAT_HALT="On"))
        await clock.sleep(1.0)
        after = await c.request("status")
        await driver.vss.close()
        return states, join, rec, during, after

    states, join, rec, during, after = run_lockstep_scenario(
        RISING_ISS_UTC, scenario, camera=camera, listen="ws://127.0.0.1:0")
    assert states == {"CONNECTION": "Ok", "VS_CLOSED_LOOP": "Ok", "SAT_TRACKING_STAT": "Busy"}
    op = during["operation"]
    assert op["kind"] == "track_satellite" and op["phase"] == "tracking"
    check_locked_on_the_true_iss(op["info"]["closed_loop"], rec, join + int(SETTLE_S * 1e6),
                                 rec.t_us[-1], camera, site,
                                 min_samples=int(10 * MEASURED_S) - 5)
    # SAT_HALT ends the track and its loop: no offset is left behind
    assert after["operation"]["phase"] != "tracking" and "offsets" not in after["corrections"]
