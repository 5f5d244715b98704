"""`run_plan` / `vs run`: a plan executed on the emulator through the VSS API, in lockstep.

The mount's own encoders, read straight from the emulator during the run, must be on each
block's target (astropy for the stars, skyfield for the ISS); a mount fault injected
mid-block makes the run re-plan and go on; a stop ends it and nothing moves afterwards;
a resumed run does not observe again what was done."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import numpy as np
import pytest
from astropy.utils import iers
from sky_truth import iss_truth, sky_sep_arcsec, star_truth
from typer.testing import CliRunner
from vss_rig import STARS_PROGRAM, run_lockstep_scenario, sample_encoders, vs_server_process

from virtualstar.astro import UtcTimes, load_site
from virtualstar.cli.main import app
from virtualstar.planning import PlanRequest, load_program, plan_program

iers.conf.auto_download = False
iers.conf.auto_max_age = None

PROGRAM = """
[defaults]
duration_s = 120
min_el_deg = 20
sun_max_el_deg = -6
[[target]]
star = "Vega"
[[target]]
star = "Arcturus"
priority = 2
[[target]]
name = "ISS"
tle_file = "stations.tle"
sat = "ISS"
priority = 5
[[target]]
star = "Deneb"
"""


def _us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


def _plan(tmp, text: str, start: str, end: str) -> dict:
    (tmp / "stations.tle").write_text(Path("catalogs/data/stations.tle").read_text())
    (tmp / "program.toml").write_text(text)
    plan = plan_program(PlanRequest(load_program(tmp / "program.toml"), _us(start), _us(end),
                                    load_site()))
    return plan.as_dict()


@pytest.fixture(scope="module")
def night(tmp_path_factory):
    return _plan(tmp_path_factory.mktemp("night"), PROGRAM, "2024-05-18T21:22:00Z",
                 "2024-05-18T21:40:00Z")


@pytest.fixture(scope="module")
def stars(tmp_path_factory):
    return _plan(tmp_path_factory.mktemp("stars"), STARS_PROGRAM, "2024-05-18T21:22:00Z",
                 "2024-05-18T21:36:00Z")


@pytest.fixture
def stars_file(stars, tmp_path):
    """The stars plan written where `vs run` reads it."""
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(stars))
    return plan


@pytest.fixture
def short_stars_file(tmp_path):
    """The same stars for 30 s each: for the runs that cross process boundaries, where the
    mount time simulated (10 kHz) is what the test costs."""
    plan = tmp_path / "short-plan.json"
    plan.write_text(json.dumps(_plan(tmp_path, STARS_PROGRAM.replace(
        "duration_s = 120", "duration_s = 30"), "2024-05-18T21:22:00Z", "2024-05-18T21:30:00Z")))
    return plan


def test_a_plan_runs_block_by_block_with_the_mount_on_each_target(night):
    site = load_site()

    async def scenario(vss, clock):
        events = vss.server.subscribe(maxsize=10_000)
        run = asyncio.ensure_future(vss.server.call("run_plan", {"plan": night, "wait": True}))
        reads = await sample_encoders(vss, clock, 5.0, until=run)
        program = await vss.server.call("program")
        status = await vss.server.call("status")
        seen = []
        while not events.empty():
            kind, data = events.get_nowait()
            if kind == "program":
                seen.append(data["state"])
        return await run, program, status, reads, seen

    result, program, status, reads, seen = run_lockstep_scenario("2024-05-18T21:20:00Z",
                                                                 scenario, site=site)
    assert result["state"] == "done" and program["records"] == result["records"]
    assert seen[0] == "running" and seen[-1] == "done"
    planned = [(b["target"], b["start_us"], b["end_us"]) for b in night["blocks"]]
    records = result["records"]
    assert [(r["target"], r["planned_start_us"], r["planned_end_us"]) for r in records] == planned
    assert all(r["outcome"] == "done" for r in records), records
    assert {r["target"] for r in records} == {"Vega", "Arcturus", "Deneb", "ISS"}
    t, az, el = reads.t_us, reads.az_deg, reads.el_deg
    for r in records:
        assert r["start_us"] == r["planned_start_us"] and r["end_us"] == r["planned_end_us"]
        assert r["samples"] > 0 and r["encoder_rms_arcsec"] < r["encoder_peak_arcsec"] < 1.0
        inside = (t >= r["start_us"]) & (t <= r["end_us"])
        assert inside.sum() >= 20, r["target"]
        truth = (iss_truth(t[inside], site) if r["target"] == "ISS"
                 else star_truth(r["target"], t[inside], site))
        sep = sky_sep_arcsec(az[inside], el[inside], *truth)
        assert sep.max() < 1.0, (r["target"], sep.max())
    assert result["summary"]["done"] == 4 and result["summary"]["faulted"] == 0
    assert status["operation"]["phase"] in ("done", "aborted")  # the mount was brought to rest


def test_a_mount_fault_mid_block_makes_the_run_reset_replan_and_go_on(stars):
    site = load_site()
    first, second = stars["blocks"][0], stars["blocks"][1]

    async def scenario(vss, clock):
        run = asyncio.ensure_future(vss.server.call("run_plan", {"plan": stars, "wait": True}))
        mid = (second["start_us"] + second["end_us"]) // 2
        await clock.sleep((mid - clock.now_us) / 1e6)
        client = await vss.emulator.connect_in_memory(name="test-fault")
        await client.write({"axis.az.inject_encoder_fault": 1.0})
        await clock.sleep(0.5)
        await client.write({"axis.az.inject_encoder_fault": 0.0})
        await client.close()
        return await run

    result = run_lockstep_scenario("2024-05-18T21:20:00Z", scenario, site=site)
    records = result["records"]
    assert records[0]["target"] == first["target"] and records[0]["outcome"] == "done"
    faulted = records[1]
    assert faulted["target"] == second["target"] and faulted["outcome"] == "faulted"
    assert faulted["error"]["code"] == "mount_fault"
    assert len(result["replans"]) >= 1
    assert result["replans"][0]["reason"].startswith(f"{second['target']} #1 faulted")
    after = records[2:]
    assert after and all(r["outcome"] == "done" for r in after), records
    assert all(r["planned_start_us"] > faulted["end_us"] for r in after)
    assert result["state"] == "done"


def test_a_block_that_begins_late_is_late_with_its_delay_and_the_night_is_planned_again(stars):
    """The run starts 5 s before the first block: its slew from the park position takes
    longer, so tracking begins late (beyond LATE_S) but within GIVE_UP_S."""
    from virtualstar.planning.runner import GIVE_UP_S, LATE_S

    first = stars["blocks"][0]
    start = UtcTimes.from_unix_us(first["start_us"] - 5_000_000).iso(3)[0]

    async def scenario(vss, clock):
        return await vss.client().request("run_plan", {"plan": stars, "wait": True})

    result = run_lockstep_scenario(start, scenario, site=load_site())
    late = result["records"][0]
    assert late["target"] == first["target"] and late["outcome"] == "late", late
    began_us = late["start_us"]  # tracking began then (the block starts no earlier)
    assert late["delay_s"] == pytest.approx((began_us - first["start_us"]) / 1e6)
    assert LATE_S < late["delay_s"] < GIVE_UP_S
    assert late["on_target_rms_arcsec"] < 0.1  # late, but on target once there
    assert result["replans"][0]["reason"].startswith(f"{first['target']} #1 late")
    assert result["summary"]["late"] == 1 and result["state"] == "done"
    assert all(r["outcome"] == "done" for r in result["records"][1:]), result["records"]


def test_a_stop_ends_the_run_nothing_moves_after_and_resume_skips_what_was_done(stars):
    site = load_site()
    first = stars["blocks"][0]

    async def scenario(vss, clock):
        vs = vss.client()
        run = asyncio.ensure_future(vs.request("run_plan", {"plan": stars, "wait": True}))
        await clock.sleep((first["end_us"] + 20_000_000 - clock.now_us) / 1e6)
        await vs.request("stop")
        stopped = await run
        still = await sample_encoders(vss, clock, 10.0, reads=6)
        again = await vs.request("run_plan", {"plan": stars, "done": stopped["records"],
                                              "wait": True})
        return stopped, still, again

    stopped, still, again = run_lockstep_scenario("2024-05-18T21:20:00Z", scenario, site=site)
    assert stopped["state"] == "stopped"
    assert [r["outcome"] for r in stopped["records"]] == ["done", "stopped"]
    assert stopped["error"]["message"] == "ended by a client's stop"
    az, el = still.az_rad, still.el_rad
    assert np.ptp(az) < 1e-6 and np.ptp(el) < 1e-6  # stop is final: at rest, for a minute
    assert again["state"] == "done"
    redone = {r["target"] for r in again["records"]}
    assert first["target"] not in redone and redone  # the rest was observed, not the first
    assert again["replans"][0]["reason"].startswith("resumed")


def test_another_clients_motion_command_ends_the_program(stars):
    async def scenario(vss, clock):
        vs = vss.client()
        await vs.request("run_plan", {"plan": stars})
        with pytest.raises(Exception) as second:
            await vs.request("run_plan", {"plan": stars})
        await clock.sleep(30.0)
        await vs.request("slew", {"altaz": "180 50"})
        return second.value, await vs.request("program")

    refused, program = run_lockstep_scenario("2024-05-18T21:20:00Z", scenario,
                                             site=load_site())
    assert getattr(refused, "code", "") == "bad_request" and "already running" in str(refused)
    assert program["state"] == "stopped"
    assert program["error"]["message"] == "ended by a client's slew"


@pytest.mark.parametrize(("plan", "expected"), [
    ({"blocks": []}, "not a plan written by vs plan"),
    ("text", "wrong type"),
])
def test_a_wrong_plan_is_refused_and_the_server_keeps_serving(plan, expected):
    async def scenario(vss, clock):
        vs = vss.client()
        with pytest.raises(Exception) as refused:
            await vs.request("run_plan", {"plan": plan})
        return refused.value, await vs.request("ping")

    refused, pong = run_lockstep_scenario("2024-05-18T21:20:00Z", scenario, site=load_site())
    assert getattr(refused, "code", "") == "bad_request" and expected in str(refused)
    assert pong == {"pong": True}


def test_vs_run_on_the_emulator_prints_the_blocks_and_writes_json_and_png(short_stars_file,
                                                                         tmp_path):
    out, png = tmp_path / "run.json", tmp_path / "run.png"
    result = CliRunner().invoke(app, ["run", str(short_stars_file), "--emulator", "--speed", "max",
                                      "-o", str(out), "--png", str(png)])
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    planned = json.loads(short_stars_file.read_text())["blocks"]
    assert doc["state"] == "done" and doc["summary"]["done"] == len(planned) == 3
    assert all(r["target"] in result.stdout for r in doc["records"])
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_vs_run_records_the_chosen_signals_for_every_block(short_stars_file, tmp_path):
    from virtualstar.recorder import ParquetStoreReader

    out, store = tmp_path / "run.json", tmp_path / "store"
    signals = ["axis.az.position_deg", "axis.el.position_deg", "axis.az.error_arcsec"]
    args = ["run", str(short_stars_file), "--emulator", "-o", str(out), "--record-rate", "10",
            "--store", f"parquet:{store}"]
    for name in signals:
        args += ["--record", name]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    assert doc["recording"]["lost"] == 0 and doc["recording"]["names"] == signals
    reader = ParquetStoreReader(store)
    assert reader.gaps() == []
    site = load_site()
    for r in doc["records"]:
        w = reader.window(r["start_us"], r["end_us"], signals)
        # 10 samples per mount second, every one of the block's
        assert abs(len(w) - (r["end_us"] - r["start_us"]) / 1e5) <= 1, r["target"]
        az_deg, el_deg = star_truth(r["target"], w.t_us, site)
        sep = sky_sep_arcsec(w.columns["axis.az.position_deg"] % 360.0,
                             w.columns["axis.el.position_deg"], az_deg, el_deg)
        assert sep.max() < 1.0, (r["target"], sep.max())
        assert np.abs(w.columns["axis.az.error_arcsec"]).max() <= r["encoder_peak_arcsec"] + 0.05


def test_vs_run_on_a_running_server_records_from_the_mount_endpoint(short_stars_file, tmp_path):
    """The server path end to end: `vs server --emulator` in its own process (lockstep paced
    at ×50), `vs run --server` following it, the recorder on the emulator's ASTCom URL."""
    import re

    from virtualstar.recorder import ParquetStoreReader

    out, store = tmp_path / "run.json", tmp_path / "store"
    with vs_server_process("--emulator", "--speed", "50", "--start",
                           "2024-05-18T21:21:30Z") as server:
        mount = re.search(r"endpoint for other clients: (\S+)\)", server.line)
        assert mount, server.line
        result = CliRunner().invoke(app, [
            "run", str(short_stars_file), "--server", server.url, "-o", str(out), "--record",
            "axis.az.error_arcsec", "--record-rate", "10", "--mount", mount.group(1),
            "--store", f"parquet:{store}"])
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    assert doc["state"] == "done" and doc["records"], doc.get("error")
    assert doc["recording"]["lost"] == 0 and "error" not in doc["recording"]
    reader = ParquetStoreReader(store)
    observed = [r for r in doc["records"] if r["outcome"] in ("done", "late")]
    assert observed, [r["outcome"] for r in doc["records"]]
    for r in observed:  # every observed second of every block is in the store
        w = reader.window(r["start_us"], r["end_us"])
        assert abs(len(w) - (r["end_us"] - r["start_us"]) / 1e5) <= 1, r["target"]


