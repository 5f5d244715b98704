"""Errors of the VirtualStar Server, one tree; `.code` travels in API error replies.

::

    VssError                                        .code
    ├── BadRequest (ValueError)                     bad_request      malformed message or parameters
    ├── UnknownCommand (KeyError)                   unknown_command  no such command (lists valid ones)
    ├── MappingError (ValueError)                   mapping          mapping file wrong or names missing on the mount
    ├── NotActive (PermissionError)                 passive          the server is passive: it only watches
    ├── Unauthorized (PermissionError)              unauthorized     no (or a wrong) password: authenticate first
    ├── Forbidden (PermissionError)                 forbidden        the connection's role may not do this (observer)
    ├── Throttled (PermissionError)                 throttled        a password attempt not checked: too many wrong ones (retry later)
    ├── MountUnavailable (ConnectionError)          mount_offline    no connection to the mount right now
    ├── MountRejected (RuntimeError)                mount_rejected   the mount refused a command (its message)
    ├── MountFault (RuntimeError)                   mount_fault      the mount latched a fault during an operation
    ├── TargetUnreachable (ValueError)              unreachable      below the horizon, beyond the cable wrap, no pass
    ├── StaleElements (ValueError)                  stale_tle        TLE too old for the mount time, or the satellite decayed
    ├── InExclusionZone (ValueError)                exclusion_zone   the target or the slew's path is too near the Sun (or Moon)
    ├── NotTracking (RuntimeError)                  not_tracking     a guide pulse needs a sky target being tracked
    ├── NoCamera (LookupError)                      no_camera        a closed loop needs a guide camera (--camera)
    ├── NotArrived (RuntimeError)                   not_arrived      the mount is not where the target is (how far: in the message)
    ├── TrackingLost (RuntimeError)                 tracking_lost    the mount stopped following the trajectory (buffer underrun)
    ├── Unsupported (RuntimeError)                  unsupported      the mount's backend cannot do this (its capabilities)
    ├── OperationAborted (RuntimeError)             aborted          stopped by a newer command, a fault or a shutdown
    │   └── StoppedByClient                         aborted          ended by a client's `stop` (`stopped`: true)
    └── InternalError (RuntimeError)                internal         a bug: reported, the server keeps running
"""

from __future__ import annotations

__all__ = [
    "BadRequest",
    "Forbidden",
    "InExclusionZone",
    "InternalError",
    "MappingError",
    "MountFault",
    "MountRejected",
    "MountUnavailable",
    "NotActive",
    "NoCamera",
    "NotArrived",
    "NotTracking",
    "OperationAborted",
    "StaleElements",
    "StoppedByClient",
    "TargetUnreachable",
    "Throttled",
    "TrackingLost",
    "Unsupported",
    "Unauthorized",
    "UnknownCommand",
    "VssError",
]


class VssError(Exception):
    """Base of every VSS error; `code` is the short text code sent to API clients."""

    code = "internal"

    @property
    def message(self) -> str:
        return str(self.args[0]) if self.args else ""

    def __str__(self) -> str:
        return self.message


class BadRequest(ValueError, VssError):
    """A request is malformed or a parameter is wrong."""

    code = "bad_request"


class UnknownCommand(KeyError, VssError):
    """A request names a command the server does not have."""

    code = "unknown_command"

    def __str__(self) -> str:  # KeyError would quote the message
        return self.message


class MappingError(ValueError, VssError):
    """The role mapping file is wrong, or names in it do not exist on the mount."""

    code = "mapping"


class NotActive(PermissionError, VssError):
    """A command that moves the mount was sent while the server is passive."""

    code = "passive"


class MountUnavailable(ConnectionError, VssError):
    """The mount is not connected (the server keeps retrying)."""

    code = "mount_offline"


class MountRejected(RuntimeError, VssError):
    """The mount refused a command; the message is the mount's own."""

    code = "mount_rejected"


class MountFault(RuntimeError, VssError):
    """The mount latched a fault (or its state went to fault) during an operation."""

    code = "mount_fault"


class TargetUnreachable(ValueError, VssError):
    """The target cannot be followed: below the horizon, beyond the cable wrap, no pass."""

    code = "unreachable"


class OperationAborted(RuntimeError, VssError):
    """An operation ended early: a newer command, a fault, a lost mount or a shutdown."""

    code = "aborted"


class StoppedByClient(OperationAborted):
    """An operation ended by a client's `stop`: what an operator asked for, not a failure.

    Its code stays `aborted` (clients know it); `stopped` marks it in the operation's
    `info.error`, so a panel can tell a deliberate stop from a replacement or a shutdown.
    """

    stopped = True


class StaleElements(ValueError, VssError):
    """A satellite's elements are too far from the mount time to be trusted, or SGP4 failed."""

    code = "stale_tle"


class NotArrived(RuntimeError, VssError):
    """After a slew the encoders are farther from the target than the arrival tolerance."""

    code = "not_arrived"

    def __init__(self, message: str, error_arcsec: float) -> None:
        super().__init__(message)
        self.error_arcsec = error_arcsec


class TrackingLost(RuntimeError, VssError):
    """The mount left the trajectory it was following (its buffer ran dry): re-acquire."""

    code = "tracking_lost"


class InternalError(RuntimeError, VssError):
    """A bug in the server, reported to the client; the server keeps running."""

    code = "internal"


class InExclusionZone(ValueError, VssError):
    """The target, or the path the mount would take to it, comes too near the Sun or the Moon."""

    code = "exclusion_zone"


class Unauthorized(PermissionError, VssError):
    """The connection has not authenticated, or its password was wrong."""

    code = "unauthorized"


class Forbidden(PermissionError, VssError):
    """The connection's role may not send this command (an observer moving the mount)."""

    code = "forbidden"


class NotTracking(RuntimeError, VssError):
    """A guide pulse arrived while no sky target is being tracked (nothing to offset)."""

    code = "not_tracking"


class NoCamera(LookupError, VssError):
    """A closed loop was asked for but the server has no guide camera."""

    code = "no_camera"


class Unsupported(RuntimeError, VssError):
    """The mount's backend cannot do what was asked (its capabilities say so)."""

    code = "unsupported"


class Throttled(PermissionError, VssError):
    """A password attempt refused unchecked: too many wrong ones from the address or overall."""

    code = "throttled"
