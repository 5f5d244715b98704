"""The emulator behind a real ASTCom Endpoint: registry, client commands, CLI, streaming."""

from __future__ import annotations

import asyncio
import json
import math
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from emulator_helpers import START_US
from typer.testing import CliRunner

from astcom_client import Client, DeviceError, InvalidValue
from mount_emulator.cli import app
from mount_emulator.config import EmulatorConfig
from mount_emulator.emulator import MountEmulator
from mount_emulator.geometry import Geometry
from mount_emulator.model import MountModel

BIN = Path(sys.executable).parent
VSS_NAMES = [
    "axis.az.position", "axis.el.position", "axis.az.encoder_counts", "axis.az.velocity",
    "axis.az.error", "axis.az.error_arcsec", "axis.el.error_arcsec", "axis.az.state",
    "axis.el.state", "axis.az.faults", "mount.state", "mount.status_bits", "time.mount_us",
    "traj.free", "traj.push", "traj.push_rates", "traj.init", "traj.start", "traj.reset",
    "traj.free_points", "traj.late", "traj.underruns", "time.set_utc", "safety.reset",
    "mount.slew", "mount.power_on", "guide.measure", "axis.az.kp", "axis.az.current",
    "axis.az.temperature",
]


def _config(**kw) -> EmulatorConfig:
    return EmulatorConfig(start_us=START_US, geometry=Geometry(ia=120.0, ie=-60.0),
                          seeing_arcsec=0.0, **kw)


def test_collection_registers_named_variables_with_units_and_the_vss_names():
    emu = MountEmulator(_config())
    infos = {i.name: i for i in emu.collection.infos()}
    variables = [i for i in infos.values() if i.kind != "function"]
    assert len(variables) >= 50
    for name in VSS_NAMES:
        assert name in infos, name
    assert infos["axis.az.position"].unit == "rad"
    assert infos["axis.el.temperature"].unit == "degC"
    assert infos["axis.az.kp"].access == "rw"
    assert all(re.fullmatch(r"[a-z_]+(\.[a-z0-9_]+)+", n) for n in infos)


def test_physical_quantities_are_registered_as_floats_not_integers():
    # A value in rad, rad/s, A, … typed as an integer would be cut to whole units on the wire.
    emu = MountEmulator(_config())
    infos = [i for i in emu.collection.infos() if i.kind != "function"]
    physical = [i for i in infos if i.unit in {"rad", "rad/s", "rad/s^2", "A", "V", "degC", "Nm"}]
    assert {"axis.az.target", "axis.el.manual_rate"} <= {i.name for i in physical}
    wrong = [(i.name, i.type) for i in physical if not i.type.startswith("f")]
    assert not wrong, wrong


MEASURED_UNITS = {"A", "V", "W", "J", "degC", "arcsec", "N*m"}


def test_measured_quantities_are_single_precision_and_positions_times_parameters_stay_double():
    # The MCU reports ADC/sensor readings and arcsec errors as f32; angles, rates, times,
    # ticks and parameters keep f64/i64 (docs/mount-emulator.md, "Wire types").
    emu = MountEmulator(_config())
    infos = {i.name: i for i in emu.collection.infos() if i.kind != "function"}
    traced = [v for v in emu.collection if getattr(v, "trace_column", None) is not None]
    measured = {v.name for v in traced if v.unit in MEASURED_UNITS}
    assert {"axis.az.current", "axis.el.temperature", "power.bus_voltage", "power.supply_power",
            "power.regen_energy", "axis.az.error_arcsec", "axis.el.load_error_arcsec"} <= measured
    assert {v.name for v in traced if v.type == "f32"} == measured
    doubles = {"rad", "rad/s", "rad/s^2", "deg", "deg/s", "us", "rad*s"}
    wrong = [(v.name, v.type) for v in traced if v.unit in doubles and v.type == "f32"]
    assert not wrong, wrong
    assert infos["time.mount_us"].type == "i64" and infos["mount.tick"].type == "i64"
    params = [i for i in infos.values() if i.kind == "parameter"]
    assert len(params) > 80 and {i.type for i in params} == {"f64"}


