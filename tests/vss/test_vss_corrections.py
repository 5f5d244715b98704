"""Corrections in real time: guide pulses and offsets act 20 ms after acceptance (replace_from).

Lockstep emulator + VSS. What the mount did comes from the test's own 10 kHz stream of
the emulator (the trajectory reference the controller follows and the encoders); where
the target is comes from astropy (stars) and skyfield (the ISS), computed here. The
emulator's geometry is perfect and no pointing model is loaded, so encoder = observed.
"""

from __future__ import annotations

import numpy as np
import pytest
from signal_recording import recording
from sky_truth import iss_truth, radec_truth, sky_sep_arcsec
from vss_rig import mapping_without, run_lockstep_scenario

from virtualstar.astro import load_site
from virtualstar.vss_client import VssRequestError

START = "2024-05-18T21:00:00Z"  # night at Poznań
RA_DEG, DEC_DEG = 250.0, 36.5  # near M13, high in the east
REF = ["traj.ref_az", "traj.ref_el", "axis.az.position", "axis.el.position"]
ISS_PASS_START = "2024-05-18T19:49:00Z"  # two minutes before the ISS rises (80° pass)


def _deg(rad: np.ndarray) -> np.ndarray:
    return np.degrees(rad) % 360.0


def test_a_guide_pulse_acts_within_50_ms_of_its_acceptance_and_moves_the_size_asked():
    site = load_site()
    north = 3.76  # a 0.5 s pulse at the ASCOM default guide rate (half sidereal)

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        await clock.sleep(3.0)
        async with recording(vss, REF, clock=clock) as rec:
            await clock.sleep(0.5)
            pulse = await c.request("guide", {"north_arcsec": north, "rate_arcsec_s": 7.52})
            await clock.sleep(2.0)
        return pulse, rec

    pulse, rec = run_lockstep_scenario(START, scenario)
    t = rec.t_us
    true_az, true_el = radec_truth(RA_DEG, DEC_DEG, t, site)
    demand = sky_sep_arcsec(_deg(rec["traj.ref_az"]), np.degrees(rec["traj.ref_el"]), true_az,
                            true_el)
    accepted = pulse["accepted_us"]
    before = demand[(t > accepted - 400_000) & (t <= accepted)]
    assert len(before) > 3000 and before.max() < 0.01  # on the star to 10 mas before
    moved = t[(t > accepted) & (demand > before.max() + 0.005)]
    first_effect_ms = (moved[0] - accepted) / 1000
    assert pulse["sent"] == "replace_from" and pulse["lead_ms"] == pytest.approx(20.0)
    assert 20.0 <= first_effect_ms <= 50.0
    # the size: the encoders, settled, against the star and the star 3.76″ north
    settled = t > pulse["end_us"] + 300_000
    enc_az, enc_el = _deg(rec["axis.az.position"][settled]), np.degrees(rec["axis.el.position"][settled])
    off = sky_sep_arcsec(enc_az, enc_el, true_az[settled], true_el[settled])
    assert off.mean() == pytest.approx(north, rel=0.02)
    shifted = radec_truth(RA_DEG, DEC_DEG + north / 3600.0, t[settled], site)
    assert sky_sep_arcsec(enc_az, enc_el, *shifted).max() < 0.02 * north


def test_an_offset_add_of_30_arcsec_is_reached_within_the_rate_and_acceleration_limits():
    site = load_site()
    rate, accel = 20.0, 40.0  # tight limits, so that both bind on a 30″ move

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        await clock.sleep(3.0)
        async with recording(vss, REF, clock=clock) as rec:
            await clock.sleep(0.3)
            answer = await c.request("offset", {"axis": "el", "op": "add", "arcsec": 30.0})
            await clock.sleep(3.5)
            status = await c.request("status")
        log = await c.request("log", {"since": 0})
        return answer, status, rec, log

    answer, status, rec, log = run_lockstep_scenario(
        START, scenario, offset_rate_arcsec_s=rate, offset_accel_arcsec_s2=accel)
    t = rec.t_us
    true_az, true_el = radec_truth(RA_DEG, DEC_DEG, t, site)
    el_off = (np.degrees(rec["traj.ref_el"]) - true_el) * 3600.0
    az_off = ((np.degrees(rec["traj.ref_az"]) - true_az + 180.0) % 360.0 - 180.0) * 3600.0
    assert np.abs(az_off).max() < 0.01  # only elevation moved
    # 0.5 s up to 20″/s, 1 s at it, 0.5 s down: 2 s, from 20 ms after acceptance
    assert answer["from_us"] - answer["accepted_us"] == 20_000
    assert (answer["reached_us"] - answer["from_us"]) / 1e6 == pytest.approx(2.0, abs=1e-3)
    assert np.abs(el_off[t <= answer["from_us"]]).max() < 0.005
    assert el_off[t >= answer["reached_us"]] == pytest.approx(30.0, abs=0.005)
    w = 100  # 10 ms windows
    speed = np.diff(el_off[::w]) / (np.diff(t[::w]) * 1e-6)
    assert speed.max() <= rate * 1.005 and speed.max() > rate * 0.99
    acc = np.diff(speed) / (np.diff(t[::w])[1:] * 1e-6)
    assert np.abs(acc).max() <= accel * 1.05
    doc = status["corrections"]
    assert doc["mode"] == "replace_from" and doc["min_lead_ms"] == 20.0
    assert doc["offsets"]["axes"]["el"]["total_arcsec"] == pytest.approx(30.0)
    assert set(doc["offsets"]["axes"]) == {"el"}
    # logged once, with what was asked and when and how it reaches the mount
    [event] = [e for e in log["events"] if e["kind"] == "offset"]
    assert event["fields"] == {"id": answer["id"], "axis": "el", "op": "add", "arcsec": 30.0,
                               "from_us": answer["from_us"], "lead_ms": 20.0,
                               "sent": "replace_from"}
    assert answer["accepted_us"] - 200_000 <= event["t_us"] <= answer["from_us"]
    assert "offset el add +30″" in event["message"]


