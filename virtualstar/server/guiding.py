"""Guide offsets: small moves along RA/Dec added to a sky track (ASCOM PulseGuide, INDI timed guide).

A guide pulse moves the boresight north/south and east/west on the sky at a guide
rate for a while, then stays offset. The feeder has already pushed the points up to
the newest time the path sampled, so a pulse begins just after it: the offset is a
sum of ramps in mount time, continuous in position (its rate steps by the guide rate,
a few arcseconds per second, which the mount follows at once).

The offset is applied in the observed frame: a step north (η) and east (ξ) on the sky
moves elevation by η cos q + ξ sin q and azimuth by (η sin q − ξ cos q) / cos E, where
q is the parallactic angle (ERFA `hd2pa`: the position angle of the zenith).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import erfa
import numpy as np

from virtualstar.astro.constants import ARCSEC_PER_RAD

__all__ = ["GuideOffsets", "GuidePulse", "MAX_GUIDE_RATE_ARCSEC_S", "MAX_GUIDE_STEP_ARCSEC",
           "offset_observed"]

MAX_GUIDE_RATE_ARCSEC_S = 150.0  # ten times the sidereal rate: a guide rate, not a slew
MAX_GUIDE_STEP_ARCSEC = 600.0  # one pulse moves at most ten arcminutes
FOLD_AFTER_US = 60_000_000  # pulses ended this long before the newest sample become a constant


@dataclass(frozen=True)
class GuidePulse:
    """One pulse: from `start_us` to `end_us` the sky offset grows at these rates (rad/s)."""

    start_us: int
    end_us: int
    north_rad_s: float
    east_rad_s: float


@dataclass
class GuideOffsets:
    """The pulses given to one tracking operation (they survive its re-acquisitions)."""

    pulses: list[GuidePulse] = field(default_factory=list)
    sampled_until_us: int | None = None  # the newest time the path has sampled
    base_north_rad: float = 0.0  # the offset of pulses long ended (folded: a night of pulses
    base_east_rad: float = 0.0  # costs one sum, not thousands)

    def add(self, north_arcsec: float, east_arcsec: float, rate_arcsec_s: float,
            not_before_us: int, step_us: int) -> GuidePulse:
        """Schedule a pulse after the newest sampled point (and `not_before_us`); return it."""
        size = math.hypot(north_arcsec, east_arcsec)
        duration_us = max(1, int(round(size / rate_arcsec_s * 1e6)))
        start = int(not_before_us)
        if self.sampled_until_us is not None:
            start = max(start, self.sampled_until_us + step_us)
        k = 1.0 / ARCSEC_PER_RAD / (duration_us * 1e-6)
        pulse = GuidePulse(start, start + duration_us, north_arcsec * k, east_arcsec * k)
        self.pulses.append(pulse)
        return pulse

    @property
    def end_us(self) -> int:
        return max((p.end_us for p in self.pulses), default=0)

    def total_arcsec(self) -> tuple[float, float]:
        """The offset once every pulse has run: (north, east) arcseconds."""
        n = self.base_north_rad + sum(p.north_rad_s * (p.end_us - p.start_us) * 1e-6
                                      for p in self.pulses)
        e = self.base_east_rad + sum(p.east_rad_s * (p.end_us - p.start_us) * 1e-6
                                     for p in self.pulses)
        return n * ARCSEC_PER_RAD, e * ARCSEC_PER_RAD

    def _fold(self) -> None:
        if self.sampled_until_us is None:
            return
        before = self.sampled_until_us - FOLD_AFTER_US
        for p in [p for p in self.pulses if p.end_us < before]:
            self.base_north_rad += p.north_rad_s * (p.end_us - p.start_us) * 1e-6
            self.base_east_rad += p.east_rad_s * (p.end_us - p.start_us) * 1e-6
            self.pulses.remove(p)

    def sky_offsets(self, t_us: np.ndarray) -> tuple[np.ndarray, ...]:
        """Return (north, east, north rate, east rate) at mount times: radians, rad/s."""
        t = np.asarray(t_us, np.int64)
        north = np.full(t.shape, self.base_north_rad)
        east = np.full(t.shape, self.base_east_rad)
        north_rate = np.zeros(t.shape)
        east_rate = np.zeros(t.shape)
        for p in self.pulses:
            run_s = np.clip((t - p.start_us) * 1e-6, 0.0, (p.end_us - p.start_us) * 1e-6)
            moving = (t >= p.start_us) & (t < p.end_us)
            north += p.north_rad_s * run_s
            east += p.east_rad_s * run_s
            north_rate += np.where(moving, p.north_rad_s, 0.0)
            east_rate += np.where(moving, p.east_rad_s, 0.0)
        return north, east, north_rate, east_rate

    def apply(self, t_us: np.ndarray, az_rad: np.ndarray, el_rad: np.ndarray,
              az_rate: np.ndarray, el_rate: np.ndarray, lat_rad: float) -> tuple[np.ndarray, ...]:
        """Add the sky offsets at `t_us` to observed places and rates (radians, rad/s)."""
        t = np.asarray(t_us, np.int64)
        if self.sampled_until_us is None or t[-1] > self.sampled_until_us:
            self.sampled_until_us = int(t[-1])
            self._fold()
        return self.offset(t, az_rad, el_rad, az_rate, el_rate, lat_rad)

    @property
    def any(self) -> bool:
        return bool(self.pulses) or self.base_north_rad != 0.0 or self.base_east_rad != 0.0

    def offset(self, t_us: np.ndarray, az_rad: np.ndarray, el_rad: np.ndarray,
               az_rate: np.ndarray, el_rate: np.ndarray, lat_rad: float) -> tuple[np.ndarray, ...]:
        """`apply` without noting the times as sampled (for readers other than the feeder)."""
        if not self.any:
            return az_rad, el_rad, az_rate, el_rate
        return offset_observed(*self.sky_offsets(np.asarray(t_us, np.int64)), az_rad, el_rad,
                               az_rate, el_rate, lat_rad)


def offset_observed(north: np.ndarray, east: np.ndarray, north_rate: np.ndarray,
                    east_rate: np.ndarray, az_rad: np.ndarray, el_rad: np.ndarray,
                    az_rate: np.ndarray, el_rate: np.ndarray, lat_rad: float) -> tuple[np.ndarray, ...]:
    """Move observed places (and rates) by sky offsets north/east (radians, rad/s)."""
    ha, dec = erfa.ae2hd(np.mod(az_rad, 2 * math.pi), el_rad, lat_rad)
    q = erfa.hd2pa(ha, dec, lat_rad)
    cos_q, sin_q = np.cos(q), np.sin(q)
    cos_el = np.maximum(np.cos(el_rad), 1e-6)
    d_el = north * cos_q + east * sin_q
    d_az = (north * sin_q - east * cos_q) / cos_el
    r_el = north_rate * cos_q + east_rate * sin_q
    r_az = (north_rate * sin_q - east_rate * cos_q) / cos_el
    return (np.mod(az_rad + d_az, 2 * math.pi), el_rad + d_el, az_rate + r_az,
            el_rate + r_el)
