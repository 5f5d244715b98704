"""The hand pad: a move at rates whose rates change within 50 ms of mount time.

A `move` turns both axes at constant rates (a hand pad, ASCOM MoveAxis, INDI motion).
On a mount whose controller maps `traj_replace` (corrections.py), a move is a path
of its own, `MovePath`, fed like any other, and every change of its rates is planned
**from the minimum lead**, as offsets and guide pulses are:

* from rest, the first point is at `from_us` = the mount time + the controller's
  minimum lead (+ a margin for the requests that start the buffer, 0 in lockstep):
  the axes hold until then and leave with a constant acceleration at the axes'
  limits (no step in position or rate);
* a new `move` while one runs changes its rates: from `from_us` each axis goes from
  the position and rate it has there to the new rate at its acceleration limit,
  and the path's buffered future is sent again (`traj_replace`); zero rates ramp
  down to rest at once likewise, and the move ends;
* whenever the rates change, where the move must begin its run-out is planned again
  (`plan_stop`): so that the axes come to rest `LIMIT_MARGIN_DEG` inside the cable wrap
  and the elevation limits, and before a Sun/Moon/horizon zone, checked an hour ahead.

A controller without `traj_replace` keeps the behaviour from before (a run-up after
the start lead; a new move ends the running one and starts again); the operation's
`info.rate_changes` says which (`"replace_from"` or `"restart"`, with a note).

`MovePath` and `plan_stop` are pure; `HandPad` holds one move operation's path, its
feeder and the lock that orders its start, its rate changes and its end.
"""

from __future__ import annotations

import asyncio
import enum
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from virtualstar.astro import MountLimits, iso_utc

from .corrections import REPLACE_ATTEMPTS, replan
from .exceptions import MountRejected, TargetUnreachable
from .offsets import OffsetProfile
from .operations import Operation, current_operation
from .trajectories import Points

if TYPE_CHECKING:
    from .feeder import Feeder
    from .safety import Safety
    from .station import Station

__all__ = ["RATES_NOTE", "RESTART_NOTE", "HandPad", "MovePath", "PadState", "plan_stop"]

MOVE_LOOKAHEAD_S = 3600.0  # a move at rates is checked against the limits and zones this far
MOVE_CHECK_STEP_DEG = 0.1  # ... on a grid of mount time that moves at most this far a step
LIMIT_MARGIN_DEG = 0.5  # a move at rates comes to rest this far inside an axis limit
MOVE_HOLD_S = 1.0  # at rest after the run-out, still following the buffer, then told to stop
START_REQUESTS = 3  # requests after reading the mount time, traj_start included (margin each)
ZERO_RATES = "the hand pad's rates were set to 0"
RESTART_NOTE = ("the mount's mapping has no traj_replace function: a move starts after the "
                "start lead with a run-up, and a new move ends this one and starts again")
RATES_NOTE = ("a rate-driven mount (no trajectory buffer): its driver turns at the rates after "
              "the start lead, and a new move ends this one and starts again")


