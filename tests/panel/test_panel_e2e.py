"""The panel end to end in headless chromium against the mount emulator, checked with the Python client.

The page (panel/test/e2e/panel.e2e.mjs) connects, streams, computes, plots, writes a parameter
and runs a formula trajectory; this test then reads the parameter back with astcom_client and
compares the mount's trajectory reference, streamed here during the run, with the formulas
evaluated independently in numpy.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import numpy as np
import pytest
from panel_helpers import (
    ARTIFACTS,
    CHROMIUM,
    PANEL_DIR,
    PASSWORD,
    ensure_browser_ready,
    ensure_panel_built,
    node,
    start_emulator,
)

from astcom_client import Client
from virtualstar.panel import PanelConfig, PanelServer

TABS = ("board", "diagnostics", "signals", "plot", "compute", "parameters", "input")
PARAM_NAME, PARAM_VALUE = "axis.az.kp", "29.75"
# The formulas as typed in the page (degrees, t in s) and the same written in numpy.
AZ_FORMULA = "p0 + 0.3 * sin(2 * pi * 0.5 * t)"
EL_FORMULA = "p0 - 0.2 * (1 - cos(2 * pi * 0.5 * t))"


DURATION_S, STEP_S, RAMP_S = 3.0, 0.02, 1.0
# the page reads the mount time, samples the formulas, pushes and starts the trajectory within
# this lead: a busy host's browser once took 0.56 s, and the mount then began 60 ms into the ramp
LEAD_S = 1.5


def ramped(f, t, p0):
    """The formula `f` blended in from p0 over the first RAMP_S and out to its final value over
    the last (docs/panel.md): a quintic 0 -> 1 with zero slope and curvature at its ends."""
    def weight(x):
        x = np.clip(x, 0.0, 1.0)
        return x**3 * (10 - 15 * x + 6 * x**2)
    end = f(DURATION_S, p0)
    blended_in = p0 + weight(t / RAMP_S) * (f(t, p0) - p0)
    return end + weight((DURATION_S - t) / RAMP_S) * (blended_in - end)


def az_deg_of(t, p0):
    return ramped(lambda tt, p: p + 0.3 * np.sin(2 * np.pi * 0.5 * tt), t, p0)


def el_deg_of(t, p0):
    return ramped(lambda tt, p: p - 0.2 * (1 - np.cos(2 * np.pi * 0.5 * tt)), t, p0)

# Hermite interpolation between 20 ms samples of these sines is far inside this
REFERENCE_TOL_DEG = 1e-4
# the mount's azimuth following error while it runs the ramped formulas (0.6″ measured; 90″
# without the ramp)
FOLLOWING_PEAK_ARCSEC = 5.0


@pytest.fixture(scope="module")
def emulator():
    emu = start_emulator()
    yield emu
    emu.stop()


@pytest.fixture(scope="module")
def panel_url():
    ensure_panel_built()
    with PanelServer(PanelConfig(port=0)) as server:
        yield server.start()


async def _run(emulator_url: str, panel_url: str, result_path) -> tuple[dict, dict]:
    """Run the page script while streaming the trajectory reference; return (result, stream)."""
    names = ["traj.ref_az", "traj.ref_el", "axis.az.state", "axis.az.error"]
    got: dict[str, list] = {"t_us": [], "az": [], "el": [], "state": [], "error": [], "lost": 0}
    async with await Client.connect(emulator_url, password=PASSWORD) as client:
        stream = await client.stream(names, rate_hz=500)

        async def collect():
            async for packet in stream:
                got["t_us"].extend(packet.t_us.tolist())
                got["az"].extend(packet.column("traj.ref_az").tolist())
                got["el"].extend(packet.column("traj.ref_el").tolist())
                got["state"].extend(packet.column("axis.az.state").tolist())
                got["error"].extend(packet.column("axis.az.error").tolist())
                got["lost"] += packet.lost

        collector = asyncio.create_task(collect())
        proc = await asyncio.create_subprocess_exec(
            node(), "test/e2e/panel.e2e.mjs", cwd=PANEL_DIR,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
            env={"PATH": "/usr/bin:/bin:/usr/local/bin", "HOME": str(result_path.parent),
                 "PANEL_URL": panel_url, "ASTCOM_URL": emulator_url, "ASTCOM_PASSWORD": PASSWORD,
                 "ARTIFACTS": str(ARTIFACTS), "RESULT": str(result_path),
                 "PARAM_NAME": PARAM_NAME, "PARAM_VALUE": PARAM_VALUE,
                 "AZ_FORMULA": AZ_FORMULA, "EL_FORMULA": EL_FORMULA,
                 "TRAJ_DURATION_S": str(DURATION_S), "TRAJ_STEP_S": str(STEP_S),
                 "TRAJ_RAMP_S": str(RAMP_S),
                 "TRAJ_LEAD_S": str(LEAD_S),
                 "CHROMIUM_PATH": str(CHROMIUM)})
        out, _ = await asyncio.wait_for(proc.communicate(), timeout=75)
        result = json.loads(result_path.read_text()) if result_path.exists() else {}
        result["log"] = out.decode(errors="replace")
        run = result.get("trajectory") or {}
        if run:  # keep streaming until the mount has passed the trajectory's last point
            end_us = run["t0_us"] + int((DURATION_S + 0.3) * 1e6)
            while not got["t_us"] or got["t_us"][-1] < end_us:
                await asyncio.sleep(0.1)
        collector.cancel()
        await stream.stop()
        result["param_read_back"] = (await client.read([PARAM_NAME]))[PARAM_NAME]
        result["units"] = {e.name: e.unit for e in await client.list("axis.az.")}
        result["traj_counts"] = await client.read(["traj.accepted", "traj.late", "traj.underruns"])
    return result, got


@pytest.fixture(scope="module")
def e2e(emulator, panel_url, tmp_path_factory):
    ensure_browser_ready()
    result_path = tmp_path_factory.mktemp("e2e") / "result.json"
    result, got = asyncio.run(_run(emulator.url, panel_url, result_path))
    assert result.get("ok"), result.get("error", "") + "\n" + result["log"]
    return result, got


def test_page_connects_and_discovers_the_endpoint_list(e2e):
    result, _ = e2e
    assert result["entries"] > 150
    assert result["quickStart"] == "mount.power_on"  # found by name in LIST, not hard-coded
    assert result["nowUs"] > 1.7e15
    assert not result.get("pageErrors"), result.get("pageErrors")


def test_the_plot_asks_for_no_animation_frame_while_idle_or_hidden(e2e):
    """A redraw loop would cost the browser CPU on every operator's laptop for nothing."""
    result, _ = e2e
    assert result["idlePlotFrames"] == 0
    assert result["hiddenPlot"]["samples"] > 0 and result["hiddenPlot"]["frames"] == 0


