"""Alt-azimuth specifics: cable-wrap unwrapping, the zenith keyhole, elevation limits.

Azimuths here are "mount azimuths": continuous angles (radians) that may run
beyond 0..2π within the cable-wrap range, e.g. -270°..+270°.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import erfa
import numpy as np

from .constants import ARCSEC_PER_RAD
from .exceptions import UnreachablePath

#: Default cable-wrap range of the azimuth axis, degrees (mount azimuth).
DEFAULT_WRAP_MIN_DEG = -270.0
DEFAULT_WRAP_MAX_DEG = 270.0


@dataclass(frozen=True)
class MountLimits:
    """Axis limits of an alt-az mount (degrees, deg/s, deg/s²: user-facing units)."""

    wrap_min_deg: float = DEFAULT_WRAP_MIN_DEG
    wrap_max_deg: float = DEFAULT_WRAP_MAX_DEG
    el_min_deg: float = 0.0
    el_max_deg: float = 90.0
    az_max_rate_deg_s: float = 10.0
    el_max_rate_deg_s: float = 10.0
    az_max_accel_deg_s2: float = 5.0
    el_max_accel_deg_s2: float = 5.0

    def __post_init__(self) -> None:
        if not self.wrap_max_deg - self.wrap_min_deg >= 360.0:
            raise ValueError(f"cable wrap {self.wrap_min_deg}..{self.wrap_max_deg} deg spans "
                             "less than 360 deg: some azimuths could never be reached")
        if not self.el_min_deg < self.el_max_deg:
            raise ValueError(f"elevation limits {self.el_min_deg}..{self.el_max_deg}: min >= max")
        for name in ("az_max_rate_deg_s", "el_max_rate_deg_s", "az_max_accel_deg_s2",
                     "el_max_accel_deg_s2"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")


#: The default limits (a typical small robotic alt-az mount).
DEFAULT_LIMITS = MountLimits()


def unwrap_azimuth(az_rad: np.ndarray, *, limits: MountLimits = DEFAULT_LIMITS,
                   current_az_rad: float | None = None) -> np.ndarray:
    """Return a continuous mount azimuth for a path of sky azimuths (radians).

    The path is made continuous, then placed on the turn of the cable wrap that
    keeps it inside the wrap range, choosing among the possible turns the one
    that starts nearest the current mount azimuth (or nearest the middle of the
    range). Raises UnreachablePath if the path spans more than the range allows.
    """
    path = np.unwrap(np.asarray(az_rad, float))
    lo, hi = math.radians(limits.wrap_min_deg), math.radians(limits.wrap_max_deg)
    k_min = math.ceil((lo - path.min()) / (2 * math.pi))
    k_max = math.floor((hi - path.max()) / (2 * math.pi))
    if k_min > k_max:
        span = math.degrees(path.max() - path.min())
        raise UnreachablePath(
            f"the azimuth path spans {span:.1f} deg, more than fits in the cable wrap "
            f"{limits.wrap_min_deg:g}..{limits.wrap_max_deg:g} deg without unwinding")
    anchor = (lo + hi) / 2 if current_az_rad is None else current_az_rad
    ks = np.arange(k_min, k_max + 1)
    k = ks[np.argmin(np.abs(path[0] + 2 * math.pi * ks - anchor))]
    return path + 2 * math.pi * k


def elevation_ok(el_rad: np.ndarray, limits: MountLimits = DEFAULT_LIMITS) -> np.ndarray:
    """Return a boolean mask of the points inside the elevation limits."""
    el = np.asarray(el_rad)
    return (el >= math.radians(limits.el_min_deg)) & (el <= math.radians(limits.el_max_deg))


@dataclass(frozen=True)
class Horizon:
    """A local horizon profile: the lowest usable elevation as a function of azimuth.

    az_deg/el_deg: points of the profile (degrees, any order, azimuth north through
    east); elevation is interpolated linearly in azimuth, wrapping through north.
    """

    az_deg: tuple[float, ...]
    el_deg: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.az_deg) != len(self.el_deg) or not self.az_deg:
            raise ValueError("horizon profile needs as many elevations as azimuths (>= 1)")

    def min_el_rad(self, az_rad: np.ndarray) -> np.ndarray:
        """Return the horizon elevation (rad) at the given azimuths (rad)."""
        az = np.mod(np.asarray(self.az_deg, float), 360.0)
        order = np.argsort(az)
        return np.radians(np.interp(np.degrees(np.mod(az_rad, 2 * math.pi)), az[order],
                                    np.asarray(self.el_deg, float)[order], period=360.0))

    def visible(self, az_rad: np.ndarray, el_rad: np.ndarray) -> np.ndarray:
        """Return a mask of the directions above this horizon."""
        return np.asarray(el_rad) > self.min_el_rad(az_rad)


@dataclass(frozen=True)
class KeyholePlan:
    """A rate-limited azimuth path through a pass too fast for the mount.

    az_rad: commanded mount azimuth (continuous); max_error_arcsec: largest
    angular distance on the sky between commanded and true direction;
    limited: True when the rate limit changed the path.
    """

    az_rad: np.ndarray
    max_error_arcsec: float
    limited: bool
    max_true_az_rate_deg_s: float


def plan_keyhole(t_s: np.ndarray, az_rad: np.ndarray, el_rad: np.ndarray,
                 max_az_rate_deg_s: float) -> KeyholePlan:
    """Plan the azimuth through a near-zenith pass under an azimuth rate limit.

    az_rad must be continuous (see unwrap_azimuth). The commanded path is the
    rate-limited function closest to the true azimuth in the worst case (the
    mid-line between the tightest rate-limited upper and lower envelopes, which
    is optimal in the max norm), so the mount starts turning before the target
    gets there and finishes after: the error is shared before and after
    culmination. Elevation is followed exactly.
    """
    t = np.asarray(t_s, float)
    az = np.asarray(az_rad, float)
    rate = math.radians(max_az_rate_deg_s)
    true_rate = np.abs(np.diff(az) / np.diff(t)) if len(t) > 1 else np.zeros(1)
    max_true = math.degrees(float(true_rate.max())) if true_rate.size else 0.0
    if max_true <= max_az_rate_deg_s:
        return KeyholePlan(az.copy(), 0.0, False, max_true)
    lt = rate * t
    # Largest rate-limited function below az, smallest above (McShane–Whitney envelopes).
    below = np.minimum(lt + np.minimum.accumulate(az - lt),
                       -lt + np.minimum.accumulate((az + lt)[::-1])[::-1])
    above = np.maximum(-lt + np.maximum.accumulate(az + lt),
                       lt + np.maximum.accumulate((az - lt)[::-1])[::-1])
    command = 0.5 * (below + above)
    err = erfa.seps(command, el_rad, az, el_rad)
    return KeyholePlan(command, float(err.max()) * ARCSEC_PER_RAD, True, max_true)