class MovePath:
    """Both axes from a place at a mount time, each along a profile of constant accelerations.

    Encoder frame, radians and rad/s (the azimuth continuous within the cable wrap).
    Endless: after its run-out it holds where it came to rest; the procedure ends it.
    """

    end_us: int | None = None

    def __init__(self, at_us: int, az_rad: float, el_rad: float) -> None:
        self.at_us = int(at_us)
        self.origin = np.array([az_rad, el_rad], float)
        # a run-out is planned up to an hour ahead of the change: keep what lies before
        keep_us = int(2 * MOVE_LOOKAHEAD_S * 1e6)
        self.axes = (OffsetProfile(keep_history_us=keep_us), OffsetProfile(keep_history_us=keep_us))

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        (daz, vaz), (del_, vel) = (prof.sample(t) for prof in self.axes)
        return Points(t, self.origin[0] + daz, self.origin[1] + del_, vaz, vel)

    def state(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return positions and rates, shape (n, 2), at mount times."""
        p = self.sample(t_us)
        return (np.column_stack([p.az_rad, p.el_rad]),
                np.column_stack([p.az_rate_rad_s, p.el_rate_rad_s]))

    def knots_between(self, t0_us: int, t1_us: int) -> list[int]:
        return sorted({k for prof in self.axes for k in prof.knots_between(t0_us, t1_us)})

    def change_rates(self, from_us: int, rates_rad_s, accel_rad_s2) -> int:
        """From `from_us`, bring each axis to its new rate at its acceleration and keep it;
        return when both have it (µs). What was planned after `from_us` is dropped."""
        return max(prof.plan_rate(from_us, float(v), float(a))
                   for prof, v, a in zip(self.axes, rates_rad_s, accel_rad_s2, strict=True))

    @property
    def rest_us(self) -> int:
        """The last change of acceleration: after it both axes keep their rates (at rest
        once a run-out was planned)."""
        return max(prof.end_us for prof in self.axes)

    def snapshot(self) -> tuple[OffsetProfile, OffsetProfile]:
        return tuple(prof.copy() for prof in self.axes)  # type: ignore[return-value]

    def restore(self, saved: tuple[OffsetProfile, OffsetProfile]) -> None:
        self.axes = saved


def plan_stop(path: MovePath, from_us: int, accel_rad_s2: np.ndarray, limits: MountLimits,
              safety: Safety, *, allow_sun: bool) -> tuple[int, str]:
    """Return the latest mount time from `from_us` the move's run-out may begin, and why.

    `path` is planned from `from_us` without a run-out. On a grid of mount time that
    moves at most MOVE_CHECK_STEP_DEG a step: the place each axis would come to rest
    if it began braking (at `accel_rad_s2`) there must stay LIMIT_MARGIN_DEG inside the
    limit it heads for, and the way must stay out of the zones (a hit is met a run-out
    early). Raises TargetUnreachable when the run-out would have to begin before
    `from_us` ("at once").
    """
    p_from, w_from = (x[0] for x in path.state(np.array([from_us], np.int64)))
    v = path.state(np.array([path.rest_us], np.int64))[1][0]  # the rates it keeps
    speed_deg_s = math.degrees(float(np.max(np.abs(v))))
    if speed_deg_s == 0.0:
        return from_us, ZERO_RATES
    ramp_s = (path.rest_us - from_us) / 1e6
    brake_s = float(np.max(np.abs(v) / accel_rad_s2))  # from the rates to rest
    step_s = min(1.0, MOVE_CHECK_STEP_DEG / speed_deg_s)
    m = math.radians(LIMIT_MARGIN_DEG)
    edges = []
    span_s = MOVE_LOOKAHEAD_S
    for axis, lo, hi, name in ((0, limits.wrap_min_deg, limits.wrap_max_deg, "the cable wrap"),
                               (1, limits.el_min_deg, limits.el_max_deg, "the elevation limit")):
        if v[axis] != 0.0:
            edge = math.radians(hi) - m if v[axis] > 0 else math.radians(lo) + m
            edges.append((axis, edge, f"stopped before {name} ({math.degrees(edge):.1f}°)"))
            # the edge is reached by then at the latest (the ramp may first go the other way)
            ramp_way = max(abs(w_from[axis]), abs(v[axis])) * ramp_s
            span_s = min(span_s, ramp_s + (abs(edge - p_from[axis]) + ramp_way) / abs(v[axis]))
    grid_s = np.arange(0.0, span_s + brake_s + 2 * step_s, step_s)
    t_us = from_us + np.round(grid_s * 1e6).astype(np.int64)
    p, w = path.state(t_us)
    rest = p + w * np.abs(w) / (2.0 * accel_rad_s2)
    stop_s = span_s
    why = ("an hour of moving elapsed" if span_s >= MOVE_LOOKAHEAD_S else
           "the end of the limits' reach")
    for axis, edge, text in edges:
        beyond = np.flatnonzero((rest[:, axis] - edge) * np.sign(v[axis]) > 0)
        if beyond.size:
            k = int(beyond[0])
            if k == 0:
                stop_s, why = -1.0, text
                break
            if grid_s[k - 1] <= stop_s:
                stop_s, why = float(grid_s[k - 1]), text
    if stop_s >= 0:
        ahead = t_us <= from_us + int((stop_s + brake_s + step_s) * 1e6)
        hit = safety.first_hit(p[ahead, 0], p[ahead, 1], t_us[ahead], allow_sun=allow_sun)
        if hit is not None:
            # braking from the rate there covers what |v|/2a seconds at that rate do
            hit_brake_s = float(np.max(np.abs(w[hit.index]) / (2.0 * accel_rad_s2)))
            hit_s = float(grid_s[hit.index]) - step_s - hit_brake_s
            if hit_s < stop_s:
                stop_s, why = hit_s, f"stopped before: {hit.describe('the mount')}"
    if stop_s < 0:
        raise TargetUnreachable(why)
    return from_us + int(stop_s * 1e6), why


class PadState(enum.Enum):
    PENDING = "pending"  # accepted, not started: a change sets the rates it starts with
    MOVING = "moving"  # following its path: a change is re-planned from the minimum lead
    ENDED = "ended"  # at rest or ended: a new move starts a new operation


class HandPad:
    """One move operation: its rates, its path and feeder, and the order of its changes."""

    def __init__(self, az_rate_deg_s: float, el_rate_deg_s: float, *, allow_sun: bool,
                 replace: bool, note: str = RESTART_NOTE) -> None:
        self.rates_deg_s = (float(az_rate_deg_s), float(el_rate_deg_s))
        self.allow_sun = allow_sun
        self.replace = replace  # the controller maps traj_replace (and the mount has a buffer)
        self.note = note  # why not, when not
        self.state = PadState.PENDING
        self.lock = asyncio.Lock()  # the start, each change and the end, one at a time
        self.changed = asyncio.Event()
        self.path: MovePath | None = None
        self.feeder: Feeder | None = None
        self.accel = np.zeros(2)  # rad/s² of each axis's ramps (set when it starts)
        self.stop_us = 0  # where the run-out begins
        self.why = ""
        self.changes = 0

    @property
    def zero(self) -> bool:
        return self.rates_deg_s == (0.0, 0.0)

    @property
    def end_us(self) -> int:
        """When the move ends: at rest, after the hold."""
        assert self.path is not None
        return self.path.rest_us + int(MOVE_HOLD_S * 1e6)

    @staticmethod
    def accel_rad_s2(limits: MountLimits) -> np.ndarray:
        return np.radians([limits.az_max_accel_deg_s2, limits.el_max_accel_deg_s2])

    # ------------------------------------------------------------------ planning
    def plan(self, t: Station, from_us: int, *, az_rad: float | None = None,
             el_rad: float | None = None) -> int:
        """Plan the current rates from `from_us` (a new path from a place at rest, or the
        running one changed) with its run-out; return when the rates are reached (µs)."""
        a = self.accel
        if az_rad is not None:
            self.path = MovePath(from_us, az_rad, el_rad)  # type: ignore[arg-type]
        path = self.path
        assert path is not None
        reached = path.change_rates(from_us, np.radians(self.rates_deg_s), a)
        stop_us, why = plan_stop(path, from_us, a, t.limits, t.safety, allow_sun=self.allow_sun)
        path.change_rates(stop_us, (0.0, 0.0), a)
        self.stop_us, self.why = stop_us, why
        return reached

    def report(self, t: Station, op: Operation, **info: Any) -> None:
        """Tell the clients the rates and where the move stops (an `operation` event)."""
        az, el = self.rates_deg_s
        op.target = f"move az {az:+g}°/s el {el:+g}°/s"
        if not self.replace:
            info["rate_changes_note"] = self.note
        t.supervisor.phase(op, op.phase, az_rate_deg_s=az, el_rate_deg_s=el,
                           stops_at_utc=iso_utc(self.stop_us), stops_for=self.why,
                           rate_changes="replace_from" if self.replace else "restart", **info)

    # ------------------------------------------------------------------ a new move command
    async def retarget(self, t: Station, op: Operation, az_rate_deg_s: float,
                       el_rate_deg_s: float, *, allow_sun: bool) -> bool:
        """Give the running move new rates; False when it cannot take them (start anew).

        Called under the supervisor's lock, so a `stop` sent after it is not overtaken.
        Refusals (a limit or zone at once, the mount refusing every re-plan) raise and
        leave the move as it was.
        """
        if not self.replace or allow_sun != self.allow_sun:
            return False
        async with self.lock:
            if self.state is PadState.ENDED:
                return False
            rates = (float(az_rate_deg_s), float(el_rate_deg_s))
            if self.state is PadState.PENDING:
                self.rates_deg_s = rates  # it starts with these
                return True
            before = self.rates_deg_s, self.stop_us, self.why
            self.rates_deg_s = rates
            token = current_operation.set(op.id)  # the mount's call log names the move
            try:
                done = await replan(t.steering.mode, t.motion.mount_time_us, lambda: self.feeder,
                                    lambda from_us: self.plan(t, from_us),
                                    self.path.snapshot, self.path.restore)  # type: ignore[union-attr]
            except TargetUnreachable as exc:
                self.rates_deg_s, self.stop_us, self.why = before
                raise TargetUnreachable(f"move at az {rates[0]:g}°/s, el {rates[1]:g}°/s: "
                                        f"{exc} at once; the move goes on as it was") from None
            except BaseException:
                self.rates_deg_s, self.stop_us, self.why = before
                raise
            finally:
                current_operation.reset(token)
            if done is None:
                self.rates_deg_s, self.stop_us, self.why = before
                raise MountRejected(f"move: the mount refused the re-planned trajectory "
                                    f"{REPLACE_ATTEMPTS} times (the host is too slow for the "
                                    f"{t.steering.mode.min_lead_us / 1000:g} ms lead); the move "
                                    "goes on as it was: send it again")
            self.changes += 1
            self.report(t, op, changes=self.changes, last_change={
                "accepted_us": done.accepted_us, "from_us": done.from_us,
                "lead_ms": done.lead_ms, "reached_us": int(done.value), "sent": done.sent,
                "az_rate_deg_s": rates[0], "el_rate_deg_s": rates[1]})
            self.changed.set()
            t.log_event("info", "move", f"operation {op.id}: rates az {rates[0]:+g}°/s el "
                        f"{rates[1]:+g}°/s from {iso_utc(done.from_us, 3)} "
                        f"({done.lead_ms:.0f} ms after acceptance, {done.sent}); "
                        f"{self.why} at {iso_utc(self.stop_us)}", id=op.id,
                        from_us=done.from_us, lead_ms=done.lead_ms)
            return True

    # ------------------------------------------------------------------ the procedure's side
    async def wait_for_end(self, t: Station, op: Operation) -> None:
        """Wait in mount time until the move is at rest and held; a change wakes it."""
        while True:
            async with self.lock:
                now = await t.motion.mount_time_us()
                if now >= self.end_us:
                    self.state = PadState.ENDED
                    return
                self.changed.clear()
                end = self.end_us
            sleeping = asyncio.ensure_future(t.motion.wait_until(end, op.info))
            changed = asyncio.ensure_future(self.changed.wait())
            try:
                await asyncio.wait({sleeping, changed}, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for task in (sleeping, changed):
                    task.cancel()
                # neither outlives this; a cancellation of this task itself still propagates
                await asyncio.wait({sleeping, changed})
            if sleeping.done() and not sleeping.cancelled() and sleeping.exception() is not None:
                raise sleeping.exception()  # type: ignore[misc]