def test_path_offset_puts_the_boresight_where_skyfield_has_the_iss_1_5_s_later():
    site = load_site()

    async def scenario(vss, clock):
        c = vss.client()
        tle = (__import__("catalogs").sample_tle_path("stations")).read_text()
        await c.request("track", {"tle": tle, "sat": "ISS"})
        while (await c.request("status"))["operation"]["phase"] != "tracking":
            await clock.sleep(1.0)
        await clock.sleep(200.0)  # high in the sky: the air bends both truth and demand alike
        answer = await c.request("offset", {"axis": "path", "op": "add", "seconds": 1.5})
        await clock.sleep(max(0.0, (answer["reached_us"] - answer["from_us"]) / 1e6) + 2.0)
        async with recording(vss, REF, rate_hz=20.0, clock=clock) as rec:
            await clock.sleep(10.0)
        return answer, rec

    answer, rec = run_lockstep_scenario(ISS_PASS_START, scenario)
    t = rec.t_us
    enc_az, enc_el = _deg(rec["axis.az.position"]), np.degrees(rec["axis.el.position"])
    later = iss_truth(t + 1_500_000, site)
    now = iss_truth(t, site)
    assert answer["sent"] == "replace_from"
    assert enc_el.min() > 30.0
    assert sky_sep_arcsec(enc_az, enc_el, *later).max() < 0.5
    assert sky_sep_arcsec(enc_az, enc_el, *now).min() > 1000.0  # 1.5 s of an ISS pass


def test_stop_ends_everything_and_leaves_no_offset_behind():
    site = load_site()

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        await c.request("offset", {"axis": "transverse", "op": "add", "arcsec": 20.0})
        await c.request("offset", {"axis": "dec", "op": "rate", "arcsec": 1.0})
        await clock.sleep(3.0)
        with_offsets = await c.request("status")
        await c.request("stop")
        stopped = await c.request("status")
        with pytest.raises(VssRequestError) as refused:
            await c.request("offset", {"axis": "ra", "arcsec": 5.0})
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        await clock.sleep(3.0)
        async with recording(vss, REF, rate_hz=20.0, clock=clock) as rec:
            await clock.sleep(2.0)
        return with_offsets, stopped, refused.value, await c.request("status"), rec

    with_offsets, stopped, refused, again, rec = run_lockstep_scenario(START, scenario)
    assert set(with_offsets["corrections"]["offsets"]["axes"]) == {"transverse", "dec"}
    assert "offsets" not in stopped["corrections"]
    assert refused.code == "not_tracking"
    assert "offsets" not in again["corrections"] or not again["corrections"]["offsets"]["axes"]
    t = rec.t_us
    err = sky_sep_arcsec(_deg(rec["axis.az.position"]), np.degrees(rec["axis.el.position"]),
                         *radec_truth(RA_DEG, DEC_DEG, t, site))
    assert err.max() < 0.1


def test_a_controller_without_replace_from_falls_back_to_appending_and_says_so(tmp_path):
    site = load_site()
    mapping = mapping_without(tmp_path, "traj_replace")

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        await clock.sleep(3.0)
        status = await c.request("status")
        pulse = await c.request("guide", {"north_arcsec": 5.0, "rate_arcsec_s": 7.52})
        await clock.sleep((pulse["end_us"] - pulse["accepted_us"]) / 1e6 + 2.0)
        async with recording(vss, REF, rate_hz=20.0, clock=clock) as rec:
            await clock.sleep(1.0)
        return status, pulse, rec

    status, pulse, rec = run_lockstep_scenario(START, scenario, mapping_path=mapping, lead_s=5.0)
    doc = status["corrections"]
    assert doc["mode"] == "append-only" and "traj_replace" in doc["note"]
    assert pulse["sent"] == "appended"
    assert pulse["lead_ms"] > 4000.0  # after the 5 s of points already buffered
    t = rec.t_us
    enc = _deg(rec["axis.az.position"]), np.degrees(rec["axis.el.position"])
    shifted = radec_truth(RA_DEG, DEC_DEG + 5.0 / 3600.0, t, site)
    assert sky_sep_arcsec(*enc, *shifted).max() < 0.1  # it still arrives, only later


def test_offset_commands_with_a_wrong_axis_op_or_value_are_refused_with_the_valid_ones():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("track", {"ra_deg": RA_DEG, "dec_deg": DEC_DEG})
        errors = []
        for params in ({"axis": "x", "arcsec": 1.0}, {"axis": "ra", "op": "spin", "arcsec": 1.0},
                       {"axis": "ra", "arcsec": 1e9}, {"axis": "ra", "seconds": 1.0},
                       {"axis": "path", "seconds": 300.0}, {"axis": "ra"},
                       {"axis": "ra", "arcsec": 1.0, "seconds": 1.0},
                       {"axis": "ra", "op": "rate", "arcsec": 1e5},
                       {"axis": "all", "op": "add", "arcsec": 1.0},
                       {"axis": "ra", "arcsec": float("nan")}):
            with pytest.raises(VssRequestError) as exc:
                await c.request("offset", params)
            errors.append(exc.value)
        return errors

    errors = run_lockstep_scenario(START, scenario)
    assert all(e.code == "bad_request" for e in errors), [(e.code, e.message) for e in errors]
    assert "ra, dec, az, el, path, transverse" in errors[0].message
    assert "add, set, rate, reset" in errors[1].message
    assert "from -3600 to 3600 (arcsec)" in errors[2].message
