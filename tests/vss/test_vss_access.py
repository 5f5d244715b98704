"""Who may drive the telescope: passwords with roles, the Origin check, loopback without passwords.

The server runs on loopback with an operator and an observer password; clients are
real WebSocket connections. One test authenticates with the documented algorithm
written out here (hmac + hashlib), not with the project's client.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os

import pytest
from typer.testing import CliRunner
from vss_rig import Rig
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from virtualstar.astro import UtcTimes, load_site
from virtualstar.cli.main import app
from virtualstar.server import AccessConfig
from virtualstar.vss_client import VssClient, VssRequestError

OPERATOR, OBSERVER = "op-secret-7", "obs-secret-3"
runner = CliRunner()


@pytest.fixture(scope="module")
def guarded():
    start_us = int(UtcTimes.from_iso(["2024-05-18T19:40:00Z"]).to_unix_us()[0])
    rig = Rig(start_us=start_us, site=load_site(),
              access=AccessConfig(passwords={"operator": OPERATOR, "observer": OBSERVER},
                                  allowed_origins=["loopback", "http://panel.example:8080"]))
    rig.start()
    yield rig
    rig.close()


def test_the_operator_may_move_the_telescope_and_the_observer_only_watch(guarded):
    async def scenario():
        async with await VssClient.connect(guarded.url, password=OPERATOR) as op, \
                await VssClient.connect(guarded.url, password=OBSERVER) as obs:
            assert (op.role, obs.role) == ("operator", "observer")
            moved = await op.request("slew", {"altaz": "120 50"})
            watched = await obs.request("status")
            event = await obs.next_event("heartbeat", 10.0)  # observers get the events
            refused = {}
            for cmd, params in [("slew", {"altaz": "200 40"}), ("stop", {}), ("park", {}),
                                ("track", {"star": "Vega", "allow_sun": True}),
                                ("set_mode", {"mode": "passive"}),
                                ("load_model", {"path": "/x"})]:
                with pytest.raises(VssRequestError) as err:
                    await obs.request(cmd, params)
                refused[cmd] = err.value
            after = await op.request("status")
            return moved, watched, event, refused, after

    moved, watched, event, refused, after = guarded.run(scenario())
    assert moved["phase"] == "done" and watched["connected"] and "t_unix" in event
    for cmd, error in refused.items():
        assert error.code == "forbidden", cmd
        assert "observer role may only watch" in error.message
    # nothing the observer sent reached the mount
    assert after["operation"]["id"] == moved["id"] and after["mode"] == "active"


def test_no_password_or_a_wrong_one_is_refused_and_three_wrong_ones_close_the_connection(guarded):
    async def scenario():
        with pytest.raises(VssRequestError) as missing:
            await VssClient.connect(guarded.url)
        with pytest.raises(VssRequestError) as wrong:
            await VssClient.connect(guarded.url, password="guess")
        async with connect(guarded.url) as ws:
            hello = json.loads(await ws.recv())
            with pytest.raises(ConnectionClosed):
                await ws.send(json.dumps({"id": 1, "cmd": "status"}))
                unauth = json.loads(await ws.recv())
                for k in range(3):
                    await ws.send(json.dumps({"id": 10 + k, "cmd": "auth", "params": {
                        "client_nonce": os.urandom(16).hex(), "mac": os.urandom(32).hex()}}))
                    json.loads(await ws.recv())
                await ws.recv()
        return missing.value, wrong.value, hello, unauth, ws.close_code

    missing, wrong, hello, unauth, close_code = guarded.run(scenario())
    assert missing.code == "unauthorized" and "vs --password" in missing.message
    assert wrong.code == "unauthorized" and "wrong password" in wrong.message
    assert hello["event"] == "hello" and hello["data"]["auth"]["required"] is True
    assert unauth["error"]["code"] == "unauthorized" and "authenticate first" in \
        unauth["error"]["message"]
    assert close_code == 1008


def test_the_documented_challenge_response_works_and_only_a_mac_crosses_the_wire(guarded):
    async def scenario():
        async with connect(guarded.url) as ws:
            hello = json.loads(await ws.recv())["data"]
            nonce = bytes.fromhex(hello["auth"]["nonce"])
            mine = os.urandom(24)
            mac = hmac.new(OBSERVER.encode(), b"ASTCom-1 client\x00" + nonce + mine,
                           hashlib.sha256).digest()
            frame = json.dumps({"id": "a", "cmd": "auth",
                                "params": {"client_nonce": mine.hex(), "mac": mac.hex()}})
            await ws.send(frame)
            while (reply := json.loads(await ws.recv())).get("id") != "a":
                pass
            proof = hmac.new(OBSERVER.encode(), b"ASTCom-1 server\x00" + nonce + mine,
                             hashlib.sha256).digest()
            await ws.send(json.dumps({"id": "s", "cmd": "status"}))
            while (status := json.loads(await ws.recv())).get("id") != "s":
                pass
            return frame, reply, proof, status

    frame, reply, proof, status = guarded.run(scenario())
    assert OBSERVER not in frame
    assert reply["ok"] and reply["result"]["role"] == "observer"
    assert bytes.fromhex(reply["result"]["server_proof"]) == proof
    assert status["ok"] and status["result"]["connected"]


@pytest.mark.parametrize(("origin", "allowed"), [
    ("http://evil.example.com", False),
    ("http://127.0.0.1:5173", True),  # the panel served from loopback
    ("http://panel.example:8080", True),  # on the allow-list
    ("https://panel.example:8080", False),
])
def test_a_browser_page_from_a_foreign_origin_is_refused_before_the_handshake(guarded, origin,
                                                                              allowed):
    async def scenario():
        try:
            async with connect(guarded.url, origin=origin) as ws:
                return json.loads(await ws.recv())["event"]
        except InvalidStatus as exc:
            return exc.response.status_code, exc.response.body.decode()

    result = guarded.run(scenario())
    if allowed:
        assert result == "hello"
    else:
        assert result[0] == 403 and "--allow-origin" in result[1]


def test_the_cli_takes_the_password_as_an_option_or_from_vs_password(guarded, monkeypatch):
    res = runner.invoke(app, ["status", "--server", guarded.url, "--json"])
    assert res.exit_code == 1 and "needs a password" in res.stderr
    res = runner.invoke(app, ["--password", OBSERVER, "status", "--server", guarded.url, "--json"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["--password", OBSERVER, "stop", "--server", guarded.url])
    assert res.exit_code == 1 and "forbidden" in res.stderr
    monkeypatch.setenv("VS_PASSWORD", OPERATOR)
    res = runner.invoke(app, ["stop", "--server", guarded.url, "--json"])
    assert res.exit_code == 0, res.output


def test_listening_beyond_loopback_without_a_password_is_refused():
    res = runner.invoke(app, ["server", "--emulator", "--speed", "max",
                              "--listen", "ws://0.0.0.0:0"])
    assert res.exit_code == 2
    assert "without passwords would let anyone on the network" in res.stderr
    res = runner.invoke(app, ["server", "--emulator", "--observer-password", "x"])
    assert res.exit_code == 2 and "needs --operator-password" in res.stderr
