"""The panel reconnects to the mount's endpoint and to the VSS after each is killed and restarted.

Two processes on fixed loopback ports: a real-time mount emulator and `vs server --mount` on
it. The page (panel/test/e2e/reconnect.e2e.mjs) is connected to both and streams a signal;
this test kills each process (SIGKILL, as a crash would) and starts it again on the same
port when the page asks, and checks what the page showed in between: values kept but marked
stale, then fresh again, the stream running again, the VSS's own view of its mount, and
the Log tab reading each restarted process's event log from its first event.
"""

from __future__ import annotations

import asyncio
import json
import sys

import pytest
from panel_helpers import (
    ARTIFACTS,
    CHROMIUM,
    PASSWORD,
    LiveProcess,
    ensure_browser_ready,
    free_port,
    run_asking_script,
    wait_ready,
)

from virtualstar.panel import PanelConfig, PanelServer

OPERATOR_PASSWORD = "reconnect-operator"


class Processes:
    """The emulator and the VSS, each restartable on its port."""

    def __init__(self) -> None:
        self.emulator_url = f"ws://127.0.0.1:{free_port()}"
        self.vss_url = f"ws://127.0.0.1:{free_port()}"
        self.emulator: LiveProcess | None = None
        self.vss: LiveProcess | None = None

    def start_emulator(self) -> None:
        port = self.emulator_url.rsplit(":", 1)[1]
        self.emulator = LiveProcess([sys.executable, "-c", "from mount_emulator.cli import main; main()",
                                     "--port", port, "--seed", "7", "--password", PASSWORD])
        wait_ready(self.emulator_url)

    def start_vss(self) -> None:
        self.vss = LiveProcess([sys.executable, "-c", "from virtualstar.cli.main import main; main()",
                                "server", "--mount", self.emulator_url, "--password", PASSWORD,
                                "--operator-password", OPERATOR_PASSWORD, "--listen", self.vss_url])
        assert self.vss.url == self.vss_url, self.vss.lines

    @staticmethod
    def kill(proc: LiveProcess | None) -> None:
        if proc is not None and proc.proc.poll() is None:
            proc.proc.kill()
            proc.proc.wait(10)

    def close(self) -> None:
        for proc in (self.vss, self.emulator):
            if proc is not None:
                proc.stop()


async def _drive(procs: Processes, panel_url: str, result_path) -> tuple[list[str], str]:
    """Run the page script, doing what it asks; return (actions done, its output)."""
    actions = {"kill-mount": lambda: procs.kill(procs.emulator),
               "restart-mount": procs.start_emulator,
               "kill-vss": lambda: procs.kill(procs.vss),
               "restart-vss": procs.start_vss}
    return await run_asking_script(
        "test/e2e/reconnect.e2e.mjs",
        {"PATH": "/usr/bin:/bin:/usr/local/bin", "HOME": str(result_path.parent),
         "PANEL_URL": panel_url, "ASTCOM_URL": procs.emulator_url, "ASTCOM_PASSWORD": PASSWORD,
         "VSS_URL": procs.vss_url, "VSS_PASSWORD": OPERATOR_PASSWORD,
         "ARTIFACTS": str(ARTIFACTS), "RESULT": str(result_path), "CHROMIUM_PATH": str(CHROMIUM)},
        actions)


async def _logs(procs: Processes) -> dict[str, list[dict]]:
    """The event logs of the running (restarted) emulator and VSS, read by our own clients."""
    from astcom_client import Client
    from virtualstar.vss_client import VssClient

    async with await Client.connect(procs.emulator_url, password=PASSWORD) as c:
        emulator = json.loads(await c.invoke("log.since", 0))
    async with await VssClient.connect(procs.vss_url, password=OPERATOR_PASSWORD) as vss:
        server = (await vss.request("log", {"since": 0, "limit": 10_000}))["events"]
    return {"emulator": emulator, "vss": server}


