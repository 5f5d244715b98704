"""Errors of the guide camera simulator, one tree.

::

    GuideCameraError
    └── CameraConfigError (ValueError)   a bad site, truth target, TLE or camera setting

Over ASTCom a refused write or call reaches the client as a DeviceError with the message.
"""

from __future__ import annotations

__all__ = ["CameraConfigError", "GuideCameraError"]


class GuideCameraError(Exception):
    """Base class of every guide camera simulator error."""


class CameraConfigError(ValueError, GuideCameraError):
    """A setting, site, truth target or TLE that cannot be used; the message says why."""