def test_streamed_signal_reaches_the_plot_without_loss(e2e):
    result, _ = e2e
    plot = result["plot"]
    assert plot["samples"] > 500 and plot["lost"] == 0
    assert plot["plotUpdates"] > 5 and plot["plotPoints"] > 50
    assert "az_err_arcsec" in plot["lastPlotSeries"] and "axis.az.error" in plot["lastPlotSeries"]


def test_compute_expression_matches_its_signal_sample_by_sample_and_reloads_from_file(e2e):
    result, _ = e2e
    assert result["computeCheck"]["n"] > 0 and result["computeCheck"]["worst"] < 1e-9
    saved = result["savedCompute"]
    assert saved["tab"] == "Compute"
    assert saved["state"]["expressions"][0]["expr"] == "axis.az.error * 3600 * 180 / pi"
    assert result["reloadedExpr"] == "axis.az.error * 3600 * 180 / pi"


def test_parameter_written_in_the_page_reads_back_with_the_python_client(e2e):
    result, _ = e2e
    assert result["param_read_back"] == float(PARAM_VALUE)
    assert result["paramShown"].strip() == PARAM_VALUE


def _decimals(label: str) -> int:
    return len(label.split(".")[1]) if "." in label and "e" not in label else 0


def test_every_y_axis_has_several_ticks_labelled_alike_and_the_unit_from_list(e2e):
    result, _ = e2e
    units = result["units"]  # LIST read by the Python client
    assert units["axis.az.error"] == "rad" and units["axis.az.position_deg"] == "deg"
    # one plot per series in stream order: axis.az.error, axis.az.position_deg, then the compute
    # (the compute's unit is the one typed on the Compute tab)
    assert sorted(result["stackedAxes"]) == ["0:rad", "1:deg", "2:arcsec"]
    # all in one plot: one y axis per unit
    assert sorted(result["allInOneAxes"]) == ["0:arcsec", "0:deg", "0:rad"]
    for labels in [*result["stackedAxes"].values(), *result["allInOneAxes"].values()]:
        assert len(labels) >= 4 and len(set(labels)) == len(labels), labels
        assert len({_decimals(x) for x in labels}) == 1, labels
        assert all(len(x) <= 10 for x in labels), labels  # no "-0.008274955"


