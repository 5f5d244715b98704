"""The panel an operator can trust at 2 a.m. (issue 29), in headless chromium at 1400×900 and
1024×700 at once, against `vs server --emulator` with operator and observer passwords.

The page script (panel/test/e2e/trust.e2e.mjs) opens one page per size in one browser and
asks this test to act and to read the truth with its own clients: the VSS's status after
each STOP and its log after each refused slew (`VssClient`), then a SIGKILL of the server and
a restart on the same VSS port with its emulator's ASTCom endpoint on another port. This
test checks what the pages measured and showed against that truth:

* no card's content and no header item overflows (scrollWidth ≤ clientWidth) on any tab;
* the STOP button's box is the same before and after a press, and after a refused press;
* a refused slew shows the server's reason on the Telescope tab;
* the Log tab hides `clock_sync` (and the `time.set_utc` calls behind it) until asked;
* after the SIGKILL every value cell looks stale (colour and italics), the header says
  `reconnecting` readably;
* after the restart the Board's ASTCom link comes back by itself, at the endpoint the VSS
  names (`mount_endpoint`).

Screenshots of each case land in artifacts/panel/trust/ (docs/panel.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import forkserver
import pytest
from panel_helpers import ARTIFACTS, CHROMIUM, ensure_browser_ready, free_port, run_asking_script

from virtualstar.panel import PanelConfig, PanelServer
from virtualstar.vss_client import VssClient

MOUNT_PASSWORD, OPERATOR_PASSWORD, OBSERVER_PASSWORD = "mount-2am", "operator-2am", "observer-2am"
START = "2024-05-18T21:00:00Z"  # Poznań (the default site): night, Vega high, the Sun below
SHOTS = ARTIFACTS / "trust"
SIZES = ("1400x900", "1024x700")
STALE_RGB = "rgb(138, 143, 153)"
START_GUARD_S = 150.0  # a hang guard for the server's start line, far above its ~5 s
LINE_RE = re.compile(r"VirtualStar Server on (ws://\S+) .*other clients: (ws://\S+?)\)")


class EmbeddedServer:
    """`vs server --emulator` on a fixed VSS port, killable and restartable there; its
    emulator's ASTCom endpoint on a free port each time (so a restart moves it)."""

    def __init__(self) -> None:
        self.url = f"ws://127.0.0.1:{free_port()}"
        self.proc: subprocess.Popen | None = None
        self.endpoint = ""
        self.output: list[str] = []

    def start(self) -> None:
        self.proc = forkserver.popen(
            [sys.executable, "-c", "from virtualstar.cli.main import main; main()", "server",
             "--emulator", "--speed", "20", "--start", START, "--password", MOUNT_PASSWORD,
             "--operator-password", OPERATOR_PASSWORD, "--observer-password", OBSERVER_PASSWORD,
             "--listen", self.url, "--endpoint-port", "0"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONFAULTHANDLER": "1"})
        lines: queue.Queue[str | None] = queue.Queue()
        out = self.proc.stdout
        threading.Thread(target=lambda: ([lines.put(x) for x in out], lines.put(None)),
                         daemon=True).start()
        deadline = time.monotonic() + START_GUARD_S
        while (line := self._next_line(lines, deadline)) is not None:
            self.output.append(line)
            match = LINE_RE.search(line)
            if match:
                assert match.group(1) == self.url, line
                self.endpoint = match.group(2)
                break
        else:
            raise RuntimeError("vs server did not start:\n" + "".join(self.output))
        threading.Thread(target=self._keep, args=(lines,), daemon=True).start()

    def _next_line(self, lines: queue.Queue, deadline: float) -> str | None:
        """The server's next line; past the hang guard, its threads' stacks (faulthandler
        prints them on SIGABRT) and None."""
        try:
            return lines.get(timeout=max(deadline - time.monotonic(), 0.0))
        except queue.Empty:
            self.proc.send_signal(signal.SIGABRT)
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(10)
            with contextlib.suppress(queue.Empty):
                while (line := lines.get(timeout=10)) is not None:
                    self.output.append(line)
            self.output.append(f"(no start line in {START_GUARD_S:.0f} s: stacks above)\n")
            return None

    def _keep(self, lines: queue.Queue) -> None:
        while (line := lines.get()) is not None:
            self.output.append(line)

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


async def _status(url: str) -> dict:
    async with await VssClient.connect(url, password=OPERATOR_PASSWORD) as vss:
        return await vss.request("status")


async def _refusals(url: str) -> list[dict]:
    """The server's own log lines of the slews it refused (what it answered, and to whom)."""
    async with await VssClient.connect(url, password=OPERATOR_PASSWORD) as vss:
        events = (await vss.request("log", {"since": 0, "limit": 10_000}))["events"]
    return [e for e in events if e["kind"] == "command" and e["level"] == "warning"
            and e["fields"].get("command") == "slew" and e["fields"].get("code")]


async def _drive(server: EmbeddedServer, panel_url: str, result_path, first_endpoint: str):
    """Run the page script, doing what it asks; return (actions done, its output)."""
    truth: dict[str, list] = {"stops": [], "refusals": []}

    def truth_stop() -> dict:
        op = asyncio.run(_status(server.url))["operation"]
        truth["stops"].append(op)
        return {"phase": op["phase"], "error": op["info"].get("error")}

    def truth_refused() -> dict:
        line = asyncio.run(_refusals(server.url))[-1]
        truth["refusals"].append(line)
        return {"message": line["message"], "code": line["fields"]["code"]}

    def restart() -> dict:
        server.start()
        return {"endpoint": server.endpoint}

    actions = {"truth-stop": truth_stop, "truth-refused": truth_refused,
               "kill-vss": server.kill, "restart-vss": restart}
    done, out = await run_asking_script(
        "test/e2e/trust.e2e.mjs",
        {"PATH": "/usr/bin:/bin:/usr/local/bin", "HOME": str(result_path.parent),
         "PANEL_URL": panel_url, "ASTCOM_URL": first_endpoint, "MOUNT_PASSWORD": MOUNT_PASSWORD,
         "VSS_URL": server.url, "OPERATOR_PASSWORD": OPERATOR_PASSWORD,
         "OBSERVER_PASSWORD": OBSERVER_PASSWORD, "ARTIFACTS": str(SHOTS),
         "RESULT": str(result_path), "CHROMIUM_PATH": str(CHROMIUM)},
        actions, line_timeout_s=300)
    return done, out, truth


@pytest.fixture(scope="module")
def trust(tmp_path_factory):
    ensure_browser_ready()
    server = EmbeddedServer()
    try:
        server.start()
        first_endpoint = server.endpoint
        result_path = tmp_path_factory.mktemp("trust") / "result.json"
        with PanelServer(PanelConfig(port=0, endpoint=first_endpoint, vss=server.url)) as panel:
            done, out, truth = asyncio.run(_drive(server, panel.start(), result_path, first_endpoint))
        result = json.loads(result_path.read_text()) if result_path.exists() else {}
        assert result.get("ok"), f"{result.get('error')}\n{out}\n{''.join(server.output)}"
        assert done == ["truth-stop", "truth-refused"] * 2 + ["kill-vss", "restart-vss"], out
        assert not result.get("pageErrors"), result["pageErrors"]
        result.update(truth=truth, first_endpoint=first_endpoint, endpoint=server.endpoint)
        return result
    finally:
        server.close()


def test_both_sizes_were_exercised_and_no_resource_is_missing(trust):
    assert [p["size"] for p in trust["pages"]] == list(SIZES)
    # a favicon is served: no 404 in the console (refused WebSocket retries are expected)
    errors = [e for e in trust.get("consoleErrors", []) if "WebSocket connection" not in e]
    assert errors == []


def test_no_card_and_no_header_item_overflows_on_any_tab(trust):
    for page in trust["pages"]:
        for tab, seen in page["overflow"].items():
            assert seen["over"] == [], (page["size"], tab, seen["over"])
            assert seen["checked"]["header"] >= 14  # header, brand, links, nav, STOP, 2 links, 9 tabs
        assert page["overflow"]["Telescope"]["checked"]["cards"] == 7  # with the offsets card
        assert page["overflow"]["Board"]["checked"]["cards"] == 3


def test_the_stop_button_never_moves_nor_changes_size(trust):
    for page in trust["pages"]:
        boxes = page["stopBox"]
        assert boxes["before"]["width"] > 50 and boxes["before"]["height"] > 30
        for when in ("after", "beforeRefused", "afterRefused"):
            assert boxes[when] == boxes["before"], (page["size"], when, boxes)
        assert "mount: mount.stop() done" in page["stopOutcome"]
        assert "VSS: stop done (mount holding)" in page["stopOutcome"]
        # the refused press (observer on both links) says so, and stays until dismissed
        assert page["refusedStopFailed"]
        assert "mount: failed:" in page["refusedStopOutcome"]
        assert "VSS: failed:" in page["refusedStopOutcome"] and "operator" in page["refusedStopOutcome"]


def test_a_stopped_operation_reads_as_stopped_not_as_an_error(trust):
    for page, truth in zip(trust["pages"], trust["truth"]["stops"], strict=True):
        assert truth["phase"] == "aborted" and truth["info"]["error"]["stopped"] is True
        shown = page["afterStop"]
        assert shown["phase"] == "stopped" and shown["phaseStyle"] == "ended"
        assert shown["ended"] == "stopped by a client"
        assert shown["errors"] == [] and not shown["errorsBad"]
        # nothing is tracked any more: no tracking error figures
        assert shown["rms"] == "—" and shown["trackingWhy"] == "nothing is tracked"


def test_a_refused_slew_shows_the_servers_reason_on_the_telescope_tab(trust):
    for page, line in zip(trust["pages"], trust["truth"]["refusals"], strict=True):
        refused = page["refused"]
        assert refused["what"] == "slew Sun"
        code = line["fields"]["code"]
        assert code == "unreachable"
        # the server's log: "slew from HOST:PORT (operator) refused: <reason> [unreachable]"
        reason = re.search(r"refused: (.*) \[unreachable\]$", line["message"]).group(1)
        assert refused["text"] == f"refused: {code}: {reason}"
        assert refused["color"] == "rgb(187, 34, 34)"  # .st-bad


def test_the_log_tab_hides_clock_syncs_until_asked(trust):
    for page in trust["pages"]:
        default, routine = page["logDefault"], page["logRoutine"]
        assert default["heldClockSync"] > 0
        assert default["clockSyncRows"] == 0 and default["setUtcRows"] == 0
        assert re.fullmatch(r"\(\d+ hidden\)", default["hiddenNote"])
        assert int(default["hiddenNote"][1:].split()[0]) >= default["heldClockSync"]
        assert routine["clockSyncRows"] > 0 and routine["setUtcRows"] > 0
        assert routine["rows"] > default["rows"]
        # the fields on one line (not wrapped character by character), a message on two at
        # most, the table within the page: many rows fit on a screen
        assert default["fieldsLinesMax"] < 2  # height in font sizes: one line
        assert default["rowHeightMax"] < 60
        assert default["pageScrollWidth"] <= default["pageWidth"]


def test_observer_buttons_are_disabled_and_say_operator_only(trust):
    for page in trust["pages"]:
        buttons = page["observer"]["disabled"]
        assert buttons and all(b["disabled"] for b in buttons)
        assert all(b["title"].startswith("operator only") for b in buttons)
        assert page["observer"]["hint"].startswith("operator only")
        # the Board's link as observer too: Parameters and Input say the same
        for where in ("observerParameters", "observerInput"):
            assert len(page[where]) >= 3, where
            assert all(b["disabled"] and b["title"].startswith("operator only") for b in page[where]), where


def test_after_sigkill_every_value_cell_looks_stale_with_its_age(trust):
    for killed in trust["killed"]:
        assert killed["checked"] >= 40, killed["fields"]
        assert killed["notStale"] == [], (killed["size"], killed["notStale"])
        for field in ("phase", "mount-link", "encoder-az", "ra", "tick", "mount-time"):
            assert field in killed["fields"]
        assert any(f.startswith("diagnostics:") for f in killed["fields"])
        assert re.fullmatch(r"stale: last update \d+ s ago \(\d\d:\d\d:\d\d UTC by this computer's clock\)",
                            killed["notes"]["vss"])
        assert killed["notes"]["astcom"].startswith("stale: last update")
        # the header says reconnecting in a readable colour, not the stale grey italics
        assert "ASTCom: reconnecting" in killed["header"]["astcom"]
        assert killed["header"]["astcomColor"] != STALE_RGB
        assert killed["header"]["astcomStyle"] == "normal"


def test_after_the_restart_the_astcom_link_follows_the_vss_to_its_new_endpoint(trust):
    assert trust["endpoint"] != trust["first_endpoint"]  # --endpoint-port 0: it moved
    for back in trust["restarted"]:
        assert back["url"] == back["boardUrl"] == back["mountEndpoint"] == trust["endpoint"]
        assert f"moved from {trust['first_endpoint']} to {trust['endpoint']}" in back["log"]
        assert back["boardsStale"] == {"telescope": False, "astcom": False}


def test_screenshots_of_each_case_are_kept(trust):
    names = ["telescope-tracking", "board", "stop-outcome", "refused-slew", "log-routine-hidden",
             "log-routine-shown", "stop-refused", "stale-telescope", "stale-board", "restarted-board"]
    for size in SIZES:
        for name in names:
            png = SHOTS / f"{name}-{size}.png"
            assert png.is_file() and png.stat().st_size > 10_000, png
