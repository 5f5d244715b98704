"""Offsets of a track as PWI4 has them: per axis a total, a rate, applied gradually.

Pure numerics, no I/O and no clock. Each axis holds an `OffsetProfile`: the
offset as a function of mount time, piecewise with constant acceleration
(knots at integer µs), so it can be sampled at any time, past or future, with
its exact rate. A change (add, set, rate, reset) is planned *from* a mount time
`from_us`: the profile before it is kept as it was (what the mount has already
been told), and from it the offset moves to its new goal along the time-optimal
path within a rate and an acceleration limit, starting from the position *and
rate* it had at `from_us` — so the demand never steps, in position or in rate.

Axes and units (docs/vss.md, "Offsets"):

* `ra`, `dec`: arcseconds on the sky toward east (ξ) and north (η);
* `az`, `el`: arcseconds of the mount's azimuth and elevation angles (PWI4's axis0/axis1);
* `path`: seconds of time along the target's track (the boresight goes where
  the target will be that much later); `transverse`: arcseconds across the
  track, positive to the left of the direction of travel as seen on the sky
  (x = azimuth·cos E to the right, y = elevation up).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["ALL_AXES", "AXES", "LOOP_AXES", "OPERATIONS", "OffsetLimits", "OffsetProfile",
           "Offsets", "time_optimal"]

AXES = ("ra", "dec", "az", "el", "path", "transverse")
# the closed loop's own axes (closed_loop.py): added to the user's, so an offset a user
# gives on top of a guided track moves the boresight from the target, not the loop
LOOP_AXES = ("guide_ra", "guide_dec", "guide_path", "guide_transverse")
ALL_AXES = AXES + LOOP_AXES
OPERATIONS = ("add", "set", "rate", "reset")
KEEP_HISTORY_US = 30_000_000  # knots older than this before a change are folded away


@dataclass(frozen=True)
class OffsetLimits:
    """How fast an offset may change: arcsec/s and arcsec/s² on the sky.

    The path axis (seconds of time) gets its limits from these divided by the
    target's on-sky rate where the change is planned (`path_limits`).
    """

    rate_arcsec_s: float = 1800.0  # 0.5°/s: a tenth of the mount's slew rate
    accel_arcsec_s2: float = 3600.0  # 1°/s²: a third of its acceleration limit

    def path_limits(self, sky_rate_arcsec_s: float) -> tuple[float, float]:
        """Return (rate s/s, acceleration s/s²) of the path axis at a target's sky rate."""
        w = max(float(sky_rate_arcsec_s), 1e-6)
        return self.rate_arcsec_s / w, self.accel_arcsec_s2 / w


def time_optimal(e0: float, w0: float, v_max: float, a_max: float) -> list[tuple[float, float]]:
    """Return [(duration s, acceleration)] that bring (error e0, rate w0) to (0, 0).

    The classic bang-(coast)-bang profile within |rate| ≤ v_max and
    |acceleration| ≤ a_max, from any initial rate (also one beyond v_max, which
    is first brought down). The direction is that of the distance left once the
    present rate has been braked to zero.
    """
    if v_max <= 0 or a_max <= 0:
        raise ValueError("v_max and a_max must be positive")
    if abs(e0) < 1e-12 and abs(w0) < 1e-12:
        return []
    brake = e0 + w0 * abs(w0) / (2.0 * a_max)  # where the error ends if braked now
    if abs(brake) < 1e-12:  # braking alone lands on the goal
        return [(abs(w0) / a_max, -math.copysign(a_max, w0))]
    s = -math.copysign(1.0, brake)  # direction of travel
    d = -e0 * s  # distance to cover, along s
    u0 = w0 * s  # rate along s
    peak = min(math.sqrt(max((2.0 * a_max * d + u0 * u0) / 2.0, 0.0)), v_max)
    # signed distances of the first ramp (u0 -> peak) and the last (peak -> 0), then a coast
    d1 = (peak * peak - u0 * u0) / (2.0 * a_max) if u0 <= peak else \
        (u0 * u0 - peak * peak) / (2.0 * a_max)
    coast_s = max(d - d1 - peak * peak / (2.0 * a_max), 0.0) / peak if peak > 0 else 0.0
    segments = [(abs(peak - u0) / a_max, s * math.copysign(a_max, peak - u0))]
    if coast_s > 0:
        segments.append((coast_s, 0.0))
    segments.append((peak / a_max, -s * a_max))
    return [(dt, a) for dt, a in segments if dt > 0]


