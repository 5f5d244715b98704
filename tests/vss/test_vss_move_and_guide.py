"""The hand pad (`move`) and guide pulses (`guide`), in lockstep on the embedded emulator.

Truth is independent of the server: encoder rates from the emulator's own readings
at known mount times against the rates asked for; a guided track against astropy's
observed place of the RA/Dec shifted by the pulse (ICRS → AltAz with the site's air).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from sky_truth import observed_frame, radec_truth, sky_sep_arcsec
from vss_rig import read_emulator, run_lockstep_scenario

from virtualstar.astro import load_site
from virtualstar.vss_client import VssRequestError

START = "2024-05-18T21:00:00Z"  # night at Poznań: the Sun far below
AXES = ["axis.az.position", "axis.el.position"]
RA_DEG, DEC_DEG = 250.0, 36.5  # near M13: high in the east-south-east at START


async def encoders(vss) -> tuple[float, float, int]:
    v, t_us = await read_emulator(vss, AXES)
    return math.degrees(v[AXES[0]]) % 360.0, math.degrees(v[AXES[1]]), t_us


def test_move_turns_the_axes_at_the_rates_asked_and_stop_brings_them_to_rest():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 120.0, "el_deg": 40.0})
        op = await c.request("move", {"az_rate_deg_s": 2.0, "el_rate_deg_s": -0.5})
        assert op["kind"] == "move" and op["phase"] == "slewing"
        await clock.sleep(8.0)  # past the run-up
        a0, e0, t0 = await encoders(vss)
        await clock.sleep(5.0)
        a1, e1, t1 = await encoders(vss)
        status = await c.request("status")
        await c.request("stop")
        b0, f0, _ = await encoders(vss)
        await clock.sleep(3.0)
        b1, f1, _ = await encoders(vss)
        return (a1 - a0) / ((t1 - t0) / 1e6), (e1 - e0) / ((t1 - t0) / 1e6), status, \
            (b1 - b0, f1 - f0)

    az_rate, el_rate, status, drift = run_lockstep_scenario(START, scenario)
    assert az_rate == pytest.approx(2.0, rel=1e-3)
    assert el_rate == pytest.approx(-0.5, rel=1e-3)
    assert status["operation"]["kind"] == "move"
    assert max(abs(d) for d in drift) * 3600 < 0.5  # arcsec: at rest after stop


def test_move_toward_the_elevation_limit_comes_to_rest_before_it():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 200.0, "el_deg": 80.0})
        op = await c.request("move", {"el_rate_deg_s": 1.0})
        done = await c.request("wait", {"id": op["id"]})
        _az, el, _t = await encoders(vss)
        return done, el

    done, el = run_lockstep_scenario(START, scenario)
    assert done["phase"] == "done"
    assert "elevation limit" in done["info"]["ended"]
    assert 88.0 < el <= 89.5 + 1e-3


def test_move_refuses_rates_beyond_the_mount_and_a_zero_move():
    async def scenario(vss, clock):
        c = vss.client()
        errors = []
        for params in ({"az_rate_deg_s": 50.0}, {}, {"az_rate_deg_s": "fast"}):
            with pytest.raises(VssRequestError) as exc:
                await c.request("move", params)
            errors.append(exc.value)
        return errors

    too_fast, zero, wrong = run_lockstep_scenario(START, scenario)
    assert too_fast.code == "bad_request" and "rate limit" in too_fast.message
    assert zero.code == "bad_request" and "stop" in zero.message
    assert wrong.code == "bad_request" and "az_rate_deg_s" in wrong.message


@pytest.mark.parametrize(("north", "east"), [(20.0, 0.0), (0.0, -20.0), (12.0, 16.0)])
def test_a_guide_pulse_moves_the_track_by_the_offset_on_the_sky(north, east):
    site = load_site()

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        pulse = await c.request("guide", {"north_arcsec": north, "east_arcsec": east})
        await clock.sleep((pulse["end_us"] - await vss.server.telescope.motion.mount_time_us())
                          / 1e6 + 3.0)
        reads = [await encoders(vss) for _ in range(4)]
        return pulse, reads, await c.request("status")

    pulse, reads, status = run_lockstep_scenario(START, scenario)
    # on target is the place the guider moved the star to: the offset is not an error
    assert status["on_target"]["error_arcsec"] < 0.3
    assert status["tracking_error"]["10s"]["off_target_s"] == 0.0
    assert pulse["end_us"] - pulse["start_us"] == pytest.approx(
        math.hypot(north, east) / 7.5205 * 1e6, rel=1e-3)
    assert pulse["offset_arcsec"]["north"] == pytest.approx(north)
    assert pulse["offset_arcsec"]["east"] == pytest.approx(east)
    az, el, t_us = (np.array(x) for x in zip(*reads, strict=True))
    cos_dec = math.cos(math.radians(DEC_DEG))
    shifted = radec_truth(RA_DEG + east / 3600 / cos_dec, DEC_DEG + north / 3600, t_us, site)
    original = radec_truth(RA_DEG, DEC_DEG, t_us, site)
    assert sky_sep_arcsec(az, el, *shifted).max() < 0.3
    assert sky_sep_arcsec(az, el, *original) == pytest.approx(math.hypot(north, east), abs=0.3)


def test_a_guide_pulse_without_a_track_is_refused_as_not_tracking():
    async def scenario(vss, clock):
        c = vss.client()
        with pytest.raises(VssRequestError) as exc:
            await c.request("guide", {"north_arcsec": 5.0})
        return exc.value

    err = run_lockstep_scenario(START, scenario)
    assert err.code == "not_tracking" and "no sky target" in err.message


def test_guide_refuses_a_rate_or_a_step_that_is_a_slew_not_a_guide_pulse():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        errors = []
        for params in ({"north_arcsec": 36000.0, "rate_arcsec_s": 1e6},
                       {"north_arcsec": 10.0, "rate_arcsec_s": 1e6},
                       {"north_arcsec": 3600.0}):
            with pytest.raises(VssRequestError) as exc:
                await c.request("guide", params)
            errors.append(exc.value)
        return errors

    for err in run_lockstep_scenario(START, scenario):
        assert err.code == "bad_request" and ("rate_arcsec_s" in err.message
                                              or "slew instead" in err.message)


@pytest.mark.parametrize(("command", "params", "north", "east"), [
    ("guide", {"north_arcsec": 30.0}, 30.0, 0.0),
    ("offset", {"axis": "ra", "op": "set", "arcsec": -12.0}, 0.0, -12.0),
], ids=["guide-pulse", "offset"])
def test_a_correction_given_while_the_track_is_still_slewing_is_part_of_the_place_it_joins(
        command, params, north, east):
    site = load_site()

    async def scenario(vss, clock):
        c = vss.client()
        op = await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG,
                                       "answer_on_accept": True})
        assert op["phase"] in ("starting", "preparing")
        await c.request(command, params)
        while (await c.request("status"))["operation"]["phase"] != "tracking":
            await clock.sleep(1.0)
        await clock.sleep(5.0)
        return [await encoders(vss) for _ in range(3)]

    az, el, t_us = (np.array(x) for x in zip(*run_lockstep_scenario(START, scenario), strict=True))
    cos_dec = math.cos(math.radians(DEC_DEG))
    shifted = radec_truth(RA_DEG + east / 3600 / cos_dec, DEC_DEG + north / 3600, t_us, site)
    assert sky_sep_arcsec(az, el, *shifted).max() < 0.3


def test_a_night_of_pulses_keeps_a_bounded_history_without_moving_the_path(monkeypatch):
    from virtualstar.server import offsets as offsets_module
    from virtualstar.server.guiding import pulse_change

    rng = np.random.default_rng(3)
    kept = offsets_module.Offsets()
    with monkeypatch.context() as m:
        m.setattr(offsets_module, "KEEP_HISTORY_US", 10**15)  # the reference keeps everything
        reference = offsets_module.Offsets()
        t0 = 1_700_000_000_000_000
        pulses = [(t0 + k * 2_000_000, *rng.normal(0, 2, 2)) for k in range(500)]
        for t, n, e in pulses:
            pulse_change(float(n), float(e), 7.52)(reference, t, None)
    for t, n, e in pulses:
        pulse_change(float(n), float(e), 7.52)(kept, t, None)
    assert len(kept.axes["dec"].t_us) < 400 < len(reference.axes["dec"].t_us)
    # the history kept (30 s before the newest change) and the future are the same
    later = np.arange(pulses[-1][0] - 25_000_000, pulses[-1][0] + 5_000_000, 1_000_000)
    for axis in ("ra", "dec"):
        assert np.allclose(kept.axes[axis].sample(later), reference.axes[axis].sample(later),
                           rtol=0, atol=1e-9)
    north = sum(n for _, n, _ in pulses)
    assert kept.axes["dec"].at(pulses[-1][0] + 10_000_000)[0] == pytest.approx(north, abs=1e-6)


def test_move_toward_the_sun_comes_to_rest_outside_its_zone():
    from astropy.coordinates import get_body
    from astropy.time import Time

    from virtualstar.astro import UtcTimes

    site = load_site()
    day = "2024-05-18T10:00:00Z"

    def sun_place(t_us: int) -> tuple[float, float]:
        aa = get_body("sun", Time(t_us / 1e6, format="unix", scale="utc")).transform_to(
            observed_frame([t_us], site))
        return float(aa.az.deg[0]), float(aa.alt.deg[0])

    sun_az, sun_el = sun_place(int(UtcTimes.from_iso([day]).to_unix_us()[0]))

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": (sun_az - 70.0) % 360.0, "el_deg": sun_el})
        op = await c.request("move", {"az_rate_deg_s": 2.0})
        done = await c.request("wait", {"id": op["id"]})
        return done, await encoders(vss)

    done, (az, el, t_us) = run_lockstep_scenario(day, scenario)
    assert done["phase"] == "done" and "Sun" in done["info"]["ended"]
    sep_deg = float(sky_sep_arcsec(az, el, *sun_place(t_us))) / 3600
    assert 30.0 <= sep_deg < 33.0  # at rest just outside the 30° zone, not far short of it
