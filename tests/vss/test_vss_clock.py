"""Clock truth: the mount clock on UTC in real time and in lockstep, and what an offset costs.

The independent truth is the emulator's own UTC (``time.true_us``: what its PPS
marks), read at the same tick as its mount clock (``time.mount_us``) straight
from the emulator over ASTCom, and in real time the host clock around the start.
"""

from __future__ import annotations

import time

import pytest
from sky_truth import vega_rate_arcsec_s
from vss_rig import Rig

from astcom_client import Client
from virtualstar.astro import UtcTimes, load_site
from virtualstar.vss_client import call_server

ONE_MS_US = 1000
START = "2024-05-18T19:40:00Z"


async def clock_reading(rig: Rig) -> dict[str, int]:
    """Return mount clock, UTC truth, their difference and the tick, all of one tick."""
    async with await Client.connect(rig.emulator.url) as c:
        v, tick, _ = await c.read_at(["time.mount_us", "time.true_us", "time.sync_count"])
    return {"mount_us": int(v["time.mount_us"]), "true_us": int(v["time.true_us"]),
            "offset_us": int(v["time.mount_us"]) - int(v["time.true_us"]), "tick": int(tick),
            "syncs": int(v["time.sync_count"])}


async def arm_wrong_second(rig: Rig, seconds_off: int) -> None:
    """Arm a wrong UTC second behind the VSS's back (an operator's mistake, a bad GPS)."""
    async with await Client.connect(rig.emulator.url) as c:
        v, _, _ = await c.read_at(["time.true_us"])
        await c.invoke("time.set_utc", int(v["time.true_us"]) // 1_000_000 + 1 + seconds_off)


def wait_for(rig: Rig, condition, timeout_s: float = 30.0) -> dict[str, int]:
    """Poll the emulator's clock until `condition(reading)`; return that reading."""
    deadline = time.monotonic() + timeout_s
    r = rig.run(clock_reading(rig))
    while not condition(r):
        assert time.monotonic() < deadline, f"the clock never got there: {r}"
        time.sleep(0.05)
        r = rig.run(clock_reading(rig))
    return r


def test_in_real_time_the_mount_clock_starts_on_host_utc_and_timesync_holds_it_within_1_ms():
    before_us = time.time_ns() // 1000
    rig = Rig(start_us=None, realtime=True, site=load_site(), timesync_period_s=1.0).start()
    after_us = time.time_ns() // 1000
    try:
        first = rig.run(clock_reading(rig))
        # tick k is due at anchor + k·100 µs: the anchor is host UTC at the loop's start
        anchor_us = first["true_us"] - first["tick"] * 100
        assert before_us - 100 <= anchor_us <= after_us
        timesync = rig.server.telescope.timesync
        timesync.active = False  # TimeS only measures while the wrong second is armed
        rig.run(arm_wrong_second(rig, -3))
        r = wait_for(rig, lambda r: r["offset_us"] < -2_900_000)
        timesync.active = True
        r = wait_for(rig, lambda r: abs(r["offset_us"]) <= ONE_MS_US)
        deadline = time.monotonic() + 10.0
        while (ts := call_server(rig.url, "status")["time_sync"])["syncs"] < r["syncs"]:
            assert time.monotonic() < deadline, ts  # TimeS measures just after the edge
            time.sleep(0.05)
        assert ts["mode"] == "sync to host utc" and ts["armed"] >= 1 and ts["syncs"] >= 2
        assert ts["offset_source"] == "utc truth"
        # the status reports the offset the mount really has, and no whole-second PPS error
        r = rig.run(clock_reading(rig))
        assert abs(ts["offset_us"]) <= ONE_MS_US and abs(r["offset_us"]) <= ONE_MS_US
        # the PPS error is the clock's error at an edge, before that edge's sync: the edge
        # that applied the repair still saw −3 s; from the next one on it is drift only
        while abs((ts := call_server(rig.url, "status")["time_sync"])["pps_error_us"]) > ONE_MS_US:
            assert time.monotonic() < deadline + 10.0, ts
            time.sleep(0.05)
        assert abs(ts["offset_us"]) <= ONE_MS_US
    finally:
        rig.close()


@pytest.fixture(scope="module")
def drifting():
    start_us = int(UtcTimes.from_iso([START]).to_unix_us()[0])
    # a crystal 20 ppm off: 12 ms in 10 minutes without syncs, 200 µs between two syncs
    rig = Rig(start_us=start_us, site=load_site(), pace=None,
              emulator_options={"params": {"time.drift_ppm": 20.0}}).start()
    yield rig
    rig.close()


def test_in_lockstep_timesync_puts_a_mount_clock_3_s_off_back_within_1_ms_and_keeps_it(drifting):
    rig = drifting

    async def scenario():
        rig.server.telescope.timesync.active = False
        await arm_wrong_second(rig, -3)
        await rig.mount_sleep(1.2)
        off = await clock_reading(rig)
        rig.server.telescope.timesync.active = True
        readings = []
        for _ in range(60):  # ten minutes of mount time
            await rig.mount_sleep(10.0)
            readings.append(await clock_reading(rig))
        return off, readings, await rig.server.call("status")

    off, readings, st = rig.run(scenario())
    assert off["offset_us"] < -2_900_000
    after_first_sync = readings[1:]
    assert max(abs(r["offset_us"]) for r in after_first_sync) <= ONE_MS_US
    assert readings[-1]["syncs"] >= 50  # one per period (10 s + the wait for mid-second)
    ts = st["time_sync"]
    assert ts["mode"] == "sync to utc truth" and abs(ts["offset_us"]) <= ONE_MS_US
    assert abs(ts["pps_error_us"]) <= ONE_MS_US  # the last edge before its sync: drift only


def test_the_on_sky_error_adds_the_clock_offset_times_the_target_rate(drifting):
    """Tracking Vega with a clock 3 s off: the sky error is ≈ 3 s × Vega's rate, the encoders' is not."""
    rig = drifting
    rig.server.telescope.timesync.active = False  # nobody corrects the clock during this test

    async def scenario():
        try:
            await arm_wrong_second(rig, -3)
            await rig.mount_sleep(1.2)
            await rig.server.telescope.timesync.verify()
            op = await rig.server.call("track", {"star": "Vega", "duration_s": 20.0,
                                                 "wait": True})
            return op, await clock_reading(rig)
        finally:
            rig.server.telescope.timesync.active = True

    op, reading = rig.run(scenario())
    info = op["info"]
    assert abs(reading["offset_us"] + 3_000_000) < 20_000
    # Vega's on-sky rate from astropy, over the 3 s the mount clock is behind
    expected = vega_rate_arcsec_s(info["tracking_from_us"], rig.site) * 3.0
    assert 10.0 < expected < 50.0
    assert info["tracking_rms_arcsec"] < 0.1
    assert info["on_sky_rms_arcsec"] == pytest.approx(expected, rel=0.05)
    assert info["on_sky_peak_arcsec"] >= info["on_sky_rms_arcsec"]


def test_a_lockstep_clock_with_an_idle_pace_runs_ahead_only_while_a_client_waits():
    """Idle: never faster than the idle pace (an upper bound, whatever the host's load);
    inside `awaited()`: as fast as the CPU allows, so an hour passes within the timeout."""
    import asyncio
    import time

    from virtualstar.lockstep import LockstepClock, run_lockstep

    clock = LockstepClock(1_716_061_200_000_000, idle_pace=1.0)

    async def main():
        assert clock.pace == 1.0
        wall0, t0 = time.monotonic(), clock.now_us
        await clock.sleep(0.3)
        idle_wall = time.monotonic() - wall0
        idle_mount = (clock.now_us - t0) / 1e6
        with clock.awaited():
            assert clock.pace is None
            await asyncio.wait_for(clock.sleep(3600.0), timeout=60.0)
        assert clock.pace == 1.0  # idle again
        return idle_mount, idle_wall

    idle_mount, idle_wall = run_lockstep(main(), clock)
    assert 0.3 <= idle_mount <= idle_wall * 1.0 + 0.01
