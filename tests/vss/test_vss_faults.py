"""Faults, lost connections and restarts: the server reports, recovers and keeps serving."""

from __future__ import annotations

import asyncio
import json

from typer.testing import CliRunner

from virtualstar.cli.main import app
from virtualstar.vss_client import VssClient

runner = CliRunner()


def test_a_mount_fault_mid_track_stops_tracking_is_reported_and_can_be_reset(rig):
    async def scenario():
        async with await VssClient.connect(rig.url) as vs:
            await vs.request("track", {"star": "Vega"})
            await rig.mount_write({"axis.az.inject_encoder_fault": 1.0})
            fault = await vs.next_event("fault", 10.0)
            while (await vs.next_event("operation", 10.0))["phase"] not in ("aborted", "failed"):
                pass
            op = await vs.request("status")
            await rig.mount_write({"axis.az.inject_encoder_fault": 0.0})
            return fault, op

    fault, st = rig.run(scenario())
    assert "encoder" in fault["faults"]
    assert st["mount_state"] == "fault"
    assert st["operation"]["phase"] in ("aborted", "failed")
    assert st["operation"]["info"]["error"]["code"] == "mount_fault"
    assert "encoder" in st["last_fault"]
    # a new motion is refused with the way out, and the server still answers
    res = runner.invoke(app, ["slew", "--altaz", "120 50", "--server", rig.url])
    assert res.exit_code == 1
    assert "reset the faults" in res.stderr
    res = runner.invoke(app, ["stop", "--reset-faults", "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["mount_state"] in ("off", "holding")
    res = runner.invoke(app, ["slew", "--altaz", "120 50", "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["info"]["landing_peak_arcsec"] < 1.0


def test_a_lost_mount_connection_is_reported_and_the_track_resumes_after_reconnecting(rig):
    async def scenario():
        async with await VssClient.connect(rig.url, silence_s=30.0) as vs:
            op = await vs.request("track", {"star": "Vega"})
            await rig.cut_line()  # the network between the server and the mount breaks
            lost = await vs.next_event("mount_disconnected", 30.0)
            back = await vs.next_event("mount_connected", 30.0)
            resumed = await vs.next_event("resumed", 60.0)
            while (st := await rig.server.call("status"))["operation"]["phase"] != "tracking":
                await rig.mount_sleep(0.5)
            await vs.request("stop")
            return op, lost, back, resumed, st

    op, lost, back, resumed, st = rig.run(scenario())
    assert back["connects"] >= 2
    # the same operation carries on: clients waiting for it keep waiting for it
    assert resumed["id"] == op["id"] and resumed["target"] == "Vega"
    assert st["operation"]["id"] == op["id"] and st["operation"]["phase"] == "tracking"
    assert st["operation"]["info"]["resumes"] == 1
    assert st["operation"]["info"]["interrupted"]["code"] == "mount_offline"


def test_a_client_waiting_for_a_track_follows_it_through_a_lost_connection(rig):
    async def scenario():
        waiting = asyncio.ensure_future(rig.server.call(
            "track", {"star": "Vega", "duration_s": 60.0, "wait": True}))
        await rig.mount_sleep(40.0)  # landed and tracking by now
        await rig.cut_line()
        return await waiting

    op = rig.run(scenario())
    assert op["phase"] == "done" and op["info"]["ended"] == "duration elapsed"
    assert op["info"]["resumes"] == 1
    assert op["info"]["tracking_rms_arcsec"] < 0.1


def test_a_track_whose_own_request_meets_the_cut_line_resumes_too(rig):
    # The line can break inside one of the operation's own mount requests, which then fails
    # with MountUnavailable before the disconnect event arrives. That order is forced
    # here; the operation must be interrupted and run again once the mount is back.
    from virtualstar.server.exceptions import MountUnavailable
    from virtualstar.server.operations import Phase

    supervisor = rig.server.telescope.supervisor
    attempts = []

    async def scenario():
        async def procedure(op):
            attempts.append(op.resumes)
            supervisor.phase(op, Phase.PREPARING)
            if op.resumes == 0:
                await rig.cut_line()
                raise MountUnavailable("lost the mount during a trajectory push")
            supervisor.phase(op, Phase.SLEWING)
            supervisor.phase(op, Phase.SETTLING)
            return {"done_after": op.resumes}

        op = await supervisor.start("test", "cut", procedure, resumable=True)
        await asyncio.wait_for(op.done, 60.0)
        return op

    op = rig.run(scenario())
    assert attempts == [0, 1], op.info
    assert op.phase.label == "done" and op.info["done_after"] == 1
    assert op.info["interrupted"]["code"] == "mount_offline"


def test_a_client_waiting_through_a_server_restart_reconnects_and_is_served(rig):
    host_port = rig.url.rsplit(":", 1)[1]

    async def scenario():
        client = await VssClient.connect(rig.url, reconnect=True, silence_s=3.0)
        try:
            await client.request("status")
            await rig.server.close()
            await rig.start_server(f"ws://127.0.0.1:{host_port}")
            data = await client.next_event("reconnected", 20.0)
            st = await client.request("status")
            return data, st
        finally:
            await client.close()

    data, st = rig.run(scenario())
    assert data["reconnects"] == 1
    assert st["connected"] is True
    # the CLI talks to the restarted server too
    res = runner.invoke(app, ["status", "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output


def test_a_client_that_disconnects_mid_track_does_not_stop_the_tracking(rig):
    async def scenario():
        vs = await VssClient.connect(rig.url)
        await vs.request("track", {"star": "Vega"})
        await vs.close()
        await rig.mount_sleep(40.0)
        async with await VssClient.connect(rig.url) as again:
            st = await again.request("status")
            await again.request("stop")
        return st

    st = rig.run(scenario())
    assert st["mount_state"] == "tracking"
    assert st["operation"]["phase"] == "tracking"
