"""The checks of the `sky` part, shared by test_alpaca_sky.py and test_indi_sky.py: a star
(slew, landing, sidereal track against astropy, the recorder), `vs run` of a small plan,
the Sun refused and a slew routed round it (see scenario_run.py for how the part runs).

Truth: every place the simulator reported, recorded with its time by an independent
client (ASCOM's alpyca, indipyclient), against astropy's topocentric apparent place of
date (truth.py). The 10-minute sidereal track and the tight figures are the benchmark's
(benchmarks/bench_backends.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from truth import _eop, _site, observed_azel_deg, sky_errors_arcsec, star_apparent

__all__ = ["test_the_backend_reads_geometry_and_rates_from_the_driver",
           "test_a_star_is_reached_and_tracked_on_astropys_place",
           "test_the_sun_is_refused_before_anything_moves",
           "test_a_slew_past_the_sun_goes_round_its_zone",
           "test_vs_run_of_a_small_plan_on_the_simulator",
           "test_the_recorder_records_the_backends_reports_rates_and_errors",
           "test_an_offset_during_a_track_moves_the_mount_by_that_much"]


def test_the_backend_reads_geometry_and_rates_from_the_driver(seen):
    caps = seen["connected"]["capabilities"]
    assert caps["backend"] == seen["kind"]
    assert caps["rate_axes"] and not caps["trajectory_buffer"] and caps["goto"]
    assert caps["native_axes"] == ["ra", "dec"]
    if seen["kind"] == "alpaca":  # AlignmentMode 1 (polar), MoveAxis up to 10°/s
        assert caps["geometry"] == "fork" and caps["max_rate_deg_s"] == pytest.approx(10.0)
    else:  # TELESCOPE_PIER_SIDE: German; ±16 384″/s less the sidereal rate
        assert caps["geometry"] == "german"
        assert caps["max_rate_deg_s"] == pytest.approx((16384 - 15.041) / 3600, rel=1e-3)
    final = seen["final_backend"]
    # measured: Alpaca reads ~20/s, INDI pushes every 250 ms (a still place is not pushed)
    assert final["report_rate_hz"] > 2.0 and 0 <= final["reported"]["age_s"] < 60.0
    assert final["driver_site"]["lat_deg"] == pytest.approx(seen["site"]["lat_deg"])


def test_a_star_is_reached_and_tracked_on_astropys_place(seen):
    op = seen["star_op"]
    assert op["phase"] == "done", op
    info = op["info"]
    samples = [s for s in seen["star_samples"]
               if s[0] * 1e6 >= info["tracking_from_us"] and s[0] * 1e6 <= info["tracking_to_us"]]
    # Alpaca is read 20 times a second; INDI pushes a place only when it has changed (a
    # well-held star: every second or two)
    assert len(samples) >= 4
    t = np.array([s[0] for s in samples])
    err = sky_errors_arcsec(samples, star_apparent(seen["star"], t, seen))
    assert np.sqrt(np.mean(err**2)) < 3.0 and err.max() < 15.0, err
    assert info["landing_error_arcsec"] < 10.0
    assert info["on_sky_rms_arcsec"] < 3.0  # the VSS's own figure agrees


def test_the_sun_is_refused_before_anything_moves(seen):
    assert seen["sun_refusal"]["code"] == "exclusion_zone", seen["sun_refusal"]
    assert "Sun" in seen["sun_refusal"]["message"]


def test_a_slew_past_the_sun_goes_round_its_zone(seen):
    op = seen["route_op"]
    assert op["phase"] == "done", op
    assert op["info"].get("detour_deg"), "the straight path crossed the zone: a detour is due"
    from virtualstar.astro import SolarSystemBody, observe_mount_times

    s = np.asarray(seen["route_samples"], float)
    az, el = observed_azel_deg(s, seen)
    t_us = (s[:, 0] * 1e6).astype(np.int64)
    sun = observe_mount_times(SolarSystemBody("sun"), t_us, _site(seen), _eop())
    sep = np.degrees(np.arccos(np.clip(
        np.sin(np.radians(el)) * np.sin(sun.el_rad) + np.cos(np.radians(el))
        * np.cos(sun.el_rad) * np.cos(np.radians(az) - sun.az_rad), -1, 1)))
    assert sep.min() > 30.0, f"came within {sep.min():.2f}° of the Sun"
    end_az, end_el = seen["route_ends"][1]
    assert math.hypot((az[-1] - end_az + 180) % 360 - 180, el[-1] - end_el) < 0.05


def test_vs_run_of_a_small_plan_on_the_simulator(seen):
    run = seen["run"]
    assert run["plan_exit"] == 0 and run["run_exit"] == 0, run.get("stderr")
    blocks = run["record"]["records"]
    assert len(blocks) == 1 and blocks[0]["outcome"] == "done", blocks
    assert blocks[0]["on_sky_rms_arcsec"] < 3.0


def test_the_recorder_records_the_backends_reports_rates_and_errors(seen):
    """`vs server --signals` serves each report as an ASTCom tick; `vs record` stores them at
    the rate the driver reports, and the stored places are the simulator's own."""
    rec = seen["recorded"]
    assert rec["record_exit"] == 0 and rec["query_exit"] == 0, rec
    data = rec["data"]
    t_all = np.asarray(data["t_us"], np.int64) / 1e6
    assert len(t_all) >= 10 and np.all(np.diff(t_all) > 0)
    # at the rate reports come (a still star: each read, or each wait for a push), at
    # least one a second
    assert np.median(np.diff(t_all)) < 1.0, np.diff(t_all)
    info = seen["star_op"]["info"]
    inside = (t_all * 1e6 >= info["tracking_from_us"]) & (t_all * 1e6 <= info["tracking_to_us"])
    assert inside.sum() >= 5, "the recording overlapped the track"
    t = t_all[inside]
    ra = np.asarray(data["values"]["report.ra_deg"], float)[inside]
    dec = np.asarray(data["values"]["report.dec_deg"], float)[inside]
    err = np.asarray(data["values"]["error.sky_arcsec"], float)[inside]  # null: not following
    # each stored place is where the simulator was: astropy's star at that time, as tracked
    truth = star_apparent(seen["star"], t, seen)
    sky = sky_errors_arcsec(np.column_stack([t, ra / 15.0, dec]), truth)
    assert np.median(sky) < 3.0, sky
    # the error signal is the VSS's own measure of the same thing, while it follows
    assert np.isfinite(err).mean() > 0.8 and np.nanmedian(err) < 3.0, err


