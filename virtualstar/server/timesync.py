"""TimeS: keep the mount clock on UTC by arming the UTC second of the next PPS edge.

The mount's clock takes an armed second exactly at its next PPS edge, which
removes the drift of its crystal. TimeS arms the *next* second only in the
middle of the current one (between `ARM_WINDOW_US`), so the intended edge is
never ambiguous and the sync has no whole-second offset.

What counts as UTC:

* real time: the host clock (NTP/GPS disciplined) is UTC. TimeS waits for the
  window on the host clock and arms host second + 1.
* simulated time (paced or lockstep): the emulator's own UTC truth (the mapping's
  ``utc_truth`` role, what its PPS marks) is UTC; TimeS waits for the window in
  mount time and arms truth second + 1, the same way. Without that role it can
  only report.

After each sync TimeS measures the offset mount − UTC: against the mount's UTC
truth read at the same tick when the mapping has one, else against the host clock
at the middle of the read (its latency included). Offsets go to `on_offset` for
the on-sky error.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass

from .clock import MountClock
from .exceptions import VssError
from .link_interface import MountBackend

__all__ = ["ARM_WINDOW_US", "TimeSync", "TimeSyncStatus"]

ARM_WINDOW_US = (200_000, 700_000)  # arm only this far into a UTC second
_ARM_AT_US = 450_000  # aim for the middle of the window
_AFTER_EDGE_US = 20_000  # measure this long after the edge that applies the armed second


@dataclass
class TimeSyncStatus:
    """What TimeS knows: mode, seconds armed, last measured offset mount − UTC (µs)."""

    mode: str
    armed: int = 0
    offset_us: int | None = None
    offset_source: str | None = None  # "utc truth" (the mount's PPS truth) or "host clock"
    host_offset_us: int | None = None  # real time: mount − host clock, read latency included
    pps_error_us: float | None = None
    syncs: int | None = None

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class TimeSync:
    """Periodically sync the mount clock to UTC and measure its offset."""

    def __init__(self, link: MountBackend, clock: MountClock, *, simulated: bool,
                 period_s: float = 10.0,
                 on_offset: Callable[[int, int], None] | None = None) -> None:
        self.link = link
        self.clock = clock
        self.simulated = simulated
        self.period_s = period_s
        self.on_offset = on_offset or (lambda t_us, offset_us: None)
        self.status = TimeSyncStatus("sync to utc truth" if simulated else "sync to host utc")
        self.active = True  # False: measure only (a passive server commands nothing)

    async def sync_once(self) -> None:
        """Measure the offset, arm the next UTC second mid-second, measure again after its edge.

        The measurement before the sync is the drift accumulated since the last one (the
        worst offset of the period), the one after it what the sync left.
        """
        if not self.active or not self.link.capabilities.time_sync:
            # a driver without a PPS clock keeps its own time (host UTC): only measured
            if not self.link.capabilities.time_sync:
                self.status.mode = "verify only (the driver keeps its own time)"
            await self.verify()
            return
        second = await self._second_in_window()
        await self.verify()
        if second is not None and self.active:  # it may have gone passive meanwhile
            await self.link.call("time_sync", second + 1)
            self.status.armed += 1
            await self._past_edge(second + 1)
            await self.verify()

    async def _utc_us(self) -> int | None:
        """UTC now, µs: the mount's UTC truth in simulated time (None without that role),
        the host clock in real time."""
        if not self.simulated:
            return time.time_ns() // 1000
        if not self.link.mapping.has("utc_truth"):
            self.status.mode = "verify only (the mount has no utc_truth role)"
            return None
        return int((await self.link.read(["utc_truth"]))["utc_truth"])

    async def _sleep_utc(self, seconds: float) -> None:
        """Let `seconds` of UTC pass: mount time in simulated time, wall time in real time."""
        if self.simulated:
            await self.clock.sleep(seconds)
        else:
            await asyncio.sleep(seconds)

    async def _second_in_window(self) -> int | None:
        """Wait until UTC lies inside `ARM_WINDOW_US` of its second; return that second
        (None: no UTC to sync to, or the window was missed 20 times)."""
        for _ in range(20):
            now = await self._utc_us()
            if now is None:
                return None
            frac = now % 1_000_000
            if ARM_WINDOW_US[0] <= frac <= ARM_WINDOW_US[1]:
                return now // 1_000_000
            await self._sleep_utc(((_ARM_AT_US - frac) % 1_000_000) / 1e6)
        return None

    async def _past_edge(self, second: int) -> None:
        """Wait until just after the PPS edge of `second`, so the measurement sees the sync."""
        now = await self._utc_us()
        if now is not None:
            await self._sleep_utc(max(second * 1_000_000 + _AFTER_EDGE_US - now, 0) / 1e6)

    async def verify(self) -> None:
        """Measure the mount clock's offset from UTC."""
        roles = ["mount_time"] + [r for r in ("utc_truth", "pps_error", "sync_count")
                                  if self.link.mapping.has(r)]
        before = time.time_ns() // 1000
        v = await self.link.read(roles)
        after = time.time_ns() // 1000
        mount_us = int(v["mount_time"])
        if not self.simulated:
            self.status.host_offset_us = mount_us - (before + after) // 2
        if "utc_truth" in v:
            self.status.offset_us = mount_us - int(v["utc_truth"])
            self.status.offset_source = "utc truth"
        elif not self.simulated:
            self.status.offset_us = self.status.host_offset_us
            self.status.offset_source = "host clock"
        self.status.pps_error_us = v.get("pps_error")
        self.status.syncs = v.get("sync_count")
        if self.status.offset_us is not None:
            self.on_offset(mount_us, self.status.offset_us)

    async def run(self) -> None:
        """Sync now and every `period_s` mount seconds until cancelled; survive mount losses."""
        while True:
            try:
                await self.link.wait_connected()
                await self.sync_once()
            except VssError:
                pass
            await self.clock.sleep(self.period_s)
