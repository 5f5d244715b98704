"""Trajectories the feeder samples: what the mount encoders must follow, per mount time.

Pure numerics over arrays (no I/O, no clock). A path answers
``sample(t_us) -> Points`` in the encoder frame (mount azimuth continuous within
the cable wrap, radians and rad/s); ``end_us`` is None for an endless path.

* `TargetPath` follows any `virtualstar.astro` target (star, RA/Dec, fixed,
  planet) chunk by chunk, keeping the azimuth continuous with the previous chunk.
* `TablePath` holds a precomputed finite path (a satellite pass after the
  keyhole plan) and interpolates it with cubic Hermite polynomials.
* `RampIn` puts a constant-acceleration run-up in front of a path, so that an
  axis at rest reaches the path's position *and* rate at the same instant:
  tracking starts without a velocity step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import erfa
import numpy as np
from scipy.interpolate import CubicHermiteSpline

from virtualstar.astro import (
    MountLimits,
    Satellite,
    Site,
    observe_mount_times,
    plan_keyhole,
    plan_slew,
    unwrap_azimuth,
)

from .exceptions import TargetUnreachable

__all__ = [
    "ConstantRatePath",
    "Path",
    "Points",
    "RampIn",
    "RampOut",
    "TablePath",
    "TargetPath",
    "observed_to_encoder",
    "plan_run_up",
    "plan_satellite_pass",
    "ramp_start",
]

SLEW_MARGIN = 1.05  # the mount's own slew takes a little longer than the trapezoid
SLEW_SETTLE_S = 1.5  # mount seconds from the end of the slew to "holding" and the next command

_ONE_ARCSEC_RAD = math.pi / 180.0 / 3600.0
_RATE_STEP_S = 0.05  # step of the finite difference that carries pointing-model corrections into rates


@dataclass(frozen=True)
class Points:
    """Trajectory points: mount time (int64 µs), encoder angles (rad) and rates (rad/s)."""

    t_us: np.ndarray
    az_rad: np.ndarray
    el_rad: np.ndarray
    az_rate_rad_s: np.ndarray
    el_rate_rad_s: np.ndarray

    def __len__(self) -> int:
        return int(self.t_us.shape[0])


class Path(Protocol):
    """Anything the feeder can sample."""

    end_us: int | None

    def sample(self, t_us: np.ndarray) -> Points: ...


def observed_to_encoder(model, az_rad: np.ndarray, el_rad: np.ndarray, az_rate: np.ndarray,
                        el_rate: np.ndarray) -> tuple[np.ndarray, ...]:
    """Apply a pointing model (or none) to observed positions and rates; radians, rad/s.

    The mount azimuth may run beyond 0..2π (cable wrap): the model's correction is
    computed on the wrapped angle and added, so the turn is kept. Rates get the
    time derivative of the correction by a short finite difference along the path.
    """
    if model is None:
        return az_rad, el_rad, az_rate, el_rate

    def correction(az: np.ndarray, el: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        az_deg = np.degrees(np.mod(az, 2 * math.pi))
        enc_az, enc_el = model.observed_to_encoder(az_deg, np.degrees(el))
        d_az = np.radians((np.asarray(enc_az) - az_deg + 180.0) % 360.0 - 180.0)
        return d_az, np.radians(np.asarray(enc_el)) - el

    d_az, d_el = correction(az_rad, el_rad)
    h = _RATE_STEP_S
    d_az2, d_el2 = correction(az_rad + az_rate * h, el_rad + el_rate * h)
    return (az_rad + d_az, el_rad + d_el, az_rate + (d_az2 - d_az) / h,
            el_rate + (d_el2 - d_el) / h)


class TargetPath:
    """Follow an astro target forever (until it leaves the limits), chunk by chunk."""

    end_us: int | None = None

    def __init__(self, target, site: Site, *, limits: MountLimits, eop=None, model=None,
                 current_az_rad: float | None = None, guard=None) -> None:
        self.target = target
        self.site = site
        self.limits = limits
        self.eop = eop
        self.model = model
        self.guard = guard  # guard(t_us, az_rad, el_rad) raises before observed places are used
        self._anchor = current_az_rad
        self._last: tuple[int, float] | None = None  # (t_us, observed mount az) of the newest sample

    def observe(self, t_us: np.ndarray) -> tuple[np.ndarray, ...]:
        """Return observed (az, el, az rate, el rate) with az continuous with earlier samples."""
        obs = observe_mount_times(self.target, np.asarray(t_us, np.int64), self.site, self.eop)
        anchor = self._last[1] if self._last is not None else self._anchor
        try:
            az = unwrap_azimuth(obs.az_rad, limits=self.limits, current_az_rad=anchor)
        except ValueError as exc:
            raise TargetUnreachable(str(exc)) from None
        if self._last is not None and abs(az[0] - self._last[1]) > math.pi:
            raise TargetUnreachable("the target's azimuth reached the end of the cable wrap "
                                    f"({self.limits.wrap_min_deg:g}..{self.limits.wrap_max_deg:g} deg)")
        if self.guard is not None:
            self.guard(np.asarray(t_us, np.int64), obs.az_rad, obs.el_rad)
        lo_el = math.radians(self.limits.el_min_deg)
        if np.any(obs.el_rad < lo_el):
            raise TargetUnreachable(
                f"{getattr(self.target, 'name', 'the target') or 'the target'} is below the "
                f"elevation limit ({self.limits.el_min_deg:g} deg) at some of the requested times")
        self._last = (int(t_us[-1]), float(az[-1]))
        return az, obs.el_rad, obs.az_rate_rad_s, obs.el_rate_rad_s

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        az, el, vaz, vel = observed_to_encoder(self.model, *self.observe(t))
        return Points(t, az, el, vaz, vel)


class ConstantRatePath:
    """Both axes turning at constant rates from a place at a mount time (ASCOM MoveAxis), until `end_us`."""

    def __init__(self, at_us: int, az_rad: float, el_rad: float, az_rate_rad_s: float,
                 el_rate_rad_s: float, end_us: int) -> None:
        self.at_us = int(at_us)
        self.p = np.array([az_rad, el_rad])
        self.v = np.array([az_rate_rad_s, el_rate_rad_s])
        self.end_us = int(end_us)

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        dt = (t - self.at_us) * 1e-6
        return Points(t, self.p[0] + self.v[0] * dt, self.p[1] + self.v[1] * dt,
                      np.full(t.shape, self.v[0]), np.full(t.shape, self.v[1]))


class TablePath:
    """A finite precomputed path, interpolated with cubic Hermite polynomials."""

    def __init__(self, points: Points) -> None:
        if len(points) < 2:
            raise TargetUnreachable("a path needs at least two points")
        self.points = points
        self.start_us = int(points.t_us[0])
        self.end_us = int(points.t_us[-1])
        t_s = (points.t_us - self.start_us) * 1e-6
        self._az = CubicHermiteSpline(t_s, points.az_rad, points.az_rate_rad_s)
        self._el = CubicHermiteSpline(t_s, points.el_rad, points.el_rate_rad_s)

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        s = np.clip((t - self.start_us) * 1e-6, 0.0, (self.end_us - self.start_us) * 1e-6)
        return Points(t, self._az(s), self._el(s), self._az(s, 1), self._el(s, 1))

    def between(self, start_us: int, end_us: int) -> TablePath:
        """Return the part of the path from `start_us` to `end_us` (nodes kept, ends exact)."""
        if start_us <= self.start_us and end_us >= self.end_us:
            return self
        p = self.points
        inner = (p.t_us > start_us) & (p.t_us < end_us)
        t = np.concatenate([[start_us], p.t_us[inner], [end_us]]).astype(np.int64)
        return TablePath(self.sample(t))


def ramp_start(position_rad: np.ndarray, rate_rad_s: np.ndarray, duration_s: float) -> np.ndarray:
    """Return where an axis must rest so a constant acceleration over `duration_s` meets the path.

    Starting at rest at p − v·T/2 with acceleration v/T reaches position p with
    rate v after T seconds.
    """
    return np.asarray(position_rad) - 0.5 * np.asarray(rate_rad_s) * duration_s


class RampIn:
    """A path preceded by a constant-acceleration run-up from rest (per axis)."""

    def __init__(self, path: Path, join_us: int, duration_s: float) -> None:
        self.path = path
        self.join_us = int(join_us)
        self.begin_us = self.join_us - int(round(duration_s * 1e6))
        self.duration_s = duration_s
        self.end_us = path.end_us
        j = path.sample(np.array([self.join_us], np.int64))
        self._p = np.array([j.az_rad[0], j.el_rad[0]])
        self._v = np.array([j.az_rate_rad_s[0], j.el_rate_rad_s[0]])
        self.rest_rad = ramp_start(self._p, self._v, duration_s)

    def knots_between(self, t0_us: int, t1_us: int) -> list[int]:
        inner = getattr(self.path, "knots_between", None)
        return [] if inner is None else inner(max(t0_us, self.join_us), t1_us)

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        late = t >= self.join_us
        if late.all():
            return self.path.sample(t)
        dt = np.clip((t - self.begin_us) * 1e-6, 0.0, self.duration_s)[:, None]
        acc = self._v / self.duration_s
        pos = self.rest_rad + 0.5 * acc * dt**2
        vel = acc * dt
        if late.any():
            tail = self.path.sample(t[late])
            pos[late, 0], pos[late, 1] = tail.az_rad, tail.el_rad
            vel[late, 0], vel[late, 1] = tail.az_rate_rad_s, tail.el_rate_rad_s
        return Points(t, pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1])


def plan_run_up(path: Path, *, az_rad: float, el_rad: float, now_us: int,
                limits: MountLimits, lead_s: float, ramp_s: float,
                not_before_us: int | None = None) -> RampIn:
    """Return the run-up that joins `path` as early as a slew from (az, el) at `now_us` allows.

    The join is: now + slew to the run-up's rest point (× SLEW_MARGIN + SLEW_SETTLE_S)
    + `lead_s` (time to prime the buffer) + `ramp_s`; never before `not_before_us`
    (a pass that has not risen). Where the rest point is depends on the join, so the
    two are refined together (three rounds suffice: the path moves little meanwhile).
    """
    def join_after(slew_s: float) -> int:
        join = now_us + int((slew_s + lead_s + ramp_s) * 1e6)
        return join if not_before_us is None else max(join, int(not_before_us))

    join = join_after(0.0)
    for _ in range(3):
        p = path.sample(np.array([join], np.int64))
        rest = ramp_start(np.array([p.az_rad[0], p.el_rad[0]]),
                          np.array([p.az_rate_rad_s[0], p.el_rate_rad_s[0]]), ramp_s)
        join = join_after(plan_slew(az_rad, el_rad, float(rest[0]), float(rest[1]),
                                    limits).duration_s * SLEW_MARGIN + SLEW_SETTLE_S)
    return RampIn(path, join, ramp_s)


class RampOut:
    """A finite path followed by a constant-deceleration run-out to rest, then a hold.

    The mount is told to stop while it is still running out or holding, never after its
    buffer ran dry: a late stop on a slow host costs nothing.
    """

    def __init__(self, path: Path, duration_s: float, hold_s: float) -> None:
        if path.end_us is None:
            raise ValueError("only a finite path can run out")
        self.path = path
        self.stop_us = int(path.end_us)
        self.duration_s = duration_s
        self.end_us = self.stop_us + int(round((duration_s + hold_s) * 1e6))

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        early = t <= self.stop_us
        if early.all():
            return self.path.sample(t)
        # where the path is at the stop, sampled now: an offset changed since still counts
        e = self.path.sample(np.array([self.stop_us], np.int64))
        p0 = np.array([e.az_rad[0], e.el_rad[0]])
        v0 = np.array([e.az_rate_rad_s[0], e.el_rate_rad_s[0]])
        dt = np.clip((t - self.stop_us) * 1e-6, 0.0, self.duration_s)[:, None]
        dec = v0 / self.duration_s
        pos = p0 + v0 * dt - 0.5 * dec * dt**2
        vel = v0 - dec * dt
        if early.any():
            head = self.path.sample(t[early])
            pos[early, 0], pos[early, 1] = head.az_rad, head.el_rad
            vel[early, 0], vel[early, 1] = head.az_rate_rad_s, head.el_rate_rad_s
        return Points(t, pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1])

    def knots_between(self, t0_us: int, t1_us: int) -> list[int]:
        inner = getattr(self.path, "knots_between", None)
        return [] if inner is None else inner(t0_us, min(t1_us, self.stop_us))


@dataclass(frozen=True)
class PassPlan:
    """A satellite pass ready to feed: the path and what the keyhole plan did."""

    path: TablePath
    keyhole_limited: bool
    keyhole_max_error_arcsec: float
    max_az_rate_deg_s: float
    max_el_deg: float


def plan_satellite_pass(sat: Satellite, site: Site, start_us: int, end_us: int, *,
                        step_s: float, limits: MountLimits, track_rate_limit_deg_s: float,
                        accel_limit_deg_s2: float = 3.0, eop=None, model=None, current_az_rad: float | None = None) -> PassPlan:
    """Precompute a whole pass [start_us, end_us] on a `step_s` grid, keyhole included.

    The azimuth is unwrapped once for the whole pass (raising TargetUnreachable when
    the pass does not fit in the cable wrap), then limited in rate near the zenith
    by `plan_keyhole`, whose rate-limited path is then smoothed by a moving
    average long enough to keep the azimuth acceleration under `accel_limit_deg_s2`
    (the plan bounds rates only). Elevation is followed exactly, except around a
    keyhole, where its cusp at culmination is smoothed the same way. The on-sky
    distance this costs is reported as `keyhole_max_error_arcsec`.
    """
    n = int(math.ceil((end_us - start_us) / (step_s * 1e6))) + 1
    t = start_us + np.round(np.arange(n) * step_s * 1e6).astype(np.int64)
    obs = observe_mount_times(sat, t, site, eop)
    try:
        az = unwrap_azimuth(obs.az_rad, limits=limits, current_az_rad=current_az_rad)
    except ValueError as exc:
        raise TargetUnreachable(str(exc)) from None
    t_s = (t - t[0]) * 1e-6
    plan = plan_keyhole(t_s, az, obs.el_rad, track_rate_limit_deg_s)
    az_cmd, az_rate = plan.az_rad, obs.az_rate_rad_s
    el_cmd, el_rate = obs.el_rad, obs.el_rate_rad_s
    if plan.limited:
        width_s = 2.0 * track_rate_limit_deg_s / accel_limit_deg_s2
        n_az = max(1, int(round(width_s / step_s)))
        # smooth only around the keyhole (tapering off outside): elsewhere the path is exact
        inside = np.abs(plan.az_rad - az) > _ONE_ARCSEC_RAD
        w_az = _taper(inside, 2 * n_az)
        az_cmd = plan.az_rad + w_az * (_moving_average(plan.az_rad, n_az) - plan.az_rad)
        az_rate = np.gradient(az_cmd, t_s)
        # so close to the zenith the elevation has a cusp (acceleration ~ ω²/miss
        # distance): smooth it the same way
        el_width_s = 2.0 * math.degrees(float(np.abs(obs.el_rate_rad_s).max())) / accel_limit_deg_s2
        n_el = max(1, int(round(el_width_s / step_s)))
        w_el = _taper(inside, n_az + n_el)
        el_cmd = obs.el_rad + w_el * (_moving_average(obs.el_rad, n_el) - obs.el_rad)
        el_rate = np.gradient(el_cmd, t_s)
    # what the sky sees of the commanded path (keyhole and smoothing), arcsec
    sky_err = float(np.max(erfa.seps(az_cmd, el_cmd, az, obs.el_rad))) * 206264.80624709636
    enc = observed_to_encoder(model, az_cmd, el_cmd, az_rate, el_rate)
    return PassPlan(TablePath(Points(t, *enc)), plan.limited, sky_err,
                    plan.max_true_az_rate_deg_s, float(np.degrees(obs.el_rad.max())))


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Return the centred moving average of `n` samples, the ends held (same length)."""
    if n < 2:
        return x.copy()
    half = n // 2
    padded = np.concatenate([np.full(half, x[0]), x, np.full(n - 1 - half, x[-1])])
    kernel = np.full(n, 1.0 / n)
    return np.convolve(padded, kernel, mode="valid")


def _taper(mask: np.ndarray, n: int) -> np.ndarray:
    """Return 1 where `mask` is set, falling linearly to 0 over `n` samples on each side."""
    if not mask.any():
        return np.zeros(mask.shape)
    idx = np.arange(mask.size)
    hits = np.flatnonzero(mask)
    dist = np.minimum(np.abs(idx - hits[0]), np.abs(idx - hits[-1]))
    dist[hits[0]:hits[-1] + 1] = 0
    return np.clip(1.0 - dist / max(n, 1), 0.0, 1.0)
