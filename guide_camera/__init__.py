"""A guide camera simulator that sees the true sky, beside the mount emulator.

It is an ASTCom device of its own (never part of the VSS): configured with the
truth — a star's catalogue place, or a satellite's *truth* TLE that differs from
the one the VSS is given — it reads the mount's encoders and hidden geometry over
ASTCom and reports, frame by frame, the target's centroid relative to the optical
axis, with noise, exposure, read-out latency, dropouts, clouds and impostors.
It imports only `astcom_client` of ours, and skyfield, sgp4 and ERFA for the truth
(tests/test_import_rules.py). docs/guide-camera.md describes it.
"""

from .device import EMULATOR_NAMES, GuideCameraDevice, MountPacedClock
from .exceptions import CameraConfigError, GuideCameraError
from .frames import CameraConfig, Frame, FrameMaker, Weather
from .tle_shift import measure_offsets, shifted_elements, shifted_tle
from .truth import CameraSite, SatelliteTruth, StarTruth

__all__ = [
    "EMULATOR_NAMES",
    "CameraConfig",
    "CameraConfigError",
    "CameraSite",
    "Frame",
    "FrameMaker",
    "GuideCameraDevice",
    "GuideCameraError",
    "MountPacedClock",
    "SatelliteTruth",
    "StarTruth",
    "Weather",
    "measure_offsets",
    "shifted_elements",
    "shifted_tle",
]