def test_an_angle_can_be_plotted_in_arcseconds_on_its_own_axis(e2e):
    result, _ = e2e
    chosen = result["unitChosen"]
    # stacked: the first plot's axis (axis.az.error, LIST says rad) now reads arcsec
    assert "0:arcsec" in chosen["axes"] and "0:rad" not in chosen["axes"]
    drawn = chosen["drawn"]["axis.az.error"]
    assert drawn["unit"] == "arcsec" and drawn["points"] > 50
    assert drawn["factor"] == pytest.approx(180 / math.pi * 3600, rel=1e-12)
    assert drawn["departure"] == 0
    other = chosen["drawn"]["axis.az.position_deg"]
    assert (other["unit"], other["factor"], other["departure"]) == ("deg", 1, 0)


def test_csv_export_holds_every_sample_of_the_visible_window_with_units(e2e):
    result, _ = e2e
    lines = Path(result["csvPath"]).read_text().splitlines()
    assert lines[0] == ("t_us [µs mount time],t [s],axis.az.error [rad],"
                        "axis.az.position_deg [deg],az_err_arcsec [arcsec]")
    rows = np.array([[float(x) if x else np.nan for x in line.split(",")] for line in lines[1:]])
    t_us = rows[:, 0]
    # 1 kHz, not decimated, nothing missing; the mount clock's discipline moves a tick by 1 µs
    assert np.all(np.abs(np.diff(t_us) - 1000) <= 1)
    span_s = (t_us[-1] - t_us[0]) / 1e6
    assert 1.0 < span_s <= result["csvWindowS"] + 1e-3
    assert np.allclose(rows[:, 1], (t_us - t_us[0]) / 1e6 + rows[0, 1], atol=1e-6)
    computed = ~np.isnan(rows[:, 4])
    assert computed.sum() > 500
    assert np.allclose(rows[computed, 4], rows[computed, 2] * 3600 * 180 / np.pi, rtol=1e-12, atol=1e-12)


def test_formula_trajectory_is_followed_by_the_mount_reference(e2e):
    result, got = e2e
    run = result["trajectory"]
    n_points = int(DURATION_S / STEP_S) + 1
    assert run["n"] == n_points and run["accepted"] == n_points
    counts = result["traj_counts"]
    assert counts["traj.accepted"] == n_points and counts["traj.late"] == 0
    t_us = np.array(got["t_us"], dtype=np.int64)
    t_s = (t_us - run["t0_us"]) / 1e6
    inside = (t_s > STEP_S) & (t_s < DURATION_S - STEP_S)
    assert inside.sum() > 0.9 * (DURATION_S - 2 * STEP_S) * 500 and got["lost"] == 0
    p0_az, p0_el = (a["p0"] for a in run["axes"])
    az_deg = np.degrees(np.array(got["az"]))[inside]
    el_deg = np.degrees(np.array(got["el"]))[inside]
    assert np.max(np.abs(az_deg - az_deg_of(t_s[inside], p0_az))) < REFERENCE_TOL_DEG
    assert np.max(np.abs(el_deg - el_deg_of(t_s[inside], p0_el))) < REFERENCE_TOL_DEG
    tracking = 3  # AxisState.TRACKING, as listed in the emulator's doc of axis.az.state
    assert np.all(np.array(got["state"])[inside] == tracking)
    assert math.isfinite(p0_az) and math.isfinite(p0_el)


