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
"""

from __future__ import annotations

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
    min_lead_us: int | None = None
    first_point_us: int = 0
    last_point_us: int = 0
    ended: str = ""

    def as_dict(self) -> dict:
        return {"pushed": self.pushed, "batches": self.batches, "rejected": self.rejected,
                "late_gaps": self.late_gaps, "min_lead_s": None if self.min_lead_us is None
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
        self.fault_code = fault_code
        self.tracking_code = tracking_code
        self.started = False  # set once the mount was told to follow the buffer
        self.stats = FeederStats()
        self.done = False
        self._roles = ["mount_time", "free_points", "mount_state"]
        if link.mapping.has("underruns"):
            self._roles.append("underruns")
        self._underruns: int | None = None

    async def cycle(self) -> int:
        """Top up the buffer once; return the mount time read (µs)."""
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
        n = int(min(n, int(v["free_points"]), cfg.max_batch))
        if n > 0:
            t = self.next_us + np.arange(n, dtype=np.int64) * self.step_us
            p = self.path.sample(t)
            accepted = await self.link.call("traj_push", p.t_us, p.az_rad, p.el_rad,
                                            p.az_rate_rad_s, p.el_rate_rad_s)
            if self.on_points is not None:
                self.on_points(p)
            if not st.batches:
                st.first_point_us = int(t[0])
            st.batches += 1
            st.pushed += int(accepted)
            st.rejected += n - int(accepted)
            st.last_point_us = int(t[-1])
            self.next_us = int(t[-1]) + self.step_us
        if end is not None and self.next_us > end:
            self.done = True
        return now

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
