"""One owner of the mount: replaced operations end first, stop is final, arrival is verified.

Each scenario runs the real VSS and emulator in lockstep simulated time in this
thread (`run_lockstep_scenario`), so it is the same on any host. The truth is read
from the emulator over a connection of the test's own, and Vega's place from astropy.
"""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from sky_truth import sky_sep_arcsec, vega_truth
from vss_rig import read_emulator, run_lockstep_scenario

from virtualstar.astro import load_site
from virtualstar.server.supervisor import operations_of_tasks
from virtualstar.vss_client import VssRequestError

START = "2024-05-18T19:40:00Z"  # Poznań: Vega at ~30° and rising
POSITION = ["axis.az.position", "axis.el.position", "mount.state_name"]
ONE_ARCSEC_RAD = math.radians(1 / 3600)


def live_operation_tasks() -> list[asyncio.Task]:
    """Return the tasks that drive the mount: operations and feeders still running."""
    return [t for t in asyncio.all_tasks() if not t.done()
            and (t.get_name().startswith("vss-op-") or t.get_name() == "vss-feeder")]


def test_a_new_command_ends_the_running_operation_before_it_starts():
    async def scenario(vss, clock):
        vs = vss.client()
        first = await vs.request("track", {"star": "Vega"})
        second = asyncio.ensure_future(vs.request("slew", {"altaz": "120 50"}))
        seen = []
        while not second.done():
            seen.append({t.get_name() for t in live_operation_tasks()})
            await clock.sleep(0.05)
        status = await vs.request("status")
        return first, second.result(), seen, status

    first, second, seen, status = run_lockstep_scenario(START, scenario)
    assert second["id"] == first["id"] + 1 and second["phase"] == "done"
    # never two operations at once: the track's task (and its feeder) ended before the slew's
    for names in seen:
        ops = operations_of_tasks(names)
        assert len(ops) <= 1, names
    assert status["operation"]["id"] == second["id"]
    assert second["info"]["landing_error_arcsec"] < 1.0


def test_after_stop_is_answered_the_mount_holds_still_and_nothing_runs():
    async def scenario(vss, clock):
        vs = vss.client()
        await vs.request("track", {"star": "Vega"})
        answer = await vs.request("stop")
        before, t0 = await read_emulator(vss, POSITION)
        tasks_after = live_operation_tasks()
        await clock.sleep(120.0)  # two minutes of mount time: nobody may move the mount
        after, t1 = await read_emulator(vss, POSITION)
        return answer, before, after, tasks_after, t1 - t0

    answer, before, after, tasks, dt_us = run_lockstep_scenario(START, scenario)
    assert answer == {"mount_state": "holding"}
    assert tasks == []
    assert dt_us >= 119_990_000  # mount time: 120 s of the clock, less its crystal drift
    assert after["mount.state_name"] == "HOLDING"
    for name in POSITION[:2]:
        assert abs(after[name] - before[name]) < ONE_ARCSEC_RAD


def test_a_slew_that_does_not_arrive_is_reported_with_how_far_off_it_is():
    """Another ASTCom client sends the mount elsewhere during the VSS's slew."""
    async def scenario(vss, clock):
        vs = vss.client()
        slew = asyncio.ensure_future(vs.request("slew", {"altaz": "120 50"}))
        await clock.sleep(3.0)
        intruder = await vss.emulator.connect_in_memory(name="another operator")
        await intruder.invoke("mount.slew", 200.0, 30.0)
        await intruder.close()
        with pytest.raises(VssRequestError) as err:
            await slew
        status = await vs.request("status")
        return err.value, status

    error, status = run_lockstep_scenario(START, scenario)
    assert error.code == "not_arrived"
    # the encoders ended at az 200 el 30, about 64° on the sky from az 120 el 50
    expected_deg = math.degrees(float(np.arccos(
        np.sin(np.radians(30)) * np.sin(np.radians(50))
        + np.cos(np.radians(30)) * np.cos(np.radians(50)) * np.cos(np.radians(80)))))
    shown = float(error.message.split("encoders are ")[1].split("°")[0])
    assert shown == pytest.approx(expected_deg, abs=0.05)
    assert status["operation"]["phase"] == "failed"
    assert status["operation"]["info"]["error"]["code"] == "not_arrived"


def test_a_buffer_underrun_is_followed_by_reacquiring_the_star_from_where_the_mount_is():
    """A host stall (the mount link held past the buffered lead) lets the buffer run dry."""
    site = load_site()

    async def scenario(vss, clock):
        vs = vss.client()
        op = await vs.request("track", {"star": "Vega"})
        await clock.sleep(10.0)
        stall_s = vss.server.telescope.margins.feed_lead_s + 8.0
        async with vss.server.telescope.link._lock:  # the feeder cannot push: a frozen host
            await clock.sleep(stall_s)
        resumed = await vs.next_event("resumed", 60.0)
        while (st := await vs.request("status"))["operation"]["phase"] != "tracking":
            await clock.sleep(0.5)
        await clock.sleep(5.0)
        reads = [await read_emulator(vss, POSITION)]
        for _ in range(4):
            await clock.sleep(2.0)
            reads.append(await read_emulator(vss, POSITION))
        await vs.request("stop")
        return op, resumed, st, reads

    op, resumed, st, reads = run_lockstep_scenario(START, scenario, site=site)
    assert resumed["id"] == op["id"]
    info = st["operation"]["info"]
    assert info["resumes"] == 1 and info["interrupted"]["code"] == "tracking_lost"
    assert "ran dry" in info["interrupted"]["message"]  # the mount's underrun counter rose
    t = np.array([r[1] for r in reads])
    az = np.degrees([r[0]["axis.az.position"] for r in reads]) % 360.0
    el = np.degrees([r[0]["axis.el.position"] for r in reads])
    taz, tel = vega_truth(t, site)
    assert sky_sep_arcsec(az, el, taz, tel).max() < 1.0


def test_a_join_made_late_by_a_stalled_host_is_planned_again_not_aborted():
    """The link is held (a frozen host) through the end of the slew: the run-up is missed."""
    site = load_site()

    async def scenario(vss, clock):
        vs = vss.client()
        slew = asyncio.ensure_future(vs.request("slew", {"star": "Vega"}))
        while ((await vs.request("status"))["operation"] or {}).get("phase") != "slewing":
            await clock.sleep(0.1)
        async with vss.server.telescope.link._lock:  # nothing reaches the mount for a minute
            await clock.sleep(60.0)
        op = await slew
        reads = [await read_emulator(vss, POSITION)]
        for _ in range(3):
            await clock.sleep(1.0)
            reads.append(await read_emulator(vss, POSITION))
        await vs.request("stop")
        return op, reads

    op, reads = run_lockstep_scenario(START, scenario, site=site)
    assert op["phase"] == "tracking" and op["info"]["join_plans"] >= 2
    t = np.array([r[1] for r in reads])
    az = np.degrees([r[0]["axis.az.position"] for r in reads]) % 360.0
    el = np.degrees([r[0]["axis.el.position"] for r in reads])
    taz, tel = vega_truth(t, site)
    assert sky_sep_arcsec(az, el, taz, tel).max() < 1.0
