"""The checks of the `pass` part, shared by test_alpaca_pass.py and test_indi_pass.py: an
ISS-like pass against skyfield, `stop` mid-pass (fixture `seen`, the pass part); the
driver killed mid-track (`seen_kill`, the kill part, run at once beside it on its own
simulator; see scenario_run.py for how the parts run).

Truth: every place the simulator reported, recorded with its time by an independent
client (ASCOM's alpyca, indipyclient), against skyfield's topocentric apparent place of
date of the same TLE (truth.py). The bounds hold on a loaded host: a report's time is
known to a few milliseconds there, which at the satellite's ~1°/s is tens of arcseconds;
the tight figures are the benchmark's (benchmarks/bench_backends.py).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import theilslopes
from truth import hour_angles_deg, satellite_apparent, sky_errors_arcsec

__all__ = ["test_an_iss_pass_is_followed_on_skyfields_place",
           "test_stop_mid_pass_leaves_the_mount_at_rest",
           "test_a_driver_killed_mid_track_ends_the_track_with_a_fault_and_no_runaway"]


def test_an_iss_pass_is_followed_on_skyfields_place(seen):
    before = seen["pass_op_before_stop"]
    assert before["phase"] == "tracking", before
    info = before["info"]
    start = info["tracking_from_us"] / 1e6 + 2.0  # backend_scenario.PASS_SETTLE_S
    samples = [s for s in seen["pass_samples"] if start <= s[0] <= seen["stop_sent_s"]]
    assert len(samples) >= 20  # the scenario follows the pass until it has them
    t = np.array([s[0] for s in samples])
    err = sky_errors_arcsec(samples, satellite_apparent(seen["tle"], t, seen))
    # the reports' own times are known to milliseconds here; the satellite moves ~1°/s
    assert np.median(err) < 60.0, np.round(err, 1)
    assert np.percentile(err, 90) < 300.0, np.round(err, 1)
    assert info["culmination_el_deg"] > 60.0
    # the satellite moved fast while it was followed (near culmination: about 1°/s)
    ra, dec = satellite_apparent(seen["tle"], t, seen)
    ra2, dec2 = satellite_apparent(seen["tle"], t + 1.0, seen)
    rate = np.hypot(((ra2 - ra + 180) % 360 - 180) * np.cos(np.radians(dec)), dec2 - dec)
    assert rate.max() > 0.3, rate.max()
    if seen["connected"]["capabilities"]["geometry"] == "german":
        # never flipped mid-track: the whole tracked stretch on one side of the meridian
        ha = hour_angles_deg(samples, seen)
        assert np.all(ha > 0) or np.all(ha < 0), np.round(ha, 2)


def test_stop_mid_pass_leaves_the_mount_at_rest(seen):
    assert seen["stop_result"]["mount_state"] == "holding"
    assert seen["pass_op"]["phase"] == "aborted"
    after = [s for s in seen["pass_samples"] if s[0] > seen["stop_sent_s"]
             + seen["stop_answered_s"]]
    assert len(after) >= 4
    assert_at_rest(after, seen)


# A place stamped late by its observing client (a loaded host: a push read 0.35 s late was
# seen) has its hour angle off by the sky's 15″ per second of delay, that sample alone
REST_DRIFT_ARCSEC = 5.0  # the axes moved less than this over the samples
STAMP_SPREAD_ARCSEC = 15.0  # a sample stamped up to a second late


def assert_at_rest(samples, seen) -> None:
    """At rest: the hour angle and declination stand still (the place of date drifts with
    the sky, the axes do not). The hour angle's drift is the robust (Theil–Sen) slope over
    the samples' span, so that one late stamp does not count as motion, while any rate
    left on (tracking: 15″/s) does; each sample also lies within a second's stamping delay
    of that line."""
    s = np.asarray(samples, float)
    t = s[:, 0] - s[0, 0]
    dec_arcsec = s[:, 2] * 3600
    ha_arcsec = hour_angles_deg(samples, seen) * 3600 * math.cos(math.radians(s[0, 2]))
    assert np.ptp(dec_arcsec) < REST_DRIFT_ARCSEC, np.round(dec_arcsec - dec_arcsec[0], 2)
    slope, intercept, _, _ = theilslopes(ha_arcsec, t)
    shown = np.round(ha_arcsec - ha_arcsec[0], 2)
    assert abs(slope) * t[-1] < REST_DRIFT_ARCSEC, (slope, t.round(2), shown)
    off_line = np.abs(ha_arcsec - (intercept + slope * t))
    assert off_line.max() < STAMP_SPREAD_ARCSEC, (t.round(2), shown)


def test_a_driver_killed_mid_track_ends_the_track_with_a_fault_and_no_runaway(seen_kill):
    seen = seen_kill  # the kill part (run beside the pass's, scenario_run.py)
    op = seen["kill_op"]
    assert op["phase"] == "failed", op
    assert op["info"]["error"]["code"] == "mount_fault", op["info"]["error"]
    assert seen["kill_fault_after_s"] < 15.0
    # between the kill and the fault: at most the rate commands already on their way, then
    # "stop"; after the fault nothing at all, and nothing resumed after the restart
    calls = seen["calls_after_kill"]
    # (INDI: a silent pushing driver counts as unchanged while the commanded rates could
    # have moved it < 1″, so one more cycle may command before the closed connection shows)
    assert calls.count("set_rates") <= 2 and set(calls) <= {"set_rates", "stop"}, calls
    after = seen["after_restart"]
    assert after["operation"]["id"] == op["id"] and after["operation"]["phase"] == "failed"
    assert after["calls"] == [], after["calls"]
    assert after["status"]["commanded_rates_arcsec_s"] == [0.0, 0.0]
    samples = after["samples"]
    if len(samples) >= 2:  # the restarted simulator reports from where it starts: at rest
        assert_at_rest(samples, seen)

