"""Errors of the mount emulator, one tree.

::

    MountEmulatorError
    ├── CommandRejected (RuntimeError)     the state machine forbids the command now
    ├── TargetOutOfRange (ValueError)      a slew or move beyond the axis limits
    ├── TrajectoryError (ValueError)       malformed trajectory batch (lengths, types)
    │   └── ReplaceRefused                 traj.replace_from too late or with bad points
    ├── ConfigError (ValueError)           bad config or geometry file, unknown parameter
    └── InsecureListen (PermissionError)   a non-loopback address without a password

The compiled physics never raises: it reports faults and events as integers in
the state array; these exceptions belong to the command layer around it.
"""

from __future__ import annotations

__all__ = [
    "CommandRejected",
    "ConfigError",
    "InsecureListen",
    "MountEmulatorError",
    "ReplaceRefused",
    "TargetOutOfRange",
    "TrajectoryError",
]


class MountEmulatorError(Exception):
    """Base class of every mount emulator error."""


class CommandRejected(RuntimeError, MountEmulatorError):
    """The state machine does not allow this command in the current state."""

    def __init__(self, command: str, state: str, allowed: list[str]) -> None:
        self.command = command
        self.state = state
        self.allowed = allowed
        super().__init__(
            f"{command} is not allowed while the mount is {state}; "
            f"allowed now: {', '.join(allowed) or 'nothing (reset the fault first)'}"
        )


class TargetOutOfRange(ValueError, MountEmulatorError):
    """A commanded position lies outside the configured axis limits."""

    def __init__(self, axis: str, value_deg: float, low_deg: float, high_deg: float) -> None:
        self.axis = axis
        self.value_deg = value_deg
        super().__init__(
            f"{axis} target {value_deg:.4f} deg is outside the axis limits "
            f"[{low_deg:.4f}, {high_deg:.4f}] deg (axis.{axis}.position_min/max)"
        )


class TrajectoryError(ValueError, MountEmulatorError):
    """A trajectory batch is malformed (different lengths, wrong dimensions)."""


class ReplaceRefused(TrajectoryError):
    """traj.replace_from was refused: its time is too close or past, or its points are bad."""


class ConfigError(ValueError, MountEmulatorError):
    """A configuration or geometry file, or a parameter name, is wrong."""


class InsecureListen(PermissionError, MountEmulatorError):
    """Refuse to listen on a non-loopback address without a password."""
