"""Watchdog: each fault trips, cuts the drive, latches, and resets; the state tables."""

from __future__ import annotations

import math

import pytest
from emulator_helpers import holding_mount, ticks

from mount_emulator import layout as L
from mount_emulator.exceptions import CommandRejected, TargetOutOfRange
from mount_emulator.states import (
    AXIS_TRANSITIONS,
    FAULT_ENCODER,
    FAULT_FOLLOWING,
    FAULT_HEARTBEAT,
    FAULT_LIMIT,
    FAULT_OVERCURRENT,
    FAULT_OVERTEMP,
    FAULT_OVERVOLTAGE,
    STATUS_FAULT,
    AxisEvent,
    AxisState,
    next_state,
)


def _overcurrent(m):
    old = m.param("axis.el.current_trip")
    m.set_param("axis.el.current_trip", 0.05)  # below the current that holds the gravity imbalance
    return lambda: m.set_param("axis.el.current_trip", old)


def _overtemp(m):
    old = m.param("axis.el.temperature_max")
    m.set_param("axis.el.temperature_max", m.param("power.ambient_temperature") - 1.0)
    return lambda: m.set_param("axis.el.temperature_max", old)


def _encoder(m):
    m.set_param("axis.el.inject_encoder_fault", 1.0)
    return lambda: m.set_param("axis.el.inject_encoder_fault", 0.0)


def _following(m):
    old = m.param("axis.el.following_error_limit")
    m.set_param("axis.el.following_error_limit", math.radians(1 / 3600))  # 1″
    m.slew(0.0, math.radians(25.0))  # the slew's transient error exceeds 1″
    return lambda: m.set_param("axis.el.following_error_limit", old)


def _limit(m):
    old = m.param("axis.el.position_max")
    m.set_param("axis.el.position_max", m.axis_slot(1, L.A_ENC) + math.radians(0.01))
    m.move(1, math.radians(0.5))
    return lambda: m.set_param("axis.el.position_max", old)


def _heartbeat(m):
    m.set_param("safety.inject_heartbeat_miss", 1.0)
    return lambda: m.set_param("safety.inject_heartbeat_miss", 0.0)


@pytest.mark.parametrize(("inject", "bit"), [
    (_overcurrent, FAULT_OVERCURRENT), (_overtemp, FAULT_OVERTEMP), (_encoder, FAULT_ENCODER),
    (_following, FAULT_FOLLOWING), (_limit, FAULT_LIMIT), (_heartbeat, FAULT_HEARTBEAT),
], ids=["overcurrent", "overtemperature", "encoder", "following-error", "axis-limit", "heartbeat"])
def test_each_fault_trips_cuts_the_drive_latches_and_resets(inject, bit):
    m = holding_mount()
    clear = inject(m)
    m.run(ticks(2.0))
    assert m.axis_state(1) == AxisState.FAULT
    assert int(m.axis_slot(1, L.A_FAULTS)) & bit
    assert m.mount_state == AxisState.FAULT
    assert int(m.state[L.G_STATUS]) & STATUS_FAULT
    assert abs(m.axis_slot(1, L.A_CUR)) < 1e-3  # drive cut
    assert m.axis_slot(1, L.A_CUR_CMD) == 0.0
    with pytest.raises(CommandRejected, match="allowed now: .*RESET"):
        m.power_on()
    clear()
    m.run(ticks(0.5))
    assert m.axis_state(1) == AxisState.FAULT  # latched although the cause is gone
    m.safety_reset()
    assert m.axis_state(1) == AxisState.OFF
    m.power_on()
    m.run(ticks(1.0))
    assert m.axis_state(1) == AxisState.HOLDING
    assert m.axis_slot(1, L.A_FAULTS) == 0


def test_fault_latches_while_its_cause_persists():
    m = holding_mount()
    m.set_param("axis.az.inject_encoder_fault", 1.0)
    m.run(10)
    m.safety_reset()
    m.run(10)
    assert m.axis_state(0) == AxisState.FAULT


def test_slew_beyond_the_limits_is_refused_with_the_limits_named():
    m = holding_mount()
    with pytest.raises(TargetOutOfRange, match=r"el target 95.0000 deg is outside.*\[0.0000, 90.0000\]"):
        m.slew(0.0, math.radians(95.0))
    assert m.axis_state(1) == AxisState.HOLDING


def test_every_state_can_reach_off_or_fault_and_fault_only_leaves_by_reset():
    for state in AxisState:
        assert next_state(state, AxisEvent.FAULT) == AxisState.FAULT
    assert set(AXIS_TRANSITIONS[AxisState.FAULT].values()) <= {AxisState.FAULT, AxisState.OFF}
    assert next_state(AxisState.FAULT, AxisEvent.RESET) == AxisState.OFF
    assert next_state(AxisState.FAULT, AxisEvent.POWER_ON) == -1


def test_slew_is_refused_while_off_and_lists_what_is_allowed(mount):
    with pytest.raises(CommandRejected, match="allowed now: POWER_ON"):
        mount.slew(0.1, 0.5)


def test_bus_overvoltage_cuts_both_axes():
    m = holding_mount()
    m.set_param("safety.overvoltage", m.param("power.supply_voltage") - 1.0)
    m.run(ticks(0.1))
    assert m.axis_state(0) == AxisState.FAULT and m.axis_state(1) == AxisState.FAULT
    assert int(m.state[L.G_FAULTS]) & FAULT_OVERVOLTAGE
    m.set_param("safety.overvoltage", 65.0)
    m.safety_reset()
    m.power_on()
    m.run(ticks(0.5))
    assert m.mount_state == AxisState.HOLDING
