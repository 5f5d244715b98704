"""The structured event log: the record and its ring, what the emulator, the VSS and the
recorder log during a scripted run, the store, `vs log` filters and `--follow`."""

from __future__ import annotations

import asyncio
import json
import re
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from astcom_client import Client
from astcom_client.events import Event, EventLog, utc_text
from mount_emulator.config import EmulatorConfig
from mount_emulator.emulator import MountEmulator
from virtualstar.cli.main import app
from virtualstar.eventlog import EventFilter, VssEventSource
from virtualstar.recorder.parquet_store import ParquetStoreReader, ParquetStoreWriter
from virtualstar.recorder.subscriber import Recorder

sys.path.insert(0, str(Path(__file__).parent.parent / "vss"))
from vss_rig import Rig, run_lockstep_scenario  # noqa: E402

START_US = 1_767_225_600_000_000  # 2026-01-01T00:00:00Z
FIELDS = {"seq", "t_us", "utc", "source", "level", "kind", "message", "fields"}


def test_the_log_numbers_events_and_hands_on_only_the_newer_ones():
    log = EventLog("test", capacity=3)
    for k in range(5):
        log.add(START_US + k, "info", "state", f"event {k}", k=k)
    assert [e.seq for e in log.since(0)] == [3, 4, 5]  # the two oldest fell out of the ring
    assert [e.fields["k"] for e in log.since(4)] == [4]
    assert log.since(5) == []
    doc = json.loads(log.since_json(3))
    assert [set(d) for d in doc] == [FIELDS, FIELDS]
    assert doc[0]["utc"] == utc_text(START_US + 3) == "2026-01-01T00:00:00.000003Z"
    with pytest.raises(ValueError, match="debug, info, warning, error"):
        log.add(START_US, "loud", "state", "no such level")