@pytest.mark.parametrize(("extra", "expected"), [
    (["--record", "axis.az.nonsense"], "no signal axis.az.nonsense"),
    (["--record", "axis.az.position", "--record-rate", "0"], "--record-rate 0"),
    (["--record", "axis.az.position", "--store", "ftp:somewhere"], "store"),
    (["--store", "parquet:x"], "go with --record"),
])
def test_vs_run_refuses_wrong_recording_options_before_running(stars_file, extra, expected):
    result = CliRunner().invoke(app, ["run", str(stars_file), "--emulator", *extra])
    assert result.exit_code == 2, result.output
    assert expected in result.output


def test_vs_run_on_a_server_needs_the_mount_url_to_record(stars_file):
    result = CliRunner().invoke(app, ["run", str(stars_file), "--record", "axis.az.position"])
    assert result.exit_code == 2 and "--mount URL" in result.output


@pytest.mark.parametrize(("content", "expected"), [
    (None, "cannot read plan"),
    ("{not json", "not JSON"),
    ('{"program": "x"}', "not a plan written by vs plan"),
])
def test_vs_run_refuses_a_wrong_plan_file(tmp_path, content, expected):
    plan = tmp_path / "plan.json"
    if content is not None:
        plan.write_text(content)
    result = CliRunner().invoke(app, ["run", str(plan), "--emulator"])
    assert result.exit_code == 2 and expected in result.output


