"""Injected degradations: each does what its parameter says, measured against a model
written here (closed-form solutions, counts of what the encoder reported)."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from emulator_helpers import START_US, holding_mount, ticks

from astcom_client import Client, InvalidValue
from mount_emulator import layout as L
from mount_emulator.config import EmulatorConfig
from mount_emulator.emulator import MountEmulator
from mount_emulator.model import MountModel

RATE_RAD_S = math.radians(0.05)


def _moving_az() -> MountModel:
    """Return a mount whose azimuth moves at a constant 0.05°/s (settled), without cogging
    (its ripple would change the mean current from one stretch to the next)."""
    m = holding_mount()
    m.set_param("axis.az.cogging", 0.0)
    m.move(0, RATE_RAD_S)
    m.run(ticks(3.0))
    return m


def _mean_current(m: MountModel, seconds: float) -> float:
    return float(m.record(ticks(seconds), ["axis.az.current"])[:, 0].mean())


def test_winding_fault_steps_the_current_up_by_one_over_one_minus_the_loss():
    m = _moving_az()
    before = _mean_current(m, 2.0)
    m.set_param("axis.az.inject_winding_fault", 0.25)
    m.run(ticks(3.0))  # the velocity integrator takes the new gain up
    after = _mean_current(m, 2.0)
    assert after / before == pytest.approx(1 / 0.75, rel=0.02)


def test_friction_growth_adds_friction_at_its_rate_and_the_drive_pays_for_it():
    m = _moving_az()
    before = _mean_current(m, 2.0)
    m.set_param("axis.az.inject_friction_growth", 3600.0)  # 1 N·m per second
    m.run(ticks(1.5))
    m.set_param("axis.az.inject_friction_growth", 0.0)
    grown = m.state[L.state_index(0, L.A_FRIC_INJ)]
    assert grown == pytest.approx(1.5, rel=1e-9)
    m.run(ticks(3.0))
    kt = m.param("axis.az.torque_constant")
    assert _mean_current(m, 2.0) - before == pytest.approx(grown / kt, rel=0.03)


def test_heat_growth_raises_the_winding_temperature_as_a_first_order_model_says():
    m = holding_mount()  # azimuth at rest: no I²R heat to speak of
    g_w_h = 3600.0 * 5.0  # 5 W more every second
    m.set_param("axis.az.inject_heat_growth", g_w_h)
    t_s = 120.0
    temp = m.record(ticks(t_s), ["axis.az.temperature"])[:, 0]
    r_th = m.param("axis.az.thermal_resistance")
    tau = m.param("axis.az.thermal_tau")
    ambient = m.param("power.ambient_temperature")
    # dT/dt = (g·t·R_th − (T − T_a)) / τ, T(0) = T_a  →  T − T_a = g·R_th·(t − τ(1 − e^(−t/τ)))
    g = g_w_h / 3600.0
    expected = ambient + g * r_th * (t_s - tau * (1 - math.exp(-t_s / tau)))
    assert temp[-1] == pytest.approx(expected, rel=1e-3)


def test_resonance_growth_rattles_the_tracking_error_at_the_injected_frequency():
    m = holding_mount()
    m.set_param("axis.az.inject_resonance_hz", 7.0)
    m.set_param("axis.az.inject_resonance_growth", 3600.0 * 5.0)
    err = m.record(ticks(4.0), ["axis.az.error_arcsec"])[:, 0]
    quiet, loud = err[: ticks(1.0)], err[ticks(3.0):]
    assert np.std(loud) > 3 * np.std(quiet)
    spectrum = np.abs(np.fft.rfft(loud - loud.mean()))
    freqs = np.fft.rfftfreq(len(loud), 1e-4)
    assert freqs[np.argmax(spectrum)] == pytest.approx(7.0, abs=1.0)


def _glitch_ticks(m: MountModel, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Run `n` ticks; return the ticks (0-based) whose encoder counts differ from the true
    axis angle it sensed (the angle at the end of the tick before), and the differences."""
    cpr = 2.0 ** m.param("axis.az.encoder_bits") / (2 * math.pi)
    sensed = m.state[L.state_index(0, L.A_POS_M)]
    trace = m.record(n, ["axis.az.encoder_counts", "axis.az.true_position"])
    angle = np.r_[sensed, trace[:-1, 1]]
    diff = trace[:, 0] - np.floor(angle * cpr + 0.5)
    return np.flatnonzero(diff != 0), diff


