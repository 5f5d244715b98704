"""How the VSS waits for mount time: paced by the wall clock, or in lockstep.

The VSS plans everything in mount time, read from the mount; it only needs to
*wait* for mount time to pass. Two clocks offer the same interface:

* `PacedClock(speed)`: the mount runs by itself (a real mount at speed 1, or a
  free-running emulator at ×speed); a wait of s mount seconds sleeps s/speed wall
  seconds. A loaded host can make the VSS late, so margins grow with the speed.
* `virtualstar.lockstep.LockstepClock`: the VSS and the embedded emulator share
  one virtual clock that advances only when every task waits; the VSS is never
  late and margins are those of real time (``speed`` is 1).
"""

from __future__ import annotations

import asyncio
from typing import Protocol

__all__ = ["MountClock", "PacedClock"]

MIN_WALL_SLEEP_S = 0.0005


class MountClock(Protocol):
    """What the VSS needs from a clock: waits in mount seconds."""

    lockstep: bool
    speed: float  # mount seconds per wall second the margins are sized for

    async def sleep(self, mount_s: float) -> None:
        """Let about `mount_s` seconds of mount time pass."""


class PacedClock:
    """Wall-clock waits for a mount that runs by itself at `speed` × real time."""

    lockstep = False

    def __init__(self, speed: float = 1.0) -> None:
        if not speed > 0:
            raise ValueError(f"speed={speed}: expected mount seconds per wall second > 0")
        self.speed = float(speed)

    async def sleep(self, mount_s: float) -> None:
        await asyncio.sleep(max(mount_s / self.speed, MIN_WALL_SLEEP_S))