def test_ramped_trajectory_starts_without_a_following_error_transient(e2e):
    """The formulas start at full speed (0.94°/s in azimuth): stepping into them made the mount
    lag by about 90″ at once; ramped in, the axis follows within a few arcseconds throughout."""
    result, got = e2e
    t_s = (np.array(got["t_us"], dtype=np.int64) - result["trajectory"]["t0_us"]) / 1e6
    during = (t_s >= 0) & (t_s <= DURATION_S)
    assert during.sum() > 0.9 * DURATION_S * 500
    peak_arcsec = np.degrees(np.max(np.abs(np.array(got["error"])[during]))) * 3600
    assert peak_arcsec < FOLLOWING_PEAK_ARCSEC


def test_trajectory_is_previewed_its_progress_shown_and_logged_with_the_parameter_write(e2e):
    result, _ = e2e
    assert result["previewStatus"].startswith(f"preview: {int(DURATION_S / STEP_S) + 1} points")
    n = int(DURATION_S / STEP_S) + 1
    assert f"{n} / {n}" in result["progress"] and f"/ {DURATION_S:g} s" in result["progress"]
    log = result["logAfterTrajectory"]
    assert f"trajectory: {n} points over {DURATION_S:g} s" in log and f"(ramps {RAMP_S:g} s)" in log
    assert AZ_FORMULA in log and f"trajectory fed: {n} of {n} points pushed, {n} accepted" in log
    assert f"wrote {PARAM_NAME} = {PARAM_VALUE}" in log


def test_wrong_password_is_reported_in_the_board_log(e2e):
    result, _ = e2e
    assert "wrong password" in result["wrongPasswordLog"] and "401" in result["wrongPasswordLog"]


def test_every_tab_saves_its_state_and_loads_it_back(e2e):
    result, _ = e2e
    states = result["states"]
    assert sorted(states) == sorted([*(t.capitalize() for t in TABS), "Telescope", "Log"])
    for tab, doc in states.items():
        assert doc["panel"] == "virtualstar-rsp" and doc["tab"] == tab and doc["version"] == 1
    assert "password" not in json.dumps(states["Board"]["state"])
    assert states["Signals"]["state"]["chosen"] == ["axis.az.error", "axis.az.position_deg"]
    assert states["Parameters"]["state"]["values"][PARAM_NAME] == float(PARAM_VALUE)
    axes = {a["arg"]: a for a in states["Input"]["state"]["trajectory"]["axes"]}
    assert axes["az_rad"]["expr"] == AZ_FORMULA and axes["el_rad"]["p0_signal"] == "axis.el.position"
    assert states["Compute"]["state"]["expressions"][0]["name"] == "az_err_arcsec"
    assert states["Compute"]["state"]["expressions"][0]["unit"] == "arcsec"
    assert states["Log"]["state"] == {"filters": {"from": "", "to": "", "level": "debug", "source": "",
                                                  "kind": "", "text": ""}, "following": True,
                                      "show_routine": False, "wrap_fields": False}


def test_an_injected_fault_turns_its_diagnostics_card_and_board_row_red(e2e):
    result, _ = e2e
    assert "axis.el" in result["faultCards"] and "axis.az" not in result["faultCards"]
    assert "axis.el.fault_text" in result["faultRows"] and "axis.az.fault_text" not in result["faultRows"]


def test_a_screenshot_of_each_tab_is_kept(e2e):
    for tab in TABS:
        png = ARTIFACTS / f"{tab}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", png
        assert png.stat().st_size > 10_000, f"{png} looks empty"
