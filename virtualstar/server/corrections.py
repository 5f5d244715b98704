"""How a correction reaches the mount within 50 ms: re-plan from the minimum lead.

One `Corrections` per operation holds its `Offsets` (offsets.py) and the feeder
currently filling the mount's buffer. A change (an offset command, a guide
pulse, the closed loop's estimate) is planned from `from_us` and sent:

* **replace_from** (the controller maps the `traj_replace` role): `from_us` is
  the mount time now + the controller's minimum lead (`traj.replace_min_lead_us`,
  20 ms on the emulator) + a margin for the request's own travel (none in
  lockstep, where mount time stands still while the VSS works; 10 ms × speed
  otherwise). The offsets' profile changes from `from_us`, and the feeder sends
  the path again from `from_us` to the last point buffered, which the mount
  swaps in between two ticks. If the mount refuses (the request came too late,
  a stalled host), the profile is put back as it was and the change is planned
  again from a later `from_us` (twice the margin, up to four times).
* **append-only** (no `traj_replace` role): the change starts after the last point
  already pushed, `feed_lead_s` later (5 s in real time) — the old behaviour,
  which `status` reports as `corrections.mode = "append-only"`.
* **rate_loop** (a rate-driven mount, Alpaca/INDI: no buffer at all): the change
  starts now; the rate loop samples the path at every driver report, so it is in
  force from the loop's next command (one report period, plus the driver's measured
  application lag).

Before the track has joined its path (preparing, slewing, the run-up), a change
starts at the join (`hold_until`), so the run-up aims at the offset place.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from .exceptions import MountRejected, NotTracking
from .feeder import Feeder
from .offset_path import OffsetPath, sky_rate_arcsec_s
from .offsets import OffsetLimits, Offsets
from .trajectories import Path

__all__ = ["CorrectionMode", "Corrections", "Replanned", "replan", "start_of_change"]

REPLACE_ATTEMPTS = 4


@dataclass(frozen=True)
class CorrectionMode:
    """How corrections reach this mount: its capability and the leads used (µs)."""

    can_replace: bool
    min_lead_us: int  # the controller's documented minimum lead
    margin_us: int  # what the VSS adds for a request's travel (0 in lockstep)
    rate_loop: bool = False  # a rate-driven mount: the VSS's rate loop samples the path

    def as_dict(self) -> dict[str, Any]:
        if self.rate_loop:
            return {"mode": "rate_loop", "min_lead_ms": 0.0, "margin_ms": 0.0,
                    "note": ("a rate-driven mount: offsets and guide pulses start when accepted "
                             "and are in force from the rate loop's next command (the next "
                             "report of the driver, plus its measured application lag)")}
        doc = {"mode": "replace_from" if self.can_replace else "append-only",
               "min_lead_ms": self.min_lead_us / 1000, "margin_ms": self.margin_us / 1000}
        if not self.can_replace:
            doc["note"] = ("the mount's mapping has no traj_replace function: offsets and guide "
                           "pulses start after the points already buffered (feed lead)")
        return doc


Change = Callable[[Offsets, int, float | None], int]
S = TypeVar("S")


@dataclass(frozen=True)
class Replanned:
    """A change that reached the mount: when it was accepted and starts (µs), how it was sent."""

    accepted_us: int  # the mount time read when it was planned
    from_us: int  # where the changed path begins
    sent: str  # "replace_from", "planned" (the next batch has it), "appended" or "rate_loop"
    value: Any  # what the change returned

    @property
    def lead_ms(self) -> float:
        return (self.from_us - self.accepted_us) / 1000


def start_of_change(mode: CorrectionMode, feeder: Feeder | None, now_us: int, margin_us: int,
                    not_before_us: int | None = None) -> tuple[int, str]:
    """Where a change may start, and how it reaches the mount."""
    floor = not_before_us if not_before_us is not None else now_us
    if mode.rate_loop:
        return max(now_us, floor), "rate_loop"  # the loop's next command samples it
    if feeder is None or not feeder.stats.pushed:
        return max(now_us, floor), "planned"  # nothing buffered yet: the next batch has it
    if mode.can_replace:
        from_us = max(now_us + mode.min_lead_us + margin_us, floor)
        if from_us <= feeder.stats.last_point_us:
            return from_us, "replace_from"
        return from_us, "planned"  # beyond the points buffered: the next batch has it
    return max(feeder.next_us, floor), "appended"


async def replan(mode: CorrectionMode, clock_now: Callable[[], Awaitable[int]],
                 feeder_of: Callable[[], Feeder | None], change: Callable[[int], Any],
                 snapshot: Callable[[], S], restore: Callable[[S], None], *,
                 not_before_us: int | None = None) -> Replanned | None:
    """Change a path from the earliest mount time the mount allows and send its future again.

    Under the feeder's lock (no cycle in between): read the mount time, choose `from_us`
    (`start_of_change`), apply `change(from_us)` to what the feeder samples and, with
    `traj_replace`, send the path again from `from_us`. A refusal (the time went by)
    puts the state back (`restore(snapshot())`) and tries again from later, up to
    REPLACE_ATTEMPTS times; None when every attempt was refused. Any other error
    restores the state and propagates.
    """
    margin = mode.margin_us
    for _attempt in range(REPLACE_ATTEMPTS):
        feeder = feeder_of()
        guard = feeder.lock if feeder is not None else contextlib.nullcontext()
        async with guard:
            now = int(await clock_now())
            from_us, how = start_of_change(mode, feeder, now, margin, not_before_us)
            saved = snapshot()
            try:
                value = change(from_us)
                if how == "replace_from":
                    await feeder.replace_from(from_us)  # type: ignore[union-attr]
            except MountRejected:
                restore(saved)  # the mount keeps the old points
                margin = max(2 * margin, 5_000)
                continue
            except BaseException:
                restore(saved)
                raise
            return Replanned(now, from_us, how, value)
    return None


class Corrections:
    """The offsets of one operation and the way their changes reach the mount."""

    def __init__(self, mode: CorrectionMode, clock_now: Callable[[], Any], lat_rad: float, *,
                 limits: OffsetLimits | None = None) -> None:
        self.mode = mode
        self._now = clock_now  # async () -> mount time µs
        self.lat_rad = lat_rad
        self.offsets = Offsets(limits or OffsetLimits())
        self.path: OffsetPath | None = None
        self.feeder: Feeder | None = None
        self.not_before_us: int | None = None
        self.history: list[dict[str, Any]] = []
        self._lock = asyncio.Lock()

    # -------------------------------------------------------------- procedures' side
    def wrap(self, base: Path, *, end_us: int | None = None) -> OffsetPath:
        """Return `base` with these offsets applied (the path the feeder samples)."""
        self.path = OffsetPath(base, self.offsets, self.lat_rad, end_us=end_us)
        return self.path

    def hold_until(self, join_us: int) -> None:
        """Changes from now on start no earlier than the join of the path (the run-up's end)."""
        self.not_before_us = int(join_us)

    def attach(self, feeder: Feeder | None) -> None:
        self.feeder = feeder

    # -------------------------------------------------------------- commands' side
    def sky_rate_at(self, t_us: int) -> float | None:
        """The target's sky rate (arcsec/s) at a mount time, or None before a path exists."""
        if self.path is None:
            return None
        p = self.path.base.sample(np.array([t_us], np.int64))
        return float(sky_rate_arcsec_s(p)[0])

    async def apply(self, what: str, change: Change) -> dict[str, Any]:
        """Plan `change(offsets, from_us, sky_rate)` from the earliest mount time and send it.

        Returns when it starts (`from_us`), when it is reached, the lead it was given
        (from the mount time it was accepted at) and how it was sent.
        """
        async with self._lock:
            done = await replan(
                self.mode, self._now, lambda: self.feeder,
                lambda from_us: change(self.offsets, from_us, self.sky_rate_at(from_us)),
                self.offsets.snapshot, self.offsets.restore, not_before_us=self.not_before_us)
            if done is None:
                raise NotTracking(f"{what}: the mount refused the re-planned trajectory "
                                  f"{REPLACE_ATTEMPTS} times (the host is too slow for the "
                                  f"{self.mode.min_lead_us / 1000:g} ms lead); try again")
            record = {"what": what, "accepted_us": done.accepted_us, "from_us": done.from_us,
                      "reached_us": int(done.value), "lead_ms": done.lead_ms, "sent": done.sent}
            self.history = (self.history + [record])[-50:]
            return record

    def status(self, t_us: int) -> dict[str, Any]:
        """What the offsets are at a mount time (per axis), and the last changes."""
        rate = None
        with contextlib.suppress(Exception):  # a path that cannot be sampled now: no rate
            rate = self.sky_rate_at(t_us)
        doc = self.offsets.as_dict(t_us, rate)
        return {"axes": {a: d for a, d in doc.items() if d["changes"]},
                "target_rate_arcsec_s": None if rate is None or math.isnan(rate) else rate,
                "last_changes": self.history[-5:]}
