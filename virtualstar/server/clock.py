"""How the VSS waits for mount time: paced by the wall clock, or in lockstep.

The VSS plans everything in mount time, read from the mount; it only needs to
*wait* for mount time to pass. Two clocks offer the same interface:

* `PacedClock(speed)`: the mount runs by itself (a real mount at speed 1, or a
  free-running emulator at ×speed); a wait of s mount seconds sleeps s/speed wall
  seconds. A loaded host can make the VSS late, so margins grow with the speed.
* `virtualstar.lockstep.LockstepClock`: the VSS and the embedded emulator share
  one virtual clock that advances only when every task waits; the VSS is never
  late and margins are those of real time (``speed`` is 1).

The clock is the one place the time mode is known: `Margins.for_clock` derives the
VSS's margins from it, and the status reports its `pace`.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

__all__ = ["Margins", "MountClock", "PacedClock"]

MIN_WALL_SLEEP_S = 0.0005
LOCKSTEP_LEAD_S = 30.0  # mount seconds of trajectory buffered in lockstep


class MountClock(Protocol):
    """What the VSS needs from a clock: waits in mount seconds."""

    lockstep: bool
    speed: float  # mount seconds per wall second the margins are sized for
    pace: float | None  # mount seconds per wall second now (None: as fast as the CPU allows)

    async def sleep(self, mount_s: float) -> None:
        """Let about `mount_s` seconds of mount time pass."""

    def awaited(self) -> contextlib.AbstractContextManager[None]:
        """A block in which a client waits for mount time to pass (a lockstep clock may
        run faster meanwhile; a mount that runs by itself cannot)."""


class PacedClock:
    """Wall-clock waits for a mount that runs by itself at `speed` × real time."""

    lockstep = False

    def __init__(self, speed: float = 1.0) -> None:
        if not speed > 0:
            raise ValueError(f"speed={speed}: expected mount seconds per wall second > 0")
        self.speed = float(speed)

    @property
    def pace(self) -> float:
        return self.speed

    async def sleep(self, mount_s: float) -> None:
        await asyncio.sleep(max(mount_s / self.speed, MIN_WALL_SLEEP_S))

    @contextlib.contextmanager
    def awaited(self) -> Iterator[None]:
        yield  # the mount keeps its own pace


@dataclass(frozen=True)
class Margins:
    """How far ahead of the mount clock the VSS works (mount seconds), from its clock.

    In real time and in lockstep the VSS is never later than a real-time host makes it;
    a mount running by itself at ×speed turns every wall-clock stall of the host into
    `speed` times more mount time, so the margins grow with it.
    """

    start_lead_s: float  # between "now" and the first point pushed (covers request delays)
    feed_lead_s: float  # points kept buffered ahead of the mount clock
    hold_after_run_out_s: float  # a finite path's hold after its run-out: stopping late is free

    @classmethod
    def for_clock(cls, clock: MountClock, lead_s: float | None = None) -> Margins:
        """Margins for `clock`; `lead_s` overrides the feed lead.

        The feed lead: 5 s in real time; in paced simulated time the same mount lead is
        a shorter wall time, and an event loop stalled by a loaded host must not drain
        the buffer: at least 3 s of wall time. In lockstep nothing is ever late, and
        longer batches cost less (each one computes the target's place once): 30 s.
        """
        speed = 1.0 if clock.lockstep else clock.speed
        if lead_s is None:
            lead_s = LOCKSTEP_LEAD_S if clock.lockstep else max(5.0, 3.0 * speed)
        return cls(start_lead_s=max(1.0, 0.25 * speed), feed_lead_s=lead_s,
                   hold_after_run_out_s=max(2.0, 1.0 * speed))
