"""TimeS: keep the mount clock on UTC by arming the UTC second of the next PPS edge.

In real time the host clock (NTP/GPS disciplined) is UTC: shortly after a
second has begun, TimeS sends the mount the number of the *next* second; the
mount's clock takes that value exactly at its next PPS edge, which removes the
drift of its crystal. Arming only in the middle of a second (away from both
edges) makes the intended edge unambiguous.

In simulated time the emulator owns mount time, so TimeS only verifies: it
reads the mount clock beside the emulator's own UTC truth (when the mapping has
a ``utc_truth`` role) and reports the offset.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

from .exceptions import VssError
from .mount_link import MountLink

__all__ = ["TimeSync", "TimeSyncStatus"]

ARM_WINDOW_US = (200_000, 700_000)  # arm only this far into a host second


@dataclass
class TimeSyncStatus:
    """What TimeS knows: mode, seconds armed, last measured offset mount − UTC (µs)."""

    mode: str
    armed: int = 0
    offset_us: int | None = None
    pps_error_us: float | None = None
    syncs: int | None = None

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class TimeSync:
    """Periodically sync (real time) or verify (simulated time) the mount clock."""

    def __init__(self, link: MountLink, *, simulated: bool, period_s: float = 10.0) -> None:
        self.link = link
        self.simulated = simulated
        self.period_s = period_s
        self.status = TimeSyncStatus("verify" if simulated else "sync")
        self.active = True  # False: measure only (a passive server commands nothing)

    async def sync_once(self) -> None:
        """Arm the next UTC second (real time) and measure the offset."""
        if not self.simulated and self.active:
            for _ in range(10):
                frac = time.time_ns() // 1000 % 1_000_000
                if ARM_WINDOW_US[0] <= frac <= ARM_WINDOW_US[1]:
                    break
                await asyncio.sleep(0.1)
            now_us = time.time_ns() // 1000
            await self.link.call("time_sync", now_us // 1_000_000 + 1)
            self.status.armed += 1
        await self.verify()

    async def verify(self) -> None:
        roles = ["mount_time"] + [r for r in ("utc_truth", "pps_error", "sync_count")
                                  if self.link.mapping.has(r)]
        t_host = time.time_ns() // 1000
        v = await self.link.read(roles)
        if self.simulated:
            if "utc_truth" in v:
                self.status.offset_us = int(v["mount_time"]) - int(v["utc_truth"])
        else:
            self.status.offset_us = int(v["mount_time"]) - t_host
        self.status.pps_error_us = v.get("pps_error")
        self.status.syncs = v.get("sync_count")

    async def run(self) -> None:
        """Sync now and every `period_s` seconds until cancelled; survive mount losses."""
        while True:
            try:
                await self.link.wait_connected()
                await self.sync_once()
            except VssError:
                pass
            await asyncio.sleep(self.period_s)
