"""Where the mount answers ASTCom, and how a client's stop is reported (issue 29, defects 1, 4).

`vs server --emulator --endpoint-port P` serves the embedded emulator's ASTCom endpoint on a
fixed port, so that a restarted server is found where it was, and tells its clients where
it is (`mount_endpoint` in `status`, and in `hello` when no password is needed). An
operation that a client's `stop` ended is `aborted` with `info.error.stopped` true, and the
server logs the command it ended as ended (info), not as refused.
"""

from __future__ import annotations

import asyncio
import re
import socket

import pytest
from typer.testing import CliRunner
from vss_rig import Rig, vs_server_process

from astcom_client import Client
from virtualstar.cli.main import app
from virtualstar.server import AccessConfig
from virtualstar.vss_client import VssClient, VssRequestError

START_US = 1_767_225_600_000_000 + 22 * 3_600_000_000  # 2026-01-01T22:00Z: night at the site
ENDPOINT_RE = re.compile(r"other clients: (ws://\S+?)\)")
runner = CliRunner()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def _hello_status_and_mount(vss_url: str, endpoint: str) -> tuple[dict, dict, dict]:
    async with await VssClient.connect(vss_url) as vss:
        status = await vss.request("status")
        hello = vss.hello
    async with await Client.connect(endpoint) as c:
        values = await c.read(["mount.state_name"])
    return hello, status, values


def test_the_embedded_endpoint_listens_on_the_port_given_and_clients_are_told_where():
    port = free_port()
    with vs_server_process("--emulator", "--endpoint-port", str(port)) as server:
        printed = ENDPOINT_RE.search(server.line).group(1)
        hello, status, values = asyncio.run(_hello_status_and_mount(server.url, printed))
    assert printed == f"ws://127.0.0.1:{port}"
    assert status["mount_endpoint"] == printed and hello["mount_endpoint"] == printed
    assert values["mount.state_name"]  # the endpoint answers ASTCom


def test_the_endpoint_port_is_checked_and_a_taken_one_is_named():
    res = runner.invoke(app, ["server", "--mount", "ws://127.0.0.1:1", "--endpoint-port", "9"])
    assert res.exit_code == 2 and "only applies to --emulator" in res.stderr
    res = runner.invoke(app, ["server", "--emulator", "--endpoint-port", "70000"])
    assert res.exit_code == 2 and "0..65535" in res.stderr
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = runner.invoke(app, ["server", "--emulator", "--endpoint-port", str(port),
                                  "--listen", f"ws://127.0.0.1:{free_port()}"])
    assert run.exit_code == 1, run.output
    assert f"ws://127.0.0.1:{port}" in run.stderr and "--endpoint-port" in run.stderr
    assert "address already in use" in run.stderr


def test_a_vss_on_a_separate_mount_names_that_mount_as_its_endpoint():
    rig = Rig(start_us=None, realtime=True).start()
    try:
        status = rig.run(rig.server.call("status"))
        hello = asyncio.run(_hello_only(rig.url))
    finally:
        rig.close()
    assert status["mount_endpoint"] == rig.emulator.url == hello["mount_endpoint"]


async def _hello_only(url: str) -> dict:
    async with await VssClient.connect(url) as vss:
        return vss.hello


def test_a_password_protected_vss_says_where_the_mount_is_only_after_authentication():
    rig = Rig(start_us=START_US, access=AccessConfig(passwords={"operator": "op-secret"})).start()
    try:
        async def look() -> tuple[dict, dict]:
            async with await VssClient.connect(rig.url, password="op-secret") as vss:
                return vss.hello, await vss.request("status")

        hello, status = asyncio.run(look())
    finally:
        rig.close()
    assert "mount_endpoint" not in hello  # the hello reaches peers before they authenticate
    assert status["mount_endpoint"] is None  # in-memory lockstep rig: no socket for others


async def _slew_then_stop(url: str) -> tuple[VssRequestError, dict]:
    """One client slews far; once it is slewing another stops; return the slew's error and
    the operation as the status shows it after."""
    async with await VssClient.connect(url) as mover, await VssClient.connect(url) as stopper:
        slew = asyncio.create_task(mover.request("slew", {"az_deg": 200.0, "el_deg": 70.0},
                                                 timeout_s=120))
        while True:  # the operation events of the mover's slew
            data = await stopper.next_event("operation", 60)
            if data["phase"] == "slewing":
                break
        await stopper.request("stop")
        with pytest.raises(VssRequestError) as exc:
            await slew
        return exc.value, (await stopper.request("status"))["operation"]


def test_a_stopped_slew_reads_as_stopped_not_as_a_failure_nor_a_refusal():
    rig = Rig(start_us=START_US).start()
    try:
        error, op = asyncio.run(_slew_then_stop(rig.url))
        events = [e for e in rig.server.telescope.log.since(0) if e.kind == "command"]
    finally:
        rig.close()
    assert error.code == "aborted"  # the answer to the slew keeps its code
    assert op["phase"] == "aborted"
    assert op["info"]["error"] == {"code": "aborted", "message": "stopped by a client",
                                   "stopped": True}
    slew_lines = [e for e in events if e.fields.get("command") == "slew"]
    assert [e.level for e in slew_lines] == ["info", "info"]  # sent, then ended
    ended = slew_lines[-1]
    assert ended.fields["outcome"] == "stopped" and "refused" not in ended.message
    assert "ended: stopped by a client" in ended.message
