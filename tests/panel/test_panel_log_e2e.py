"""The Log tab in headless chromium, following `vs server --emulator` (lockstep) live.

The page (panel/test/e2e/log.e2e.mjs) connects to the VSS and to the mount's ASTCom
endpoint and opens the Log tab. This test then slews through `VssClient` and writes a
mount parameter through `astcom_client`, and checks with its own reads: the page holds the
two logs exactly as the server and the emulator serve them; the slew and the write show
with their source, kind, client and role; every filter keeps the events `vs log`'s
EventFilter and parse_time_bound keep (the Python implementation beside the page's);
the export holds those events; paused, a new write waits aside, and Follow adds it.
"""

from __future__ import annotations

import asyncio
import json
import queue
import re
import subprocess
import threading
import time

import pytest
from panel_helpers import ARTIFACTS, CHROMIUM, PANEL_DIR, node, vss_and_panel

from astcom_client import Client
from astcom_client.events import Event, utc_text
from virtualstar.eventlog import EventFilter
from virtualstar.recorder.timeparse import parse_time_bound
from virtualstar.vss_client import VssClient, VssRequestError

MOUNT_PASSWORD, OPERATOR_PASSWORD = "mount-secret", "operator-secret"
OBSERVER_PASSWORD = "observer-secret"
START = "2024-05-18T21:00:00Z"  # night at the default site: any az/el above the horizon is safe
PACE = "20"
WRITER = "log-e2e-writer"  # the ASTCom client name the emulator logs with our writes
PARAM = "axis.az.kp"
TARGET = "120 45"  # altaz, degrees


@pytest.fixture(scope="module")
def rig():
    with vss_and_panel("--speed", PACE, "--start", START, "--password", MOUNT_PASSWORD,
                       "--operator-password", OPERATOR_PASSWORD,
                       "--observer-password", OBSERVER_PASSWORD) as urls:
        yield urls


