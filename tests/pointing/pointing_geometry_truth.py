"""An independent truth for the tests: a mount with exact (rotation-matrix) geometry.

Frame: x north, y east, z up; azimuth A from north through east, elevation E. The mount
has encoder zero-point errors, a tilted azimuth axis, a tilted elevation axis and a
collimation error, each applied as an exact rotation — no small-angle formulas, nothing
shared with pointing_model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ARCSEC = np.pi / 180.0 / 3600.0  # radians


@dataclass(frozen=True)
class ExactMount:
    """Geometry errors in arcsec, meaning spelled out in each field's comment."""

    az_zero: float = 0.0  # encoder azimuth reads this much more than the true mount azimuth
    el_zero: float = 0.0  # encoder elevation reads this much more than the true one
    tilt_north: float = 0.0  # azimuth axis tilted towards north (A = 0) by this angle
    tilt_west: float = 0.0  # azimuth axis tilted towards west (A = 270°)
    el_axis_right_end_up: float = 0.0  # right end (seen from behind) of the elevation axis raised
    beam_left: float = 0.0  # optical axis turned left of the plane ⟂ the elevation axis

    def sky_direction(self, enc_az_deg: np.ndarray, enc_el_deg: np.ndarray) -> np.ndarray:
        """Return unit vectors (N, 3) of where the telescope points for encoder readings."""
        a = np.radians(enc_az_deg) - self.az_zero * ARCSEC
        e = np.radians(enc_el_deg) - self.el_zero * ARCSEC
        h = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)  # forward, horizontal
        right = np.stack([-np.sin(a), np.cos(a), np.zeros_like(a)], axis=-1)
        up = np.array([0.0, 0.0, 1.0])
        n = self.el_axis_right_end_up * ARCSEC
        axis = np.cos(n) * right + np.sin(n) * up  # tilted elevation axis
        lift = np.cross(h, axis)  # the direction the tube rises towards
        p = np.cos(e)[:, None] * h + np.sin(e)[:, None] * lift
        c = self.beam_left * ARCSEC
        p = np.cos(c) * p - np.sin(c) * axis  # collimation: towards the left end of the axis
        t_n, t_w = self.tilt_north * ARCSEC, self.tilt_west * ARCSEC
        rot_n = np.array([[np.cos(t_n), 0, np.sin(t_n)], [0, 1, 0], [-np.sin(t_n), 0, np.cos(t_n)]])
        rot_w = np.array([[1, 0, 0], [0, np.cos(t_w), -np.sin(t_w)], [0, np.sin(t_w), np.cos(t_w)]])
        return p @ (rot_w @ rot_n).T

    def observed(self, enc_az_deg: np.ndarray, enc_el_deg: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Return the observed (az_deg, el_deg) on axis at these encoder readings."""
        v = self.sky_direction(np.atleast_1d(enc_az_deg), np.atleast_1d(enc_el_deg))
        az = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0
        el = np.degrees(np.arcsin(np.clip(v[:, 2], -1.0, 1.0)))
        return az, el

    def encoder_for(self, obs_az_deg: np.ndarray, obs_el_deg: np.ndarray,
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Return encoder readings that put observed positions on axis (Newton on `observed`)."""
        enc_az = np.array(obs_az_deg, dtype=float)
        enc_el = np.array(obs_el_deg, dtype=float)
        for _ in range(20):
            az, el = self.observed(enc_az, enc_el)
            d_az = (np.asarray(obs_az_deg) - az + 180.0) % 360.0 - 180.0
            enc_az, enc_el = enc_az + d_az, enc_el + (np.asarray(obs_el_deg) - el)
        return enc_az, enc_el
