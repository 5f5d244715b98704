"""Axis and mount state machines as data tables, status bits and fault bits.

Rules of the axis machine (one table, used both by the Python commands and, as an
integer array, inside the compiled step):

* ``OFF`` — drive output cut, holding brake on. ``POWER_ON`` closes the loops
  on the current encoder position (``HOLDING``).
* ``HOLDING`` — the loops hold a fixed reference. From here an axis may
  ``SLEW`` (point-to-point profile), ``TRACK`` (follow the trajectory buffer) or
  ``MOVE`` (manual rate).
* ``SLEWING`` / ``TRACKING`` / ``MANUAL`` — moving. ``STOP`` (command) or
  ``UNDERRUN`` (no future trajectory point) lead to ``STOPPING``: a ramp to zero
  velocity under the acceleration limit, never a jump. ``ARRIVED`` ends a slew.
* ``STOPPING`` — ``STOPPED`` when the reference velocity reached zero.
* any state — ``FAULT`` from the watchdog cuts the drive; the fault latches
  until ``RESET``, which leads to ``OFF``. ``POWER_OFF`` always cuts the drive.

The mount machine is the same table applied to the mount state. The mount
state follows its axes: ``FAULT`` if any axis is in fault, else the "busiest"
axis state in the order tracking > slewing > manual > stopping > holding > off.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

__all__ = [
    "AXIS_TRANSITIONS",
    "AxisEvent",
    "AxisState",
    "FAULT_NAMES",
    "MountState",
    "TRANSITION_TABLE",
    "allowed_events",
    "next_state",
]


class AxisState(IntEnum):
    OFF = 0
    HOLDING = 1
    SLEWING = 2
    TRACKING = 3
    MANUAL = 4
    STOPPING = 5
    FAULT = 6


MountState = AxisState  # the mount runs the same machine over its aggregate state


class AxisEvent(IntEnum):
    POWER_ON = 0
    POWER_OFF = 1
    SLEW = 2
    TRACK = 3
    MOVE = 4
    STOP = 5
    ARRIVED = 6
    STOPPED = 7
    UNDERRUN = 8
    FAULT = 9
    RESET = 10


S, E = AxisState, AxisEvent
_ANY_RUNNING = {E.POWER_OFF: S.OFF, E.FAULT: S.FAULT}
AXIS_TRANSITIONS: dict[AxisState, dict[AxisEvent, AxisState]] = {
    S.OFF: {E.POWER_ON: S.HOLDING, E.POWER_OFF: S.OFF, E.STOP: S.OFF, E.FAULT: S.FAULT},
    S.HOLDING: {
        **_ANY_RUNNING,
        E.POWER_ON: S.HOLDING,
        E.SLEW: S.SLEWING,
        E.TRACK: S.TRACKING,
        E.MOVE: S.MANUAL,
        E.STOP: S.HOLDING,
    },
    S.SLEWING: {
        **_ANY_RUNNING,
        E.SLEW: S.SLEWING,
        E.MOVE: S.MANUAL,
        E.STOP: S.STOPPING,
        E.ARRIVED: S.HOLDING,
    },
    S.TRACKING: {
        **_ANY_RUNNING,
        E.SLEW: S.SLEWING,
        E.MOVE: S.MANUAL,
        E.STOP: S.STOPPING,
        E.UNDERRUN: S.STOPPING,
    },
    S.MANUAL: {**_ANY_RUNNING, E.SLEW: S.SLEWING, E.MOVE: S.MANUAL, E.STOP: S.STOPPING},
    S.STOPPING: {
        **_ANY_RUNNING,
        E.SLEW: S.SLEWING,
        E.MOVE: S.MANUAL,
        E.STOP: S.STOPPING,
        E.STOPPED: S.HOLDING,
    },
    S.FAULT: {E.FAULT: S.FAULT, E.RESET: S.OFF, E.POWER_OFF: S.FAULT},
}
del S, E


def _as_array() -> np.ndarray:
    table = np.full((len(AxisState), len(AxisEvent)), -1, dtype=np.int64)
    for state, row in AXIS_TRANSITIONS.items():
        for event, new in row.items():
            table[state, event] = new
    return table


# The compiled step reads this (numba freezes a global array as a constant).
TRANSITION_TABLE = _as_array()


def next_state(state: int, event: int) -> int:
    """Return the state after ``event``, or -1 when the table forbids it."""
    return int(TRANSITION_TABLE[state, event])


def allowed_events(state: int) -> list[str]:
    """Return the names of the events the table allows in ``state``."""
    return [AxisEvent(e).name for e in range(len(AxisEvent)) if TRANSITION_TABLE[state, e] >= 0]


# Fault bits (per axis in axis.<ax>.faults; mount-level ones also in safety.mount_faults).
FAULT_OVERCURRENT = 1
FAULT_OVERTEMP = 2
FAULT_ENCODER = 4
FAULT_FOLLOWING = 8
FAULT_LIMIT = 16
FAULT_HEARTBEAT = 32
FAULT_OVERVOLTAGE = 64
FAULT_NAMES = {
    FAULT_OVERCURRENT: "overcurrent",
    FAULT_OVERTEMP: "over-temperature",
    FAULT_ENCODER: "encoder fault",
    FAULT_FOLLOWING: "following error beyond limit",
    FAULT_LIMIT: "axis limit",
    FAULT_HEARTBEAT: "missed controller heartbeat",
    FAULT_OVERVOLTAGE: "bus overvoltage",
}

# Mount status bits (mount.status_bits).
STATUS_UNDERRUN = 1
STATUS_TRAJ_STARTED = 2
STATUS_TIME_SYNCED = 4
STATUS_SYNC_ARMED = 8
STATUS_FAULT = 16
STATUS_CHOPPER = 32

# Events seen during a block (returned by step, also in state[G_EVENTS]).
EV_FAULT = 1
EV_UNDERRUN = 2
EV_ARRIVED = 4
EV_PPS = 8
EV_SYNC = 16


def fault_text(bits: int) -> str:
    """Return the fault bits as a comma-separated list of names ("none" when clear)."""
    names = [name for bit, name in FAULT_NAMES.items() if bits & bit]
    return ", ".join(names) if names else "none"