class PageScript:
    """The node page script, spoken with line by line (its stdout read in a thread)."""

    def __init__(self, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen([node(), "test/e2e/log.e2e.mjs"], cwd=PANEL_DIR, env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.out: list[str] = []
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.out.append(line)
            self.lines.put(line)

    def expect(self, word: str, timeout_s: float = 120.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=max(0.1, deadline - time.monotonic()))
            except queue.Empty:
                break
            if line.strip() == f"LOG-E2E {word}":
                return
        raise AssertionError(f"the page script did not say {word}:\n{''.join(self.out)}")

    def send(self, word: str, doc: dict) -> None:
        self.proc.stdin.write(f"{word} {json.dumps(doc)}\n")
        self.proc.stdin.flush()


async def _write_param(url: str, value: float) -> None:
    async with await Client.connect(url, password=MOUNT_PASSWORD, name=WRITER) as c:
        await c.write({PARAM: value})


async def _slew(url: str) -> None:
    """Slew to TARGET; first as an observer (refused: a warning in the log)."""
    async with await VssClient.connect(url, password=OBSERVER_PASSWORD) as vss:
        with pytest.raises(VssRequestError, match="operator"):
            await vss.request("slew", {"altaz": TARGET})
    async with await VssClient.connect(url, password=OPERATOR_PASSWORD) as vss:
        await vss.request("slew", {"altaz": TARGET}, timeout_s=120)


async def _truth(rig) -> dict[str, list[Event]]:
    async with await VssClient.connect(rig["vss"], password=OPERATOR_PASSWORD) as vss:
        vss_events = (await vss.request("log", {"since": 0, "limit": 10_000}))["events"]
    async with await Client.connect(rig["emulator"], password=MOUNT_PASSWORD) as c:
        emu_events = json.loads(await c.invoke("log.since", 0))
    return {"vss": [Event.from_dict(d) for d in vss_events],
            "emulator": [Event.from_dict(d) for d in emu_events]}


def _filters(kp_before: float) -> list[dict]:
    """The filter cases the page applies in turn (the last one is exported)."""
    return [
        {"kind": "param"},
        {"source": "vss"},
        {"source": "vss", "kind": "command"},
        {"level": "warning"},
        {"text": PARAM.upper()},
        {"text": f"old={kp_before}"},  # Python writes the float 35.0, not 35
        {"text": "slew", "source": "emulator"},
        {"from": "+0.5", "to": "-0.5"},
        {"from": "not a time"},
        {"kind": "command,param", "text": "operator"},
    ]


@pytest.fixture(scope="module")
def followed(rig, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("log")
    kp_before = asyncio.run(_read_param(rig["emulator"]))
    filters = _filters(kp_before)
    env = {"PATH": "/usr/bin:/bin:/usr/local/bin", "HOME": str(tmp), "PANEL_URL": rig["panel"],
           "ASTCOM_URL": rig["emulator"], "ASTCOM_PASSWORD": MOUNT_PASSWORD,
           "VSS_URL": rig["vss"], "VSS_PASSWORD": OPERATOR_PASSWORD,
           "ARTIFACTS": str(ARTIFACTS), "RESULT": str(tmp / "log.json"),
           "FILTERS": json.dumps(filters), "CHROMIUM_PATH": str(CHROMIUM)}
    page = PageScript(env)
    try:
        page.expect("READY")
        asyncio.run(_slew(rig["vss"]))
        asyncio.run(_write_param(rig["emulator"], kp_before + 1))
        page.send("SENT", {"param": PARAM, "value": kp_before + 1})
        page.expect("PAUSED")
        asyncio.run(_write_param(rig["emulator"], kp_before + 2))
        page.send("SENT", {"param": PARAM, "value": kp_before + 2})
        page.proc.wait(timeout=180)
    finally:
        if page.proc.poll() is None:
            page.proc.kill()
    result = json.loads((tmp / "log.json").read_text())
    assert result.get("ok"), f"{result.get('error')}\n{''.join(page.out)}"
    assert not result.get("pageErrors"), result["pageErrors"]
    result.update(truth=asyncio.run(_truth(rig)), filters=filters, kp_before=kp_before)
    result["held_events"] = [Event.from_dict(d) for d in result["held"]]
    return result


async def _read_param(url: str) -> float:
    async with await Client.connect(url, password=MOUNT_PASSWORD, role="observer") as c:
        return (await c.read([PARAM]))[PARAM]


def _key(e: Event) -> str:
    return f"{e.source}:{e.seq}"


def test_the_page_holds_both_logs_exactly_as_served_merged_by_time(followed):
    held = followed["held_events"]
    for source, truth in followed["truth"].items():
        mine = [e for e in held if e.source == source]
        assert mine, source
        # every event from the first up to the newest the page had seen, none changed
        assert mine == truth[: len(mine)], source
        assert mine[0].seq == 1
    times = [e.t_us for e in held]
    assert times == sorted(times)


def test_the_slew_and_the_write_show_with_their_source_kind_client_and_role(followed):
    held = followed["held_events"]
    slews = [e for e in held if e.kind == "command" and e.fields.get("command") == "slew"]
    assert [(e.source, e.level, e.fields["role"]) for e in slews] == [
        ("vss", "warning", "observer"), ("vss", "info", "operator")]
    assert json.loads(slews[1].fields["params"]) == {"altaz": TARGET}
    writes = [e for e in held if e.kind == "param" and e.fields.get("name") == PARAM]
    assert len(writes) == 1 and writes[0].source == "emulator"
    assert writes[0].fields["client"] == WRITER and writes[0].fields["role"] == "operator"
    assert writes[0].fields["old"] == followed["kp_before"]
    assert writes[0].fields["new"] == followed["kp_before"] + 1
    # the table's cells for that row (the kind=param filter)
    rows = {r["key"]: r for r in followed["filtered"][0]["rows"]}
    row = rows[_key(writes[0])]
    assert (row["level"], row["source"], row["kind"]) == ("info", "emulator", "param")
    assert row["t_us"] == str(writes[0].t_us)
    assert row["utc"].replace(" ", "T") == utc_text(writes[0].t_us)
    assert row["message"] == writes[0].message and json.loads(row["fields"]) == writes[0].fields


def _python_filter(f: dict, held: list[Event]) -> EventFilter | None:
    """The same filter as vs log builds it; None when a time bound is refused."""
    first, last = held[0].t_us, held[-1].t_us
    try:
        lo = parse_time_bound(f["from"], first, last) if f.get("from") else None
        hi = parse_time_bound(f["to"], first, last, option="--to") if f.get("to") else None
    except ValueError:
        return None
    split = lambda text: tuple(w.strip() for w in text.split(",") if w.strip())  # noqa: E731
    return EventFilter(lo, hi, f.get("level", "debug"), split(f.get("source", "")),
                       split(f.get("kind", "")), f.get("text", ""))


def test_every_filter_keeps_what_vs_log_keeps_and_narrows_the_table(followed):
    held = followed["held_events"]
    for case in followed["filtered"]:
        flt = _python_filter(case["filter"], held)
        if flt is None:  # a refused bound is said, and the other filters still apply
            assert case["errors"] and "expected 'start', 'end'" in case["errors"][0]
            flt = _python_filter({**case["filter"], "from": ""}, held)
        want = [_key(e) for e in held if flt.matches(e)]
        got = [r["key"] for r in case["rows"]]
        assert got == list(reversed(want)), case["filter"]  # newest first
        assert case["count"].startswith(f"{len(want)} of {len(held)} events")
        if case["filter"].get("from") != "not a time":
            assert 0 < len(want) < len(held), case["filter"]


def test_the_export_holds_the_filtered_events_as_json_lines(followed):
    held = followed["held_events"]
    flt = _python_filter(followed["filters"][-1], held)
    lines = followed["exported"].splitlines()
    exported = [Event.from_dict(json.loads(line)) for line in lines]
    assert exported == [e for e in held if flt.matches(e)] and exported
    assert all(json.loads(line)["utc"] == utc_text(e.t_us) for line, e in zip(lines, exported, strict=True))


def test_paused_new_events_wait_and_follow_adds_them(followed):
    paused = followed["paused"]
    assert paused["during"] == paused["before"]
    assert re.fullmatch(r"Follow \(\d+ new\)", paused["button"])
    newest = followed["afterFollow"]["rows"][0]
    second = [e for e in followed["truth"]["emulator"]
              if e.kind == "param" and e.fields.get("new") == followed["kp_before"] + 2]
    assert len(second) == 1 and newest["key"] == _key(second[0])
    assert followed["afterFollow"]["heldCount"] > len(followed["held_events"])
    for name in ("log", "log-followed"):
        png = ARTIFACTS / f"{name}.png"
        assert png.is_file() and png.stat().st_size > 10_000, png
