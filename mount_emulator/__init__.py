"""A 10 kHz two-axis direct-drive alt-azimuth mount behind an ASTCom Endpoint.

Library use: ``await MountEmulator(EmulatorConfig(...)).start("ws://127.0.0.1:0")``
(in-process, on the caller's event loop), or ``MountModel`` to drive the compiled
physics directly in simulated time. The console script is ``mount-emulator``.
"""

from mount_emulator.config import EmulatorConfig, load_config_file
from mount_emulator.emulator import LOOP_RATE_HZ, MountEmulator
from mount_emulator.exceptions import (
    CommandRejected,
    ConfigError,
    InsecureListen,
    MountEmulatorError,
    TargetOutOfRange,
    TrajectoryError,
)
from mount_emulator.geometry import Geometry, GuideCamera
from mount_emulator.model import MountModel
from mount_emulator.physics import initial_state, step
from mount_emulator.states import AxisEvent, AxisState, MountState

__all__ = [
    "LOOP_RATE_HZ",
    "AxisEvent",
    "AxisState",
    "CommandRejected",
    "ConfigError",
    "EmulatorConfig",
    "Geometry",
    "GuideCamera",
    "InsecureListen",
    "MountEmulator",
    "MountEmulatorError",
    "MountModel",
    "MountState",
    "TargetOutOfRange",
    "TrajectoryError",
    "initial_state",
    "load_config_file",
    "step",
]