def test_f32_signals_read_and_stream_the_float64_state_rounded_to_single_precision():
    names = ["axis.az.position", "axis.az.current", "axis.az.error_arcsec"]

    async def main():
        emu = MountEmulator(_config(speed=0.0))  # not started: we step it ourselves
        emu.model.power_on()
        emu.model.slew(math.radians(0.5), math.radians(20.2))
        client = await Client.open(emu.endpoint.connect_in_memory())
        try:
            stream = await client.stream(names, rate_hz=1000.0)
            first_tick = int(emu.model.state[0]) + 1
            for _ in range(3):
                emu.advance(400)
            read = await client.read(names)
            for _ in range(20):
                await asyncio.sleep(0)
            packet = await stream.get(2.0)
        finally:
            await client.close()
            await emu.endpoint.close()
        return first_tick, read, packet

    first_tick, read, packet = asyncio.run(main())
    # the truth: an identical model stepped directly, float64 state, no ASTCom involved
    twin = MountModel(start_us=START_US, az_rad=0.0, el_rad=math.radians(20.0),
                      params=MountEmulator(_config()).model.params)
    twin.power_on()
    twin.slew(math.radians(0.5), math.radians(20.2))
    twin_record = twin.record(1200, names)
    rows = packet.ticks - first_tick
    truth = twin_record[rows]
    assert packet.column("axis.az.position").dtype == np.float64
    assert packet.column("axis.az.position").tobytes() == truth[:, 0].tobytes()
    for j, name in enumerate(names[1:], start=1):
        col = packet.column(name)
        assert col.dtype == np.float32
        assert col.tobytes() == truth[:, j].astype(np.float32).tobytes()
    assert np.abs(truth[:, 1]).max() > 0.1  # the slew really drew current
    assert read["axis.az.current"] == float(np.float32(twin_record[-1, 1]))
    assert read["axis.az.position"] == twin_record[-1, 0]


def test_a_fractional_slew_target_reads_back_unrounded():
    async def body(emu, c):
        await c.invoke("mount.power_on")
        await c.invoke("mount.slew", 12.5, 35.25)
        target = (await c.read(["axis.az.target"]))["axis.az.target"]
        assert target == pytest.approx(math.radians(12.5), abs=1e-12)
    asyncio.run(_with_client(_config(speed=0.0), body))


async def _with_client(config: EmulatorConfig, body):
    emu = MountEmulator(config)
    url = await emu.start("ws://127.0.0.1:0")
    try:
        async with await Client.connect(url) as client:
            return await body(emu, client)
    finally:
        await emu.stop()


async def _wait_for(client, name, predicate, limit_reads=2000):
    for _ in range(limit_reads):
        value = (await client.read([name]))[name]
        if predicate(value):
            return value
        await asyncio.sleep(0.005)
    raise AssertionError(f"{name} never satisfied the condition")


def test_client_slews_in_simulated_time_and_sees_mount_time():
    async def body(emu, c):
        t0 = (await c.read(["time.mount_us"]))["time.mount_us"]
        assert START_US <= t0 < START_US + 60_000_000
        await c.invoke("mount.power_on")
        await c.invoke("mount.slew", 12.0, 35.0)
        await _wait_for(c, "mount.state_name", lambda v: v == "SLEWING")
        await _wait_for(c, "mount.state_name", lambda v: v == "HOLDING")
        values = await c.read(["axis.az.position_deg", "axis.el.position_deg", "time.mount_us"])
        assert values["axis.az.position_deg"] == pytest.approx(12.0, abs=1 / 3600)
        assert values["axis.el.position_deg"] == pytest.approx(35.0, abs=1 / 3600)
        assert values["time.mount_us"] - t0 > 4_000_000  # a 12° slew takes > 4 s of mount time
        with pytest.raises(DeviceError, match="outside the axis limits"):
            await c.invoke("mount.slew", 12.0, 95.0)
    asyncio.run(_with_client(_config(speed=0.0), body))


def test_client_tracks_a_pushed_trajectory_and_gain_writes_apply():
    async def body(emu, c):
        await c.invoke("mount.power_on")
        now = (await c.read(["time.mount_us"]))["time.mount_us"]
        el0 = math.radians(20.0)
        rate = math.radians(0.01)
        t = now + 20_000_000 + np.arange(400, dtype=np.int64) * 100_000
        s = (t - t[0]) * 1e-6
        n = await c.invoke("traj.push_rates", t, rate * s, el0 + rate * s,
                           np.full(400, rate), np.full(400, rate))
        assert n == 400
        assert await c.invoke("traj.free") == emu.model.traj_capacity - 1 - 400
        await c.invoke("traj.start")
        await _wait_for(c, "time.mount_us", lambda v: v > t[0] + 5_000_000)
        await c.write({"axis.az.kp": 45.0})
        assert emu.model.param("axis.az.kp") == 45.0
        err = await c.read(["axis.az.error_arcsec", "axis.el.error_arcsec", "mount.state_name"])
        assert err["mount.state_name"] == "TRACKING"
        assert abs(err["axis.az.error_arcsec"]) < 0.1 and abs(err["axis.el.error_arcsec"]) < 0.1
        with pytest.raises(InvalidValue, match="is below its minimum"):
            await c.write({"axis.az.inertia_load": -1.0})
        late = await c.invoke("traj.push", np.array([now], dtype=np.int64), [0.0], [el0])
        assert late == 0
        assert (await c.read(["traj.late"]))["traj.late"] == 1
    asyncio.run(_with_client(_config(speed=0.0), body))