def test_an_offset_during_a_track_moves_the_mount_by_that_much(seen):
    """`offset dec add 60″` (PWI4-style, issue 28) on a rate mount: the loop follows the
    offset path, so the simulator's reported place is 60″ north of astropy's star once
    the offset is reached (and the loop has taken it up), and on the star before it."""
    off = seen["offset"]
    answer = off["answer"]
    assert answer["offsets"]["axes"]["dec"]["goal_arcsec"] == pytest.approx(off["arcsec"])
    s = np.asarray(off["samples"], float)
    ra, dec = star_apparent(seen["star"], s[:, 0], seen)
    d_ra = ((s[:, 1] * 15.0 - ra + 180.0) % 360.0 - 180.0) * np.cos(np.radians(dec)) * 3600
    d_dec = (s[:, 2] - dec) * 3600
    from_s, reached_s = answer["from_us"] / 1e6, answer["reached_us"] / 1e6
    tracking_s = off["op_before_stop"]["info"]["tracking_from_us"] / 1e6
    # on the star before: the places reported since the landing check (INDI pushes a place
    # only when it changed, so the last one before the offset stands for the time since)
    last_s = s[s[:, 0] < from_s, 0].max() if (s[:, 0] < from_s).any() else from_s
    before = (s[:, 0] < from_s) & (s[:, 0] >= min(tracking_s, last_s))
    # the loop takes a step up in about 8 report periods (60 % of the error per period):
    # judged from 10 periods (at least 2.5 s: a loaded host delays it) after it is reached
    period_s = 1.0 / seen["final_backend"]["report_rate_hz"]
    after = s[:, 0] > reached_s + max(2.5, 10 * period_s)
    # (INDI pushes nothing once the mount holds the offset place: its last push stands)
    assert before.sum() >= 1 and after.sum() >= 1, (before.sum(), after.sum())
    assert np.abs(d_dec[before]).max() < 3.0 and np.abs(d_ra[before]).max() < 3.0
    # the place it holds (the last reported) is the offset one; on the way there, converging
    assert abs(d_dec[-1] - off["arcsec"]) < 3.0 and abs(d_ra[-1]) < 3.0, (d_ra[-1], d_dec[-1])
    assert np.abs(d_dec[after] - off["arcsec"]).max() < 10.0, np.round(d_dec[after], 2)
    assert np.abs(d_ra[after]).max() < 10.0, np.round(d_ra[after], 2)
