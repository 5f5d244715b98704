"""Slew planning: time-optimal trapezoidal velocity profiles under rate and acceleration limits.

Each axis moves from rest to rest: accelerate at the limit, cruise at the rate
limit if the distance allows it (trapezoid), decelerate; short moves never
reach the rate limit (triangle). A two-axis slew lasts as long as its slower
axis; with synchronise=True the faster axis is stretched to finish together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .altaz import DEFAULT_LIMITS, MountLimits


@dataclass(frozen=True)
class TrapezoidProfile:
    """A rest-to-rest move of one axis (radians, rad/s, rad/s², seconds)."""

    start_rad: float
    distance_rad: float
    peak_rate_rad_s: float
    accel_rad_s2: float

    @property
    def accel_time_s(self) -> float:
        return self.peak_rate_rad_s / self.accel_rad_s2 if self.peak_rate_rad_s else 0.0

    @property
    def cruise_time_s(self) -> float:
        if not self.peak_rate_rad_s:
            return 0.0
        return abs(self.distance_rad) / self.peak_rate_rad_s - self.accel_time_s

    @property
    def duration_s(self) -> float:
        return 2.0 * self.accel_time_s + self.cruise_time_s

    def position(self, t_s: np.ndarray) -> np.ndarray:
        """Return the axis position (rad) at times since the start of the move."""
        t = np.clip(np.asarray(t_s, float), 0.0, self.duration_s)
        a, v, ta = self.accel_rad_s2, self.peak_rate_rad_s, self.accel_time_s
        tc, total = self.cruise_time_s, self.duration_s
        up = 0.5 * a * t**2
        cruise = 0.5 * a * ta**2 + v * (t - ta)
        down = abs(self.distance_rad) - 0.5 * a * (total - t) ** 2
        s = np.where(t < ta, up, np.where(t < ta + tc, cruise, down))
        return self.start_rad + math.copysign(1.0, self.distance_rad) * s

    def rate(self, t_s: np.ndarray) -> np.ndarray:
        """Return the axis rate (rad/s) at times since the start of the move."""
        t = np.asarray(t_s, float)
        a, v, total = self.accel_rad_s2, self.peak_rate_rad_s, self.duration_s
        speed = np.minimum(np.minimum(a * np.clip(t, 0, None), v),
                           a * np.clip(total - t, 0, None))
        speed = np.where((t < 0) | (t > total), 0.0, speed)
        return math.copysign(1.0, self.distance_rad) * speed


def trapezoid(start_rad: float, end_rad: float, max_rate_rad_s: float,
              max_accel_rad_s2: float, *, duration_s: float | None = None) -> TrapezoidProfile:
    """Return the fastest rest-to-rest profile, or one stretched to `duration_s`.

    Raises ValueError if limits are not positive or duration_s is shorter than possible.
    """
    if max_rate_rad_s <= 0 or max_accel_rad_s2 <= 0:
        raise ValueError("rate and acceleration limits must be positive")
    d = end_rad - start_rad
    dist = abs(d)
    if dist == 0.0:
        return TrapezoidProfile(start_rad, 0.0, 0.0, max_accel_rad_s2)
    peak = min(max_rate_rad_s, math.sqrt(dist * max_accel_rad_s2))
    fastest = TrapezoidProfile(start_rad, d, peak, max_accel_rad_s2)
    if duration_s is None or duration_s <= fastest.duration_s * (1 + 1e-12):
        if duration_s is not None and duration_s < fastest.duration_s * (1 - 1e-9):
            raise ValueError(f"a move of {math.degrees(dist):.3f} deg needs at least "
                             f"{fastest.duration_s:.3f} s, not {duration_s:.3f} s")
        return fastest
    # Same acceleration, lower peak: T = v/a + dist/v  →  v = (aT - sqrt(a²T² - 4 a dist)) / 2
    a = max_accel_rad_s2
    v = 0.5 * (a * duration_s - math.sqrt(max(a * a * duration_s**2 - 4.0 * a * dist, 0.0)))
    return TrapezoidProfile(start_rad, d, v, a)


@dataclass(frozen=True)
class SlewPlan:
    """Profiles of both axes; duration_s is the time until both have arrived."""

    az: TrapezoidProfile
    el: TrapezoidProfile

    @property
    def duration_s(self) -> float:
        return max(self.az.duration_s, self.el.duration_s)

    def sample(self, step_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (t_s, az_rad, el_rad) every step_s from 0 to the end inclusive."""
        t = np.append(np.arange(0.0, self.duration_s, step_s), self.duration_s)
        return t, self.az.position(t), self.el.position(t)


def plan_slew(start_az_rad: float, start_el_rad: float, end_az_rad: float, end_el_rad: float,
              limits: MountLimits = DEFAULT_LIMITS, *, synchronise: bool = False) -> SlewPlan:
    """Plan a two-axis slew between mount positions (radians, mount azimuth)."""
    az = trapezoid(start_az_rad, end_az_rad, math.radians(limits.az_max_rate_deg_s),
                   math.radians(limits.az_max_accel_deg_s2))
    el = trapezoid(start_el_rad, end_el_rad, math.radians(limits.el_max_rate_deg_s),
                   math.radians(limits.el_max_accel_deg_s2))
    if synchronise:
        total = max(az.duration_s, el.duration_s)
        az = trapezoid(start_az_rad, end_az_rad, math.radians(limits.az_max_rate_deg_s),
                       math.radians(limits.az_max_accel_deg_s2), duration_s=total)
        el = trapezoid(start_el_rad, end_el_rad, math.radians(limits.el_max_rate_deg_s),
                       math.radians(limits.el_max_accel_deg_s2), duration_s=total)
    return SlewPlan(az, el)


def plan_slew_to_target(target, site, start, start_az_rad: float, start_el_rad: float,
                        limits: MountLimits = DEFAULT_LIMITS, eop=None, *,
                        iterations: int = 6) -> tuple[SlewPlan, float]:
    """Plan a slew that meets a moving target where it will be on arrival.

    target: anything with observe(times, site, eop); start: UtcTimes of one
    instant. Returns (plan, arrival_s after start). The arrival point is found
    by fixed-point iteration (the slew time changes where the target is).
    """
    from .altaz import unwrap_azimuth

    arrival_s = 0.0
    plan = None
    for _ in range(iterations):
        obs = target.observe(start.shifted(arrival_s), site, eop)
        end_az = float(unwrap_azimuth(obs.az_rad, limits=limits, current_az_rad=start_az_rad)[0])
        plan = plan_slew(start_az_rad, start_el_rad, end_az, float(obs.el_rad[0]), limits)
        if abs(plan.duration_s - arrival_s) < 1e-3:
            break
        arrival_s = plan.duration_s
    return plan, arrival_s