def test_guide_measure_reports_the_hidden_index_errors():
    async def body(emu, c):
        dx, dy = await c.invoke("guide.measure", 0.0, 20.0)  # encoders at az 0°, el 20°
        # pure index terms, TPOINT: sky − encoder = Δ with ΔA = −IA, ΔE = +IE; with the
        # encoders on the star's place the axis is at (A − IA, E + IE): star − axis = (IA·cosE, −IE)
        assert dx == pytest.approx(120.0 * math.cos(math.radians(20.0)), abs=0.01)
        assert dy == pytest.approx(60.0, abs=0.01)
    asyncio.run(_with_client(_config(speed=0.0), body))


def test_time_set_utc_over_astcom_applies_on_the_pps_edge():
    async def body(emu, c):
        await c.write({"time.drift_ppm": 0.0})
        now = (await c.read(["time.mount_us"]))["time.mount_us"]
        target = now // 1_000_000 + 3600  # one hour ahead
        await c.invoke("time.set_utc", target)
        await _wait_for(c, "time.sync_count", lambda v: v == 1)
        v = await c.read(["time.mount_us", "time.true_us"])  # both at one tick
        offset_us = v["time.mount_us"] - v["time.true_us"]
        assert offset_us % 1_000_000 == 0  # the jump happened exactly on a whole true second
        assert 3590 <= offset_us // 1_000_000 <= 3600
        assert v["time.mount_us"] >= target * 1_000_000
    asyncio.run(_with_client(_config(speed=0.0), body))


def _start_cli(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([str(BIN / "mount-emulator"), "--port", "0", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    match = re.search(r"(ws|tcp)://\S+", line)
    if not match:
        proc.kill()
        raise AssertionError(f"no URL printed: {line!r} {proc.stderr.read()}")
    return proc, match.group(0)


def test_astcom_stream_cli_gets_4_signals_at_10_khz_for_5_s_without_loss():
    proc, url = _start_cli("--seed", "1")
    try:
        out = subprocess.run(
            [str(BIN / "astcom"), "stream", url, "axis.az.error_arcsec", "axis.el.error_arcsec",
             "axis.az.position", "mount.state", "--rate", "10000", "--duration", "5", "--json"],
            capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        report = json.loads(out.stdout)
        assert report["lost"] == 0
        assert report["rate_hz"] == 10000.0
        counts = set(report["samples"].values())
        assert len(counts) == 1
        # every tick the emulator computed while streaming arrived (nothing dropped)
        assert counts.pop() >= 0.5 * 5 * 10_000
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)


def test_cli_shuts_down_cleanly_on_sigterm_in_simulated_time():
    proc, url = _start_cli("--speed", "max", "--start", "2026-03-01T20:00:00Z", "--transport", "tcp",
                           "--seed", "3")
    assert url.startswith("tcp://127.0.0.1:")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=20) == 0
    assert "stopped" in proc.stdout.read()


@pytest.mark.parametrize(("args", "message"), [
    (["--host", "0.0.0.0"], "not a loopback address: give --password"),
    (["--speed", "fast"], "expected a positive number (1 = real time) or 'max'"),
    (["--start", "yesterday"], "expected ISO-8601 UTC"),
    (["--transport", "udp"], "expected ws or tcp"),
    (["--seed", "1", "--geometry", "g.toml"], "either --geometry FILE or --seed N"),
])
def test_cli_rejects_bad_arguments_with_a_clear_message(args, message):
    result = CliRunner().invoke(app, args, env={"ASTCOM_PASSWORD": ""})
    assert result.exit_code == 2
    assert message in result.output


def test_cli_rejects_a_config_naming_an_unknown_parameter(tmp_path):
    cfg = tmp_path / "mount.toml"
    cfg.write_text("[axis.az]\nkpp = 3.0\n")
    result = CliRunner().invoke(app, ["--config", str(cfg)])
    assert result.exit_code == 2
    assert "unknown parameter 'axis.az.kpp'; did you mean axis.az.kp" in result.output


def test_config_file_sets_parameters_and_start_position(tmp_path):
    from mount_emulator.config import load_config_file

    cfg = tmp_path / "mount.toml"
    cfg.write_text("[emulator]\nel_deg = 45.0\n[axis.el]\nkp = 20.0\n[time]\ndrift_ppm = 0.5\n"
                   "[geometry]\nIA = 30\n")
    config = load_config_file(cfg)
    emu = MountEmulator(config)
    assert emu.model.param("axis.el.kp") == 20.0
    assert emu.model.param("time.drift_ppm") == 0.5
    assert emu.model.axis_slot(1, 6) == pytest.approx(math.radians(45.0), abs=1e-7)
    assert config.geometry == Geometry(ia=30.0)


if os.name != "posix":  # pragma: no cover
    pytest.skip("signals", allow_module_level=True)