def test_encoder_glitches_come_at_their_rate_with_their_size_on_the_same_ticks_every_run():
    runs = []
    for block in (ticks(10.0), 777):
        m = holding_mount()
        m.set_param("axis.az.inject_encoder_glitches", 50.0)
        m.set_param("axis.az.inject_encoder_glitch_counts", 3.0)
        found = []
        for start in range(0, ticks(10.0), block):
            idx, diff = _glitch_ticks(m, min(block, ticks(10.0) - start))
            found += list(idx + start)
            assert set(np.abs(diff[idx]).tolist()) <= {3.0}
        runs.append(found)
    assert runs[0] == runs[1]
    # 500 expected over 10 s: Poisson, 5 sigma ≈ ±112
    assert abs(len(runs[0]) - 500) < 112


def test_drift_growth_bends_the_mount_clock_as_its_integral_says():
    m = MountModel(start_us=START_US)
    d0 = m.param("time.drift_ppm")
    m.set_param("time.inject_drift_growth", 3600.0 * 10)  # +10 ppm every second
    t_s = 20.0
    m.run(ticks(t_s))
    offset_us = m.mount_time_us - m.true_time_us
    # ∫ (d0 + 10 t) dt over 20 s, in ppm·s = µs
    assert offset_us == pytest.approx(d0 * t_s + 10 * t_s**2 / 2, abs=1.5)


def test_clear_injections_ends_every_injection_and_its_grown_effects():
    m = _moving_az()
    for name, value in (("axis.az.inject_friction_growth", 3600.0),
                        ("axis.az.inject_heat_growth", 3600.0),
                        ("axis.az.inject_resonance_growth", 3600.0),
                        ("axis.az.inject_winding_fault", 0.3),
                        ("axis.az.inject_encoder_glitches", 10.0),
                        ("time.inject_drift_growth", 3600.0)):
        m.set_param(name, value)
    m.run(ticks(1.0))
    m.clear_injections()
    defaults = L.default_params()
    for slot in L.PARAM_SLOTS:
        if "inject_" in slot.name:
            assert m.params[slot.index] == defaults[slot.index], slot.name
    for field in (L.A_FRIC_INJ, L.A_RES_AMP, L.A_HEAT_INJ):
        assert m.state[L.state_index(0, field)] == 0.0
    assert m.state[L.G_DRIFT_INJ_PPM] == 0.0


def test_injections_are_registered_parameters_with_a_range_and_a_clear_function():
    asyncio.run(_registered_injections())


async def _registered_injections() -> None:
    emu = MountEmulator(EmulatorConfig(start_us=START_US, seeing_arcsec=0.0))
    await emu.start(None, run_loop=False)
    try:
        client = await Client.open(emu.endpoint.connect_in_memory(), name="test")
        infos = {i.name: i for i in emu.collection.infos()}
        for name in ("axis.az.inject_friction_growth", "axis.el.inject_winding_fault",
                     "axis.az.inject_resonance_growth", "axis.az.inject_resonance_hz",
                     "axis.el.inject_encoder_glitches", "axis.el.inject_encoder_glitch_counts",
                     "axis.az.inject_heat_growth", "time.inject_drift_growth"):
            assert infos[name].access == "rw", name
        await client.write({"axis.el.inject_winding_fault": 0.5})
        assert emu.model.param("axis.el.inject_winding_fault") == 0.5
        with pytest.raises(InvalidValue):
            await client.write({"axis.el.inject_winding_fault": 1.0})  # no torque at all: refused
        await client.invoke("fault.clear_injections")
        assert emu.model.param("axis.el.inject_winding_fault") == 0.0
        await client.close()
    finally:
        await emu.stop()