@pytest.fixture(scope="module")
def reconnect(tmp_path_factory):
    ensure_browser_ready()
    procs = Processes()
    try:
        procs.start_emulator()
        procs.start_vss()
        result_path = tmp_path_factory.mktemp("reconnect") / "result.json"
        with PanelServer(PanelConfig(port=0)) as panel:
            done, out = asyncio.run(_drive(procs, panel.start(), result_path))
        result = json.loads(result_path.read_text()) if result_path.exists() else {}
        assert result.get("ok"), f"{result.get('error')}\n{out}"
        assert done == ["kill-mount", "restart-mount", "kill-vss", "restart-vss"]
        assert not result.get("pageErrors"), result["pageErrors"]
        result["truth_logs"] = asyncio.run(_logs(procs))
        return result
    finally:
        procs.close()


def test_values_are_fresh_while_both_links_are_up(reconnect):
    fresh = reconnect["fresh"]
    assert fresh["astcom"] == "connected" and fresh["vss"] == "connected"
    assert not fresh["astcomStaleClass"] and not fresh["vssStaleClass"]
    assert fresh["astcomStaleNote"] == "" and fresh["vssStaleNote"] == ""
    assert fresh["mountLink"] == "connected" and fresh["streamActive"]


def test_a_killed_endpoint_leaves_its_values_marked_stale_while_the_panel_retries(reconnect):
    killed = reconnect["mountKilled"]
    assert killed["astcom"] == "reconnecting" and "ASTCom: reconnecting" in killed["headerAstcom"]
    assert killed["astcomStaleClass"] and killed["astcomStaleNote"].startswith("stale: last update")
    assert "connection lost" in killed["log"]
    # the VSS is still up and says it has lost its mount; the last known place stays, marked
    assert killed["vss"] == "connected" and killed["mountLink"] == "disconnected"
    assert killed["encoderAz"] not in ("", "—") and killed["encoderAzKept"]
    assert killed["encoderAzColor"] == "rgb(138, 143, 153)"  # the stale grey
    assert killed["placeKept"].startswith("mount away: last known place")


def test_the_restarted_endpoint_is_found_again_and_its_stream_resumes(reconnect):
    back = reconnect["mountBack"]
    assert back["astcom"] == "connected" and not back["astcomStaleClass"]
    assert back["astcomStaleNote"] == "" and back["streamActive"]
    assert back["samples"] > 20  # counted on the new stream
    assert "reconnected to mount-emulator" in back["log"]
    assert back["mountLink"] == "connected"  # the VSS found its mount again too
    assert not back["encoderAzKept"] and back["placeKept"] == ""


def test_a_killed_vss_leaves_the_telescope_board_stale_then_fresh_after_restart(reconnect):
    killed, back = reconnect["vssKilled"], reconnect["vssBack"]
    assert killed["vss"] == "reconnecting" and "VSS: reconnecting" in killed["headerVss"]
    assert killed["vssStaleClass"] and killed["vssStaleNote"].startswith("stale: last update")
    assert killed["encoderAz"] not in ("", "—")  # the last values stay on screen
    assert killed["astcom"] == "connected" and not killed["astcomStaleClass"]
    assert back["vss"] == "connected" and not back["vssStaleClass"] and back["vssStaleNote"] == ""
    assert "VSS reconnected" in back["log"]


def test_the_log_tab_reads_each_restarted_log_from_its_first_event(reconnect):
    rows = reconnect["logRows"]
    for source, truth in reconnect["truth_logs"].items():
        mine = [e for e in rows if e["source"] == source]
        restart = max(i for i, e in enumerate(mine) if e["seq"] == 1)
        assert restart > 0, source  # events of the first process came before
        since_restart = mine[restart:]
        assert since_restart == truth[: len(since_restart)], source
        assert [e["seq"] for e in since_restart] == list(range(1, len(since_restart) + 1))
