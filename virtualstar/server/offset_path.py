"""A path with a track's offsets applied: what the feeder samples once offsets exist.

Pure numerics over arrays (no I/O, no clock). `OffsetPath(base, offsets, lat)`
samples the base path (a `TargetPath` of a star, or a satellite pass's
`TablePath`) in the encoder frame and moves it by the offsets of
`offsets.Offsets` at the same mount times:

1. path (seconds): the base is sampled at t + path(t): the boresight goes where
   the target is that much later; its rates scale by 1 + d path/dt;
2. the sky offsets, in the tangent plane (x = azimuth·cos E, y = elevation):
   ra/dec through the parallactic angle q (ERFA `hd2pa`, the position angle of
   the zenith): y += η cos q + ξ sin q, x += η sin q − ξ cos q; transverse
   along ĉ, the direction of travel û turned +90° (to the left); el adds to y;
3. back to angles: Δaz = x / cos E (+ the az axis offset), Δel = y.

The offsets move the demand by at most degrees, so the encoder frame stands in
for the observed frame in the rotations (a pointing model changes the angles by
arcminutes: a relative error of 1e-4 on an offset). Rates: the offsets' own
rates turned by the same rotation, plus the rotation's change (central
difference of the base over ±`ROTATION_STEP_S`) applied to the offsets.
"""

from __future__ import annotations

import math

import erfa
import numpy as np

from virtualstar.astro.constants import ARCSEC_PER_RAD

from .offsets import Offsets
from .trajectories import Path, Points

__all__ = ["OffsetPath", "sky_rate_arcsec_s"]

ROTATION_STEP_S = 0.05  # the base is sampled this far either side for the rotation's change
_MIN_COS_EL = 1e-3  # 89.94°: beyond, an azimuth offset would ask for an infinite rate


def sky_rate_arcsec_s(p: Points) -> np.ndarray:
    """Return the on-sky rate of trajectory points (arcsec/s)."""
    return np.hypot(p.az_rate_rad_s * np.cos(p.el_rad), p.el_rate_rad_s) * ARCSEC_PER_RAD


class OffsetPath:
    """`base` moved by `offsets` (which the procedures and the closed loop change)."""

    def __init__(self, base: Path, offsets: Offsets, lat_rad: float, *,
                 end_us: int | None = None) -> None:
        self.base = base
        self.offsets = offsets
        self.lat_rad = float(lat_rad)
        self.end_us = base.end_us if end_us is None else int(end_us)

    def knots_between(self, t0_us: int, t1_us: int) -> list[int]:
        """Mount times in (t0, t1] where an offset's acceleration changes (sample them)."""
        return self.offsets.knots_between(t0_us, t1_us)

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        if not self.offsets.any:
            return self.base.sample(t)
        off = self.offsets.sample(t)
        path_s, path_rate = off["path"]
        tau = t + np.round(path_s * 1e6).astype(np.int64)
        h_us = int(ROTATION_STEP_S * 1e6)
        # one call for the three times the rotations need: tau - h, tau, tau + h
        both = self.base.sample(np.concatenate([tau - h_us, tau, tau + h_us]))
        n = len(t)
        mid = _part(both, n, 1)
        frame = _frames(mid, self.lat_rad)
        ahead, behind = _frames(_part(both, n, 2), self.lat_rad), _frames(_part(both, n, 0),
                                                                          self.lat_rad)
        dx, dy = _tangent(frame, off, 0)
        dx_rate, dy_rate = _tangent(frame, off, 1)
        ax, ay = _tangent(ahead, off, 0)
        bx, by = _tangent(behind, off, 0)
        scale = 1.0 + path_rate
        dx_rate = dx_rate + (ax - bx) / (2 * ROTATION_STEP_S) * scale
        dy_rate = dy_rate + (ay - by) / (2 * ROTATION_STEP_S) * scale
        cos_el = np.maximum(np.cos(mid.el_rad), _MIN_COS_EL)
        az_axis, az_axis_rate = off["az"]
        d_az = (dx / cos_el + az_axis) / ARCSEC_PER_RAD
        d_el = dy / ARCSEC_PER_RAD
        # d/dt (dx / cos E) = dx' / cos E + dx · tan E · E' / cos E
        el_rate = mid.el_rate_rad_s * scale
        d_az_rate = (dx_rate / cos_el + dx * np.tan(mid.el_rad) * el_rate / cos_el
                     + az_axis_rate) / ARCSEC_PER_RAD
        d_el_rate = dy_rate / ARCSEC_PER_RAD
        return Points(t, mid.az_rad + d_az, mid.el_rad + d_el,
                      mid.az_rate_rad_s * scale + d_az_rate, el_rate + d_el_rate)


def _part(p: Points, n: int, k: int) -> Points:
    s = slice(k * n, (k + 1) * n)
    return Points(p.t_us[s], p.az_rad[s], p.el_rad[s], p.az_rate_rad_s[s], p.el_rate_rad_s[s])


def _frames(p: Points, lat_rad: float) -> tuple[np.ndarray, ...]:
    """Per point: (cos q, sin q, û_x, û_y) — the parallactic angle and the direction of travel."""
    ha, dec = erfa.ae2hd(np.mod(p.az_rad, 2 * math.pi), p.el_rad, lat_rad)
    q = erfa.hd2pa(ha, dec, lat_rad)
    ux = p.az_rate_rad_s * np.cos(p.el_rad)
    uy = p.el_rate_rad_s
    norm = np.hypot(ux, uy)
    moving = norm > 0
    safe = np.where(moving, norm, 1.0)
    return np.cos(q), np.sin(q), np.where(moving, ux / safe, 0.0), np.where(moving, uy / safe, 0.0)


def _tangent(frame, off, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The sky offsets (k=0) or their rates (k=1) in the tangent plane: (x, y) arcsec."""
    cos_q, sin_q, ux, uy = frame
    east, north, el, across = off["ra"][k], off["dec"][k], off["el"][k], off["transverse"][k]
    x = north * sin_q - east * cos_q - across * uy
    y = north * cos_q + east * sin_q + across * ux + el
    return x, y
