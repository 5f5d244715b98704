"""Trajectory buffer: interpolation, late points, underrun, free space, live gain changes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from emulator_helpers import (
    ONE_ARCSEC,
    SIDEREAL_RATE,
    holding_mount,
    push_smooth_ramp,
    star_altaz,
    ticks,
)

from mount_emulator import layout as L
from mount_emulator.exceptions import CommandRejected, TrajectoryError
from mount_emulator.physics import SAMPLE_OK, hermite_sample
from mount_emulator.states import STATUS_UNDERRUN, AxisState

LAT = math.radians(-24.6)
DEC = math.radians(-40.0)


def _star_path(t_s):
    return star_altaz(math.radians(20.0) + SIDEREAL_RATE * np.asarray(t_s), DEC, LAT)


@pytest.mark.parametrize("with_rates", [True, False], ids=["given-rates", "estimated-rates"])
def test_hermite_interpolation_reproduces_a_star_path_between_points(mount, with_rates):
    spacing_s = 0.25
    t_s = np.arange(0, 41) * spacing_s
    az, el = _star_path(t_s)
    t0 = mount.mount_time_us + 1_000
    t_us = t0 + (t_s * 1e6).astype(np.int64)
    if with_rates:
        h = 1e-3  # central differences of the analytic path, far finer than the point spacing
        az_p, el_p = _star_path(t_s + h)
        az_m, el_m = _star_path(t_s - h)
        mount.traj_push(t_us, az, el, (az_p - az_m) / (2 * h), (el_p - el_m) / (2 * h))
    else:
        mount.traj_push(t_us, az, el)
    out = np.zeros(6)
    worst = 0.0
    # sample between points (not at them) over the inner segments
    for t in np.linspace(1.0, 9.0, 517):
        code = hermite_sample(mount.traj_t, mount.traj_p, mount.traj_v, mount.state, t0 + t * 1e6, out)
        assert code == SAMPLE_OK
        true_az, true_el = _star_path(t)
        worst = max(worst, abs(out[0] - true_az) * math.cos(true_el), abs(out[1] - true_el))
    assert worst < 0.01 * ONE_ARCSEC


def test_late_and_non_increasing_points_are_rejected_and_counted(mount):
    now = mount.mount_time_us
    t = np.array([now - 100, now, now + 1_000, now + 1_000, now + 500, now + 2_000], dtype=np.int64)
    accepted = mount.traj_push(t, np.zeros(6), np.full(6, 0.3))
    assert accepted == 2  # now + 1000 and now + 2000
    assert mount.state[L.G_TRAJ_LATE] == 4
    assert mount.state[L.G_TRAJ_ACCEPTED] == 2
    assert mount.traj_free() == mount.traj_capacity - 1 - 2


def test_points_outside_the_axis_limits_are_rejected(mount):
    now = mount.mount_time_us
    t = now + np.array([1000, 2000], dtype=np.int64)
    assert mount.traj_push(t, [0.0, 0.0], [0.3, math.radians(95.0)]) == 1
    assert mount.state[L.G_TRAJ_OUT_OF_RANGE] == 1


def test_push_refuses_arrays_of_different_lengths(mount):
    with pytest.raises(TrajectoryError, match="differ in length"):
        mount.traj_push([1, 2], [0.0], [0.1, 0.2])


def test_free_space_stops_accepting_when_full(mount):
    cap = mount.traj_capacity
    t = mount.mount_time_us + 1000 + np.arange(cap + 10, dtype=np.int64) * 1000
    accepted = mount.traj_push(t, np.zeros(len(t)), np.full(len(t), 0.3))
    assert accepted == cap - 1
    assert mount.traj_free() == 0


def test_underrun_decelerates_smoothly_to_a_stop_and_flags_it():
    m = holding_mount()
    rate = math.radians(0.5)
    az0 = m.axis_slot(0, L.A_REF)
    last_s = push_smooth_ramp(m, rate, math.radians(2.0), 2.0)
    m.traj_start()
    m.run(ticks(last_s - 0.2))
    trace = m.record(ticks(1.5), ["axis.az.reference", "axis.az.reference_velocity",
                                  "axis.az.error_arcsec", "axis.az.state"])
    ref, vel, err, state = trace.T
    amax = m.param("axis.az.accel_limit")
    assert (np.abs(np.diff(vel)) <= amax * 1e-4 * 1.0001 + 1e-12).all()  # never a velocity jump
    assert (np.abs(np.diff(ref)) <= rate * 1e-4 * 1.01).all()  # never a position jump
    assert AxisState.STOPPING in state
    assert m.axis_state(0) == AxisState.HOLDING
    assert m.state[L.G_TRAJ_UNDERRUNS] == 1
    assert int(m.state[L.G_STATUS]) & STATUS_UNDERRUN
    # it stopped past the last point by the braking distance v²/2a
    t_acc = rate / math.radians(2.0)
    last_pos = az0 + rate * (last_s - 0.1 - t_acc / 2)
    assert ref[-1] - last_pos == pytest.approx(rate**2 / (2 * amax), rel=0.02)
    assert np.abs(err).max() < 5.0


def test_gain_change_takes_effect_at_the_next_tick_while_tracking():
    m = holding_mount()
    rate = math.radians(0.2)
    push_smooth_ramp(m, rate, math.radians(1.0), 6.0)
    m.traj_start()
    m.run(ticks(2.5))
    before = m.record(ticks(0.5), ["axis.az.error_arcsec", "axis.az.velocity_cmd"])
    assert np.abs(before[:, 0]).max() < 0.1
    m.set_param("axis.az.velocity_ff", 0.0)  # drop the feed-forward: the loops must carry the rate
    after = m.record(ticks(0.5), ["axis.az.error_arcsec", "axis.az.velocity_cmd"])
    # the very next velocity command has lost the feed-forward term (the rate limit allows it)
    ctrl_amax = m.param("axis.az.ctrl_accel_limit")
    assert before[-1, 1] - after[0, 1] == pytest.approx(ctrl_amax * 1e-4, rel=1e-6)
    assert np.abs(after[ticks(0.2):, 0]).max() > 10 * np.abs(before[:, 0]).max()
    m.set_param("axis.az.velocity_ff", 1.0)
    m.run(ticks(2.0))
    assert m.axis_state(0) == AxisState.TRACKING
    assert abs(m.axis_slot(0, L.A_ERR_AS)) < 0.1


def test_trajectory_init_is_refused_while_tracking():
    m = holding_mount()
    t0 = m.mount_time_us
    m.traj_push(t0 + np.array([100_000, 200_000]), [0.0, 0.0], [m.axis_slot(1, L.A_REF)] * 2)
    m.traj_start()
    with pytest.raises(CommandRejected, match="traj.reset"):
        m.traj_init()
    m.traj_reset()
    m.run(ticks(0.5))
    assert m.axis_state(0) == AxisState.HOLDING


def test_push_refuses_one_rate_array_without_the_other(mount):
    with pytest.raises(TrajectoryError, match="both az_rate_rad_s and el_rate_rad_s"):
        mount.traj_push([mount.mount_time_us + 1000], [0.0], [0.3], [0.0], None)
