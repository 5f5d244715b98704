"""Keep the mount's trajectory buffer filled ahead of its clock, never late.

The feeder samples a path on a fixed grid of mount time (`point_rate_hz`) and
pushes the points in batches whenever the buffer has free space, keeping
`lead_s` seconds of mount time buffered. Each cycle costs one read (mount
time, free space, state) and at most one push; between cycles it sleeps a
fraction of the lead in mount time on the VSS's clock (wall-paced or lockstep).
A point is never pushed less than `min_lead_s` before the mount reaches it: if
the feeder ever falls that far behind (a stalled host), it skips ahead on the
grid and counts the gap in `late_gaps` instead of sending points the mount would
reject. A mount that stops following once started is reported: `TrackingLost`
when its buffer ran dry (the target is then re-acquired), `OperationAborted`
when something outside the VSS stopped it, `MountFault` on a fault.

A correction (an offset, a guide pulse) changes the path while points of the
old one are buffered: `replace_from(from_us)` samples the changed path from
`from_us` up to the last point pushed and hands it to the mount's
`traj_replace` function, which drops the buffered future and appends the new
points between two ticks (docs/mount-emulator.md, `traj.replace_from`). Cycles
and replacements hold the feeder's lock, so the two never interleave. Where a
path says where its acceleration changes (`knots_between`), those instants are
sampled too, so the mount's cubic interpolation follows an offset's profile
exactly instead of rounding its corners between grid points.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .clock import MountClock
from .exceptions import MountFault, OperationAborted, TrackingLost
from .link_interface import MountBackend
from .trajectories import Path, Points

__all__ = ["Feeder", "FeederConfig", "FeederStats"]


@dataclass(frozen=True)
class FeederConfig:
    """Grid and lead of the trajectory feed (mount seconds)."""

    point_rate_hz: float = 20.0
    lead_s: float = 5.0
    min_lead_s: float = 0.5
    max_batch: int = 1000

    @property
    def step_us(self) -> int:
        return int(round(1e6 / self.point_rate_hz))


@dataclass
class FeederStats:
    """What the feeder did: points pushed and the smallest lead seen (mount µs)."""

    pushed: int = 0
    batches: int = 0
    rejected: int = 0
    late_gaps: int = 0
    replacements: int = 0
    replaced_points: int = 0
    min_lead_us: int | None = None
    first_point_us: int = 0
    last_point_us: int = 0
    ended: str = ""

    def as_dict(self) -> dict:
        return {"pushed": self.pushed, "batches": self.batches, "rejected": self.rejected,
                "late_gaps": self.late_gaps, "replacements": self.replacements,
                "replaced_points": self.replaced_points, "min_lead_s": None if self.min_lead_us is None
                else self.min_lead_us / 1e6, "ended": self.ended}


class Feeder:
    """Feeds one path to the mount; create one per trajectory."""

    def __init__(self, link: MountBackend, clock: MountClock, config: FeederConfig, path: Path,
                 first_us: int, *, fault_code: int, tracking_code: int,
                 on_points: Callable[[Points], None] | None = None) -> None:
        self.link = link
        self.clock = clock
        self.on_points = on_points
        self.config = config
        self.path = path
        self.step_us = config.step_us
        self.next_us = int(first_us)
        self.grid0_us = int(first_us)  # points fall on grid0_us + k·step_us (and knots)
        self.fault_code = fault_code
        self.tracking_code = tracking_code
        self.started = False  # set once the mount was told to follow the buffer
        self.stats = FeederStats()
        self.done = False
        self._roles = ["mount_time", "free_points", "mount_state"]
        if link.mapping.has("underruns"):
            self._roles.append("underruns")
        self._underruns: int | None = None
        self.lock = asyncio.Lock()  # a cycle and a replacement never interleave

    def times(self, first_us: int, last_us: int) -> np.ndarray:
        """The grid from `first_us` (on it) to `last_us`, plus the path's knots between."""
        n = max(0, (last_us - first_us) // self.step_us + 1)
        t = first_us + np.arange(n, dtype=np.int64) * self.step_us
        knots = getattr(self.path, "knots_between", None)
        if knots is None or not n:
            return t
        extra = [k for k in knots(first_us, int(t[-1])) if (k - first_us) % self.step_us]
        return np.union1d(t, np.asarray(extra, np.int64)) if extra else t

    async def cycle(self) -> int:
        """Top up the buffer once; return the mount time read (µs)."""
        async with self.lock:
            return await self._cycle()

    async def _cycle(self) -> int:
        v = await self.link.read(self._roles)
        now = int(v["mount_time"])
        state = int(v["mount_state"])
        underruns = int(v["underruns"]) if "underruns" in v else None
        if self._underruns is None:
            self._underruns = underruns
        if state == self.fault_code:
            raise MountFault("the mount went to FAULT while tracking")
        if self.started and state != self.tracking_code:
            self._left_trajectory(state, underruns)
        st = self.stats
        if st.pushed:
            lead = st.last_point_us - now
            st.min_lead_us = lead if st.min_lead_us is None else min(st.min_lead_us, lead)
        cfg = self.config
        earliest = now + int(cfg.min_lead_s * 1e6)
        if self.next_us <= earliest:
            if st.pushed:
                st.late_gaps += 1
            k = math.ceil((earliest + 1 - self.next_us) / self.step_us)
            self.next_us += k * self.step_us
        horizon = now + int(cfg.lead_s * 1e6)
        end = self.path.end_us
        if end is not None:
            horizon = min(horizon, end)
        n = 0 if self.next_us > horizon else (horizon - self.next_us) // self.step_us + 1
        free = int(v["free_points"])
        n = int(min(n, free, cfg.max_batch))
        if n > 0:
            t = self.times(self.next_us, self.next_us + (n - 1) * self.step_us)[:free]
            p = self.path.sample(t)
            accepted = await self.link.call("traj_push", p.t_us, p.az_rad, p.el_rad,
                                            p.az_rate_rad_s, p.el_rate_rad_s)
            if self.on_points is not None:
                self.on_points(p)
            if not st.batches:
                st.first_point_us = int(t[0])
            st.batches += 1
            st.pushed += int(accepted)
            st.rejected += len(t) - int(accepted)
            st.last_point_us = int(t[-1])
            self.next_us = int(t[-1]) + 1
            self._regrid()
        if end is not None and self.next_us > end:
            self.done = True
        return now

    async def replace_from(self, from_us: int) -> int:
        """Send the path again from `from_us` to the last point pushed (call under `lock`).

        The first point is at `from_us` itself; the rest on the grid and at the
        path's knots. Returns the points the mount accepted; raises MountRejected
        when it refused (too late: the caller tries again from later).
        """
        last = max(self.stats.last_point_us, from_us)
        k0 = (from_us - self.grid0_us) // self.step_us + 1  # the first grid point after from_us
        grid = self.grid0_us + np.arange(k0, (last - self.grid0_us) // self.step_us + 1,
                                         dtype=np.int64) * self.step_us
        knots = getattr(self.path, "knots_between", None)
        extra = knots(from_us, last) if knots is not None else []
        t = np.union1d(np.asarray([from_us, *extra], np.int64), grid)
        p = self.path.sample(t)
        accepted = int(await self.link.call("traj_replace", int(from_us), p.t_us, p.az_rad,
                                            p.el_rad, p.az_rate_rad_s, p.el_rate_rad_s))
        if self.on_points is not None:
            self.on_points(p)
        st = self.stats
        st.replacements += 1
        st.replaced_points += accepted
        if accepted < len(t):  # the buffer was full: the rest goes with the next cycle
            st.last_point_us = int(t[accepted - 1]) if accepted else from_us - 1
            self.next_us = st.last_point_us + 1
            self._regrid()
        return accepted

    def _regrid(self) -> None:
        """Put `next_us` back on the grid of the path's first point."""
        k = -(-(self.next_us - self.grid0_us) // self.step_us)
        self.next_us = self.grid0_us + k * self.step_us

    def _left_trajectory(self, state: int, underruns: int | None) -> None:
        name = self.link.mapping.state_name(state)
        if underruns is None or self._underruns is None or underruns > self._underruns:
            what = "its trajectory buffer ran dry" if underruns is not None else \
                "it left the trajectory (no underrun counter to tell why)"
            raise TrackingLost(f"the mount stopped tracking (state {name}): {what}; "
                               f"the last point pushed was for {self.stats.last_point_us} µs")
        raise OperationAborted(f"the mount stopped following the trajectory (state {name}) "
                               "without a buffer underrun: stopped outside the VSS")

    async def run(self) -> None:
        """Top up until the path ends (or the task is cancelled)."""
        pause_s = self.config.lead_s / 4.0
        while not self.done:
            await self.cycle()
            await self.clock.sleep(pause_s)
        self.stats.ended = "path ended"
