"""The compiled step: plant, control loops and their documented settling figures.

Settling figures checked here are the ones stated in docs/mount-emulator.md.
All runs are in simulated time through the pure step (via MountModel).
"""

from __future__ import annotations

import math

import numpy as np
from emulator_helpers import ONE_ARCSEC, SIDEREAL_RATE, holding_mount, star_altaz, ticks

from mount_emulator import layout as L
from mount_emulator.states import AxisState

STEP_SETTLE_S = (0.2, 1.0)  # a 10″ reference step is within 0.3″ after 0.2 s, 0.1″ after 1 s (docs)
RAMP_SETTLE_S = 1.0  # 1 s after reaching a 0.5 °/s ramp (1 °/s²) the error is within 0.1″ (docs)
SLEW_SETTLE_S = 1.0  # after the profile ends a slew is within 1″ (docs)


def test_structural_resonance_lies_in_10_to_30_hz_and_is_resolved(mount):
    for a, axis in enumerate(L.AXES):
        for name in ("coulomb_friction", "viscous_friction", "brake_torque", "cogging", "gravity_imbalance"):
            mount.set_param(f"axis.{axis}.{name}", 0.0)
        mount.state[L.state_index(a, L.A_POS_L)] += 100 * ONE_ARCSEC  # pluck the tube
    trace = mount.record(ticks(4.0), ["axis.az.twist_arcsec", "axis.el.twist_arcsec"])
    freqs = np.fft.rfftfreq(len(trace), 1e-4)
    for a, axis in enumerate(L.AXES):
        jm = mount.param(f"axis.{axis}.inertia_motor")
        jl = mount.param(f"axis.{axis}.inertia_load")
        k = mount.param(f"axis.{axis}.stiffness")
        expected_hz = math.sqrt(k * (1 / jm + 1 / jl)) / (2 * math.pi)
        spectrum = np.abs(np.fft.rfft(trace[:, a] - trace[:, a].mean()))
        measured_hz = freqs[np.argmax(spectrum)]
        assert 10.0 <= measured_hz <= 30.0
        assert abs(measured_hz - expected_hz) < 0.5  # 100 µs steps resolve the mode


def test_reference_step_settles_within_documented_time():
    m = holding_mount()
    for a in range(2):
        m.state[L.state_index(a, L.A_REF)] += 10 * ONE_ARCSEC
    trace = m.record(ticks(1.5), ["axis.az.error_arcsec", "axis.el.error_arcsec"])
    assert np.abs(trace[ticks(STEP_SETTLE_S[0]):]).max() < 0.3
    assert np.abs(trace[ticks(STEP_SETTLE_S[1]):]).max() < 0.1
    assert np.abs(trace[:10]).max() > 9.0  # it was a real step


def _push_line(m, rate_rad_s, seconds, spacing_s=0.1, with_rates=True):
    t0 = m.mount_time_us
    t = t0 + np.arange(1, int(seconds / spacing_s) + 1) * int(spacing_s * 1e6)
    s = (t - t0) * 1e-6
    az0 = m.axis_slot(0, L.A_REF)
    el0 = m.axis_slot(1, L.A_REF)
    rates = (np.full(len(t), rate_rad_s), np.full(len(t), rate_rad_s)) if with_rates else (None, None)
    return m.traj_push(t, az0 + rate_rad_s * s, el0 + rate_rad_s * s, *rates)


def test_ramp_from_rest_settles_within_documented_time():
    m = holding_mount()
    rate = math.radians(0.5)
    accel = math.radians(1.0)
    t_acc = rate / accel
    # rest for 0.1 s, accelerate at 1 °/s² to 0.5 °/s, then a constant-rate ramp
    t0 = m.mount_time_us
    t = t0 + np.arange(1, 40) * 100_000
    s = np.maximum((t - t0) * 1e-6 - 0.1, 0.0)
    pos = np.where(s < t_acc, 0.5 * accel * s**2, rate * (s - t_acc / 2))
    vel = np.where(s < t_acc, accel * s, rate)
    az0, el0 = m.axis_slot(0, L.A_REF), m.axis_slot(1, L.A_REF)
    assert m.traj_push(t, az0 + pos, el0 + pos, vel, vel) == len(t)
    m.traj_start()
    trace = m.record(ticks(3.5), ["axis.az.error_arcsec", "axis.el.error_arcsec"])
    assert np.abs(trace[ticks(0.1 + t_acc + RAMP_SETTLE_S):]).max() < 0.1
    assert np.abs(trace).max() > 0.1  # the ramp did load the loops