def test_the_emulator_logs_clients_commands_states_faults_resets_parameter_writes_and_syncs():
    async def run() -> list[dict]:
        emu = MountEmulator(EmulatorConfig(start_us=START_US, seeing_arcsec=0.0))
        await emu.start(None, run_loop=False)
        try:
            c = await Client.open(emu.endpoint.connect_in_memory(), name="test")
            await c.invoke("mount.power_on")
            emu.advance(100)
            await c.write({"axis.az.inject_encoder_fault": 1.0})
            emu.advance(100)
            await c.write({"axis.az.inject_encoder_fault": 0.0})
            await c.invoke("safety.reset")
            await c.invoke("time.set_utc", START_US // 1_000_000 + 1)
            emu.advance(20_000)
            docs = json.loads(await c.invoke("log.since", 0))
            assert (await c.read(["log.last_seq"]))["log.last_seq"] == docs[-1]["seq"]
            await c.close()
            return docs
        finally:
            await emu.stop()

    docs = asyncio.run(run())
    assert all(set(d) == FIELDS and d["source"] == "emulator" for d in docs)
    by_kind = {}
    for d in docs:
        by_kind.setdefault(d["kind"], []).append(d)
    power_on = by_kind["command"][0]
    assert power_on["fields"] == {"command": "mount.power_on", "args": [], "client": "test",
                                  "role": "operator"}
    assert power_on["message"] == "mount.power_on() by test (operator)"
    assert by_kind["connection"][0]["fields"]["what"] == "connected"
    assert by_kind["connection"][0]["fields"]["client"] == "test"
    assert {"OFF → HOLDING", "HOLDING → FAULT"} <= {d["message"].split("mount ")[1]
                                                     for d in by_kind["state"]}
    fault = by_kind["fault"][0]
    assert fault["level"] == "error" and fault["fields"] == {"axis": "az", "bits": 4}
    inject = by_kind["param"][0]
    assert inject["level"] == "warning"
    assert inject["fields"] == {"name": "axis.az.inject_encoder_fault", "old": 0.0, "new": 1.0,
                                "client": "test", "role": "operator"}
    assert by_kind["param"][1]["level"] == "info"  # the injection ended
    assert by_kind["fault_reset"][0]["fields"]["command"] == "safety.reset"
    sync = by_kind["clock_sync"][0]
    assert sync["t_us"] == (START_US // 1_000_000 + 1) * 1_000_000  # set on the PPS edge
    times = [d["t_us"] for d in docs]
    assert times == sorted(times)


def _scripted_night(store: Path):
    """A VSS slews the emulator, a fault is injected and reset, while a recorder records."""
    async def scenario(vss, clock):
        emu = vss.emulator.emulator
        writer = ParquetStoreWriter(store)

        async def connect():
            return await vss.emulator.connect_in_memory(name="recorder")

        recorder = Recorder(connect, ["axis.az.position", "axis.az.current"], 100.0, writer,
                            source="scripted night",
                            event_sources=[VssEventSource(vss.client())])
        task = asyncio.ensure_future(recorder.run())
        await recorder.started.wait()
        vs = vss.client()
        await vs.request("slew", {"altaz": "120 50"})
        await clock.sleep(2.0)
        emu.model.set_param("axis.el.inject_encoder_fault", 1.0)  # as an ASTCom WRITE would
        emu.param_written("axis.el.inject_encoder_fault", 0.0, 1.0)
        await clock.sleep(2.0)
        emu.model.set_param("axis.el.inject_encoder_fault", 0.0)
        await vs.request("reset_faults")
        await clock.sleep(2.0)
        log = await vs.request("log", {"since": 0})
        recorder.stop()
        await task
        return log

    return run_lockstep_scenario("2026-01-01T22:00:00Z", scenario)


@pytest.fixture(scope="module")
def night_store(tmp_path_factory):
    store = tmp_path_factory.mktemp("night") / "store"
    log = _scripted_night(store)
    return store, log


def test_a_scripted_run_logs_every_kind_with_its_fields(night_store):
    store, vss_log = night_store
    vss = [Event.from_dict(d) for d in vss_log["events"]]
    kinds = {e.kind for e in vss}
    assert {"command", "phase", "fault", "connection"} <= kinds, kinds
    slew = next(e for e in vss if e.kind == "command" and e.fields["command"] == "slew")
    assert slew.fields["role"] == "operator" and slew.fields["client"] == "in-process"
    assert json.loads(slew.fields["params"]) == {"altaz": "120 50"}
    phases = [e.fields["phase"] for e in vss if e.kind == "phase"]
    assert phases and all(isinstance(p, str) and p for p in phases)
    assert next(e for e in vss if e.kind == "fault").level == "error"
    assert vss_log["last_seq"] == vss[-1].seq

    stored = ParquetStoreReader(store).events()
    by_source = {}
    for e in stored:
        by_source.setdefault(e.source, set()).add(e.kind)
    assert {"command", "state", "param", "fault", "fault_reset"} <= by_source["emulator"]
    assert "session" in by_source["recorder"]
    assert {"command", "phase", "fault"} <= by_source["vss"]  # the VSS's log, kept too
    stored_vss = [e.seq for e in stored if e.source == "vss"]
    assert len(stored_vss) == len(set(stored_vss))  # each VSS event stored once
    t0, t1 = ParquetStoreReader(store).time_range()
    for e in stored:  # mount time, within the recording (the emulator's from before it too)
        assert e.t_us <= t1 + 2_000_000, e
    assert (store / "events").is_dir() and not (store / "events.jsonl").exists()


def test_vs_log_filters_a_store_by_level_source_kind_text_and_time(night_store):
    store, _ = night_store
    everything = ParquetStoreReader(store).events()
    runner = CliRunner()

    def shown(*args: str) -> list[dict]:
        result = runner.invoke(app, ["log", str(store), "--json", *args])
        assert result.exit_code == 0, result.output
        return json.loads(result.stdout)

    assert len(shown()) == len(everything)
    assert {d["level"] for d in shown("--level", "warning")} <= {"warning", "error"}
    assert shown("--level", "error") and all(d["kind"] == "fault" for d in shown("--level",
                                                                                "error"))
    assert {d["source"] for d in shown("--source", "recorder")} == {"recorder"}
    assert {d["kind"] for d in shown("--kind", "param,fault_reset")} == {"param", "fault_reset"}
    assert all("inject_encoder_fault" in d["message"] for d in shown("--grep", "INJECT_ENC"))
    middle = everything[len(everything) // 2].t_us
    assert all(d["t_us"] >= middle for d in shown("--from", str(middle)))
    table = runner.invoke(app, ["log", str(store), "--kind", "fault"])
    assert table.exit_code == 0 and "el axis faulted: encoder" in table.stdout


def test_vs_log_help_names_the_levels_astcom_defines():
    from astcom_client.events import LEVELS
    from virtualstar.cli.log import LEVEL_NAMES

    assert LEVEL_NAMES == LEVELS  # named twice so that `vs log --help` imports no ASTCom


def test_the_event_filter_keeps_what_each_option_says():
    e = Event(START_US, "vss", "warning", "safety", "safety: Sun → park", {"reason": "Sun"})
    assert EventFilter(min_level="warning").matches(e)
    assert not EventFilter(min_level="error").matches(e)
    assert not EventFilter(sources=("emulator",)).matches(e)
    assert EventFilter(kinds=("safety", "fault")).matches(e)
    assert EventFilter(text="reason=sun").matches(e)
    assert not EventFilter(from_t_us=START_US + 1).matches(e)
    assert not EventFilter(to_t_us=START_US).matches(e)


@pytest.mark.parametrize(("args", "message"), [
    (["--level", "loud"], "--level"),
    (["--follow"], "--follow needs a VSS URL"),
    (["--from", "yesterday"], "--from"),
])
def test_vs_log_refuses_bad_arguments_with_exit_2(night_store, args, message):
    store, _ = night_store
    result = CliRunner().invoke(app, ["log", str(store), *args])
    assert result.exit_code == 2
    assert message in result.stderr


def test_vs_log_follows_a_running_vss():
    rig = Rig(start_us=START_US + 22 * 3_600_000_000).start()
    try:
        rig.run(rig.server.call("set_mode", {"mode": "passive"}))
        result = CliRunner().invoke(app, ["log", rig.url, "--follow", "--duration", "1.5",
                                          "--json", "--kind", "command,mode"])
        assert result.exit_code == 0, result.output
        lines = [json.loads(x) for x in result.stdout.splitlines() if x.strip()]
        assert [d["fields"]["command"] for d in lines if d["kind"] == "command"] == ["set_mode"]
        assert any(d["kind"] == "mode" and d["message"] == "mode passive" for d in lines)
    finally:
        rig.close()


def test_vs_log_without_follow_prints_the_whole_vss_log_once_and_ends():
    rig = Rig(start_us=START_US + 22 * 3_600_000_000).start()
    try:
        async def toggle() -> None:
            for i in range(600):  # more than one page (1000 events) of the server's log
                await rig.server.call("set_mode", {"mode": "passive" if i % 2 else "active"})

        rig.run(toggle())
        held = rig.server.telescope.log.since(0)
        assert len(held) > 1000
        result = CliRunner().invoke(app, ["log", rig.url, "--json"])
        table = CliRunner().invoke(app, ["log", rig.url, "--kind", "mode"])
    finally:
        rig.close()
    assert result.exit_code == 0, result.output
    shown = json.loads(result.stdout)  # one JSON list: read once, then the command ended
    assert [d["seq"] for d in shown][: len(held)] == [e.seq for e in held]
    assert table.exit_code == 0
    modes = [x for x in table.stdout.splitlines() if "mode passive" in x or "mode active" in x]
    assert len(modes) == sum(e.kind == "mode" for e in held)


def test_vs_log_says_on_stderr_how_many_events_of_each_kind_the_server_dropped():
    from virtualstar.server.event_log import KEPT_APART

    rig = Rig(start_us=START_US + 22 * 3_600_000_000).start()
    try:
        extra = 37
        log = rig.server.telescope.log

        async def churn() -> None:  # what a connect/close storm leaves in the ring
            for i in range(KEPT_APART["connection"] + extra):
                log.add(START_US, "info", "connection", f"client {i} connected")

        rig.run(churn())
        table = CliRunner().invoke(app, ["log", rig.url, "--kind", "connection"])
        as_json = CliRunner().invoke(app, ["log", rig.url, "--json"])
        final = log.dropped["connection"]
    finally:
        rig.close()
    assert table.exit_code == 0 and as_json.exit_code == 0, table.output
    # the ring kept its newest events; the reader is told how many of which kind it lost
    # (the rig's and the CLI's own connections are in the ring too)
    said = [re.search(r"dropped, to keep operations and faults: (\d+) connection events",
                      r.stderr) for r in (table, as_json)]
    assert all(said), (table.stderr, as_json.stderr)
    assert extra <= int(said[0].group(1)) <= int(said[1].group(1)) <= final
    json.loads(as_json.stdout)  # stdout stays one JSON list
    shown = [x for x in table.stdout.splitlines() if "connected" in x]
    assert len(shown) == KEPT_APART["connection"]


def test_a_command_the_server_refuses_is_logged_as_a_warning_with_its_code():
    from virtualstar.vss_client import VssRequestError, call_server

    rig = Rig(start_us=START_US + 22 * 3_600_000_000).start()
    try:
        with pytest.raises(VssRequestError) as exc:
            call_server(rig.url, "slew", {"az_deg": 100.0, "el_deg": -20.0})
        events = [e for e in rig.server.telescope.log.since(0) if e.kind == "command"]
    finally:
        rig.close()
    assert exc.value.code == "unreachable"
    info, warning = events[-2:]
    assert info.level == "info" and info.fields["command"] == "slew"
    assert warning.level == "warning" and warning.fields["code"] == "unreachable"
    assert "refused" in warning.message
