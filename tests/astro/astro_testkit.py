"""Helpers shared by the astronomy tests (named tolerances, separations)."""

import erfa
import numpy as np

ONE_MAS_RAD = np.deg2rad(1 / 3_600_000)
ONE_ARCSEC_RAD = np.deg2rad(1 / 3600)


def sep_rad(az1, el1, az2, el2):
    """Angular separation between two az/el directions, radians."""
    return erfa.seps(az1, el1, az2, el2)
