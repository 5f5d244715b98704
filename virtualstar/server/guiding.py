"""Guide pulses (ASCOM PulseGuide, INDI timed guide, the closed loop's sky axes) as offsets.

A guide pulse moves the boresight north/south and east/west on the sky at a guide
rate, then stays offset. It is an `add` on the `dec` (north) and `ra` (east)
offset axes (offsets.py) whose rate limit is the guide rate, shared between the two
axes so that they arrive together; the acceleration limit is the offsets' own, so
the rate rises in milliseconds instead of stepping. Like every correction it is
planned from the mount's minimum lead (corrections.py): on a mount with
`traj_replace` it acts 20 ms after it is accepted.
"""

from __future__ import annotations

import math

from .offsets import Offsets

__all__ = ["MAX_GUIDE_RATE_ARCSEC_S", "MAX_GUIDE_STEP_ARCSEC", "pulse_change"]

MAX_GUIDE_RATE_ARCSEC_S = 150.0  # ten times the sidereal rate: a guide rate, not a slew
MAX_GUIDE_STEP_ARCSEC = 600.0  # one pulse moves at most ten arcminutes


def pulse_change(north_arcsec: float, east_arcsec: float, rate_arcsec_s: float):
    """Return the change (for `Corrections.apply`) that one guide pulse makes."""
    size = math.hypot(north_arcsec, east_arcsec)

    def change(offsets: Offsets, from_us: int, sky_rate: float | None) -> int:
        reached = from_us
        for axis, value in (("dec", north_arcsec), ("ra", east_arcsec)):
            if value:
                share = abs(value) / size  # both axes at their part of the guide rate
                reached = max(reached, offsets.change(axis, "add", value, from_us,
                                                      v_max=rate_arcsec_s * share))
        return reached

    return change