@dataclass
class OffsetProfile:
    """One axis's offset over mount time: knots (µs) with position, rate, acceleration.

    Before the first knot the offset is 0; from knot k it is
    p_k + v_k·dt + a_k·dt²/2 (dt in seconds).
    """

    t_us: list[int] = field(default_factory=list)
    p: list[float] = field(default_factory=list)
    v: list[float] = field(default_factory=list)
    a: list[float] = field(default_factory=list)
    changes: int = 0
    folded: bool = False  # knots older than keep_history_us before a change were forgotten
    keep_history_us: int | None = None  # None: KEEP_HISTORY_US
    _arrays: tuple[np.ndarray, ...] | None = field(default=None, repr=False, compare=False)

    def copy(self) -> OffsetProfile:
        return OffsetProfile(list(self.t_us), list(self.p), list(self.v), list(self.a),
                             self.changes, self.folded, self.keep_history_us)

    def at(self, t_us: int) -> tuple[float, float]:
        """Return (offset, rate) at one mount time."""
        p, v = self.sample(np.array([t_us], np.int64))
        return float(p[0]), float(v[0])

    def sample(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (offset, rate) at mount times (int64 µs)."""
        t = np.asarray(t_us, np.int64)
        if not self.t_us:
            return np.zeros(t.shape), np.zeros(t.shape)
        if self._arrays is None:
            self._arrays = (np.asarray(self.t_us, np.int64), np.asarray(self.p),
                            np.asarray(self.v), np.asarray(self.a))
        knots, pk, vk, ak = self._arrays
        k = np.searchsorted(knots, t, side="right") - 1
        before = k < 0
        k = np.maximum(k, 0)
        # before the first knot: nothing (never offset), or, once history was forgotten,
        # the oldest state kept (nobody asks that far back: the feeder samples the future,
        # the closed loop frames a second old)
        dt = np.where(before, 0.0, (t - knots[k]) * 1e-6)
        a = ak[k]
        v = vk[k] + a * dt
        p = pk[k] + vk[k] * dt + 0.5 * a * dt * dt
        if self.folded:
            return p, v
        return np.where(before, 0.0, p), np.where(before, 0.0, v)

    def knots_between(self, t0_us: int, t1_us: int) -> list[int]:
        """Return the knot times in (t0_us, t1_us]: where the acceleration changes."""
        return self.t_us[bisect.bisect_right(self.t_us, t0_us):
                         bisect.bisect_right(self.t_us, t1_us)]

    @property
    def end_us(self) -> int:
        """The last knot: from it on the offset moves at a constant rate (or holds)."""
        return self.t_us[-1] if self.t_us else 0

    def plan(self, from_us: int, goal: float, goal_rate: float, v_max: float,
             a_max: float) -> int:
        """Replace the profile from `from_us` by the way to `goal` + `goal_rate`·(t − arrival).

        The goal moves at `goal_rate` from `from_us` on; the profile leaves its
        position and rate at `from_us` within `v_max`/`a_max` (relative to the
        moving goal: `v_max` − |goal_rate|) and follows the goal once it is there.
        Returns the mount time at which it arrives (µs).
        """
        from_us = int(from_us)
        p0, v0 = self.at(from_us)
        self._truncate(from_us)
        v_rel = max(v_max - abs(goal_rate), 1e-3 * v_max)
        t, p, v = from_us, p0, v0
        g = goal
        for dt, acc in time_optimal(p0 - goal, v0 - goal_rate, v_rel, a_max):
            t_next = t + int(round(dt * 1e6))
            if t_next == t:  # shorter than a microsecond: its rate change, at once
                v += acc * dt
                continue
            self._knot(t, p, v, acc)
            dt = (t_next - t) * 1e-6
            p, v = p + v * dt + 0.5 * acc * dt * dt, v + acc * dt
            g += goal_rate * dt
            t = t_next
        # on the goal (to rounding): follow it exactly from here
        self._knot(t, g, goal_rate, 0.0)
        self.changes += 1
        return t

    def plan_rate(self, from_us: int, rate: float, a_max: float) -> int:
        """From `from_us`, change the rate to `rate` at `a_max` and keep it (a drift)."""
        from_us = int(from_us)
        p0, v0 = self.at(from_us)
        self._truncate(from_us)
        t = from_us
        if v0 != rate:
            # whole µs, rounded up: the acceleration never exceeds a_max
            dt_us = max(1, math.ceil(abs(rate - v0) / a_max * 1e6 - 1e-6))
            acc = (rate - v0) / (dt_us * 1e-6)
            self._knot(t, p0, v0, acc)
            dt = dt_us * 1e-6
            p0, t = p0 + v0 * dt + 0.5 * acc * dt * dt, t + dt_us
        self._knot(t, p0, rate, 0.0)
        self.changes += 1
        return t

    def fold(self, before_us: int) -> None:
        """Forget knots older than `before_us` (but the one in force then)."""
        k = bisect.bisect_right(self.t_us, before_us) - 1
        if k > 0:
            del self.t_us[:k], self.p[:k], self.v[:k], self.a[:k]
            self._arrays = None
            self.folded = True

    def _truncate(self, from_us: int) -> None:
        """Drop the knots at or after `from_us` (the plan from there is being replaced)."""
        n = bisect.bisect_left(self.t_us, from_us)
        del self.t_us[n:], self.p[n:], self.v[n:], self.a[n:]
        self._arrays = None
        keep = KEEP_HISTORY_US if self.keep_history_us is None else self.keep_history_us
        self.fold(from_us - keep)

    def _knot(self, t_us: int, p: float, v: float, a: float) -> None:
        self._arrays = None
        if self.t_us and self.t_us[-1] == t_us:
            self.p[-1], self.v[-1], self.a[-1] = float(p), float(v), float(a)
            return
        self.t_us.append(int(t_us))
        self.p.append(float(p))
        self.v.append(float(v))
        self.a.append(float(a))


@dataclass
class Offsets:
    """The offsets of one operation, per axis, and what was done to them."""

    limits: OffsetLimits = field(default_factory=OffsetLimits)
    axes: dict[str, OffsetProfile] = field(
        default_factory=lambda: {a: OffsetProfile() for a in ALL_AXES})

    def snapshot(self) -> dict[str, OffsetProfile]:
        return {a: prof.copy() for a, prof in self.axes.items()}

    def restore(self, snapshot: dict[str, OffsetProfile]) -> None:
        self.axes = snapshot

    def change(self, axis: str, operation: str, value: float, from_us: int, *,
               sky_rate_arcsec_s: float | None = None, v_max: float | None = None) -> int:
        """Apply one operation to one axis from `from_us`; return when it is reached (µs).

        add: the total grows by `value`; set: the total becomes `value`; rate: the
        total drifts at `value` per second from now on (keeping what it reached);
        reset: back to 0 and no drift. `value` is arcsec (path: seconds). The path
        axis needs the target's sky rate (its limits come from it). `v_max`, when
        given, lowers the rate limit (a guide pulse moves at its guide rate).
        """
        prof = self.axes[axis]
        if operation == "reset" and not prof.t_us:
            return from_us  # never offset: nothing to undo
        p0, _ = prof.at(from_us)
        drift = prof.v[-1] if prof.t_us else 0.0  # the rate it keeps once a move is over
        rate_lim, acc_lim = self.axis_limits(axis, sky_rate_arcsec_s)
        if v_max is not None:
            rate_lim = min(rate_lim, v_max)
        if operation == "add":
            return prof.plan(from_us, _goal_after_drift(prof, from_us, p0) + value, drift,
                             rate_lim, acc_lim)
        if operation == "set":
            return prof.plan(from_us, value, drift, rate_lim, acc_lim)
        if operation == "rate":
            return prof.plan_rate(from_us, value, acc_lim)
        if operation == "reset":
            return prof.plan(from_us, 0.0, 0.0, rate_lim, acc_lim)
        raise ValueError(f"operation {operation!r}: expected one of {', '.join(OPERATIONS)}")

    def steer(self, axis: str, from_us: int, goal: float, goal_rate: float, *,
              sky_rate_arcsec_s: float | None = None) -> int:
        """Head for `goal` at `from_us`, moving on at `goal_rate` (the closed loop's estimate)."""
        rate_lim, acc_lim = self.axis_limits(axis, sky_rate_arcsec_s)
        return self.axes[axis].plan(from_us, goal, goal_rate, rate_lim, acc_lim)

    def axis_limits(self, axis: str, sky_rate_arcsec_s: float | None) -> tuple[float, float]:
        if axis in ("path", "guide_path"):
            if sky_rate_arcsec_s is None:
                raise ValueError("the path axis needs the target's sky rate")
            return self.limits.path_limits(sky_rate_arcsec_s)
        return self.limits.rate_arcsec_s, self.limits.accel_arcsec_s2

    def sample(self, t_us: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Return {axis: (offset, rate)} at mount times (arcsec, path seconds; per second),
        the closed loop's axes added into the user's (ra, dec, path, transverse)."""
        out = {a: self.axes[a].sample(t_us) for a in AXES}
        for loop in LOOP_AXES:
            prof = self.axes[loop]
            if prof.t_us:
                axis = loop.removeprefix("guide_")
                (p, v), (lp, lv) = out[axis], prof.sample(t_us)
                out[axis] = (p + lp, v + lv)
        return out

    def total(self, axis: str, t_us: int) -> float:
        """An axis's offset with the closed loop's share (path: seconds) at one time."""
        loop = self.axes.get(f"guide_{axis}")
        return self.axes[axis].at(t_us)[0] + (loop.at(t_us)[0] if loop is not None else 0.0)

    def knots_between(self, t0_us: int, t1_us: int) -> list[int]:
        return sorted({t for prof in self.axes.values() for t in prof.knots_between(t0_us, t1_us)})

    @property
    def any(self) -> bool:
        return any(prof.t_us for prof in self.axes.values())

    def settled_us(self) -> int:
        """The mount time after which every offset holds or drifts at a constant rate."""
        return max((prof.end_us for prof in self.axes.values()), default=0)

    def as_dict(self, t_us: int, sky_rate_arcsec_s: float | None = None) -> dict:
        """The status view at a mount time: per axis total, rate, goal and when reached."""
        out = {}
        for axis, prof in self.axes.items():
            p, v = prof.at(t_us)
            end = prof.end_us
            goal = prof.p[-1] + prof.v[-1] * max(t_us - end, 0) * 1e-6 if prof.t_us else 0.0
            unit = "s" if axis.endswith("path") else "arcsec"
            doc = {f"total_{unit}": p, f"rate_{unit}_per_s": v, f"goal_{unit}": goal,
                   "moving": bool(prof.t_us) and t_us < end, "changes": prof.changes}
            if unit == "s" and sky_rate_arcsec_s is not None:
                doc["total_arcsec"] = p * sky_rate_arcsec_s
            out[axis] = doc
        return out


def _goal_after_drift(prof: OffsetProfile, from_us: int, p0: float) -> float:
    """Where an axis would be at `from_us` once a move in progress has arrived.

    An `add` given while an earlier move still runs adds to that move's goal (as
    PWI4's offsets accumulate), not to the position reached half-way.
    """
    if not prof.t_us or prof.end_us <= from_us:
        return p0
    end = prof.end_us
    i = len(prof.t_us) - 1
    # the goal then moves at the final rate: bring it back to from_us
    return prof.p[i] - prof.v[i] * (end - from_us) * 1e-6