def test_sidereal_tracking_error_below_a_tenth_arcsec_rms_after_settling():
    m = holding_mount()
    lat = math.radians(48.0)
    dec = math.radians(30.0)
    ha0 = math.radians(-30.0)
    az_start, el_start = star_altaz(ha0, dec, lat)
    m.slew(float(az_start), float(el_start))
    m.run(ticks(25.0))
    assert m.mount_state == AxisState.HOLDING
    # star path from 1 s ahead, points every 0.2 s without rates (the buffer estimates them)
    t0 = m.mount_time_us
    lead = 1_000_000
    t = t0 + lead + np.arange(0, 200) * 200_000
    az, el = star_altaz(ha0 + SIDEREAL_RATE * (t - t0 - lead) * 1e-6, dec, lat)
    m.slew(float(az[0]), float(el[0]))
    m.run(ticks(0.5))
    assert m.traj_push(t, az, el) == 200
    m.traj_start()
    trace = m.record(ticks(30.0), ["axis.az.error_arcsec", "axis.el.error_arcsec"])
    settled = trace[ticks(6.0):]
    rms = np.sqrt((settled**2).mean(axis=0))
    assert (rms < 0.1).all(), rms
    assert m.axis_state(0) == AxisState.TRACKING


def test_slew_lands_within_one_arcsec_after_the_profile():
    m = holding_mount()
    target = (math.radians(35.0), math.radians(60.0))
    m.slew(*target)
    # az: 35° at 6°/s, 3°/s² takes 35/6 + 6/3 = 7.83 s; el moves 40° in 8.67 s
    profile_s = max(35 / 6 + 2.0, 40 / 6 + 2.0)
    trace = m.record(ticks(profile_s + SLEW_SETTLE_S + 0.5),
                     ["axis.az.position", "axis.el.position", "axis.az.velocity"])
    after = trace[ticks(profile_s + SLEW_SETTLE_S):]
    assert np.abs(after[:, 0] - target[0]).max() < ONE_ARCSEC
    assert np.abs(after[:, 1] - target[1]).max() < ONE_ARCSEC
    assert np.abs(trace[:, 2]).max() <= math.radians(6.0) * 1.02  # rate limit held
    assert m.mount_state == AxisState.HOLDING


def test_manual_move_runs_at_the_commanded_rate_then_stops():
    m = holding_mount()
    rate = math.radians(1.0)
    m.move(0, rate)
    trace = m.record(ticks(3.0), ["axis.az.velocity"])
    assert abs(trace[ticks(2.0):, 0].mean() - rate) < 1e-3 * rate
    m.stop()
    m.run(ticks(2.0))
    assert m.axis_state(0) == AxisState.HOLDING
    assert abs(m.axis_slot(0, L.A_VEL_EST)) < 1e-5


def test_winding_temperature_approaches_i2r_steady_state():
    m = holding_mount()
    m.set_param("axis.el.thermal_tau", 1.0)
    m.run(ticks(8.0))
    cur = m.axis_slot(1, L.A_CUR)
    expected = m.param("power.ambient_temperature") + cur**2 * m.param(
        "axis.el.winding_resistance") * m.param("axis.el.thermal_resistance")
    assert abs(cur) > 0.2  # the elevation axis holds its gravity imbalance
    assert abs(m.axis_slot(1, L.A_TEMP) - expected) < 0.01 * (expected - 15.0) + 1e-6


def test_braking_energy_goes_to_the_chopper_when_the_bus_is_high():
    m = holding_mount()
    m.set_param("power.chopper_on_voltage", m.param("power.supply_voltage") - 0.5)
    m.run(ticks(0.5))
    assert m.state[L.G_REGEN_J] > 0.0
    assert m.state[L.G_BUS_V] < m.param("power.supply_voltage")


def test_the_write_range_keeps_every_parameter_the_step_divides_by_above_zero():
    """layout.param_range knows the positive-parameter bound itself (the range LIST shows
    and WRITE checks), not only the registry's setter."""
    from mount_emulator import layout as L

    positive = [s for s in L.PARAM_SLOTS if s.name.rsplit(".", 1)[-1] in L.POSITIVE_PARAMS]
    assert len(positive) >= len(L.POSITIVE_PARAMS)  # every name is a real parameter
    for slot in positive:
        lo, hi = L.param_range(slot)
        assert 0.0 < lo <= slot.default <= hi, (slot.name, lo, slot.default, hi)
    for slot in L.PARAM_SLOTS:
        if slot.name.rsplit(".", 1)[-1] in L.NONNEGATIVE_PARAMS:
            assert L.param_range(slot)[0] >= 0.0, slot.name
