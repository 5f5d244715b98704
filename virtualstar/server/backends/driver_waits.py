"""Bounded waits on a driver: every request and every goto ends within a time we can state.

Two things live here, both pure of I/O:

* `within`: await something for at most so long. It is `asyncio.timeout` rather than
  `asyncio.wait_for` on purpose. Python 3.11's `wait_for` runs the awaited coroutine in a
  task of its own and, when a cancellation of the waiting task arrives in the loop
  iteration in which that inner task has just finished, returns the result and drops the
  cancellation (CPython gh-86296, fixed in 3.12). A poll loop that reads a driver through
  `wait_for` then never ends when it is cancelled at that moment, and whoever awaits it
  hangs with it: the Alpaca sky scenario's 720-s hang (the VSS polled the simulator for
  12 minutes after the test had closed it). `asyncio.timeout` runs the coroutine inline,
  so a cancellation always reaches it.
* `GotoBudget`: how long a goto may take before it is overdue, from the axis travel
  (the driver's own way: each native axis turns by its own difference, a German mount's
  flip through the pole included) and the slew rate the driver was *measured* to move at,
  plus a margin; `SlewRateMeter` keeps that measure from the gotos that landed.
"""

from __future__ import annotations

import asyncio
import math
import statistics
from collections import deque
from collections.abc import Awaitable
from dataclasses import dataclass, field
from typing import TypeVar

__all__ = ["GotoBudget", "SlewRateMeter", "axis_travel_deg", "within"]

T = TypeVar("T")

DEFAULT_SLEW_RATE_DEG_S = 1.0  # a driver that neither says nor has shown its goto speed
MIN_MEASURED_TRAVEL_DEG = 2.0  # a goto shorter than this says more about latency than speed


async def within(aw: Awaitable[T], timeout_s: float) -> T:
    """Await `aw` for at most `timeout_s` (TimeoutError after); a cancellation always wins."""
    async with asyncio.timeout(timeout_s):
        return await aw


def axis_travel_deg(ra1_h: float, dec1_deg: float, ra2_h: float, dec2_deg: float,
                    geometry: str) -> tuple[float, float]:
    """(direct, worst): the larger of the native axes' turns for a goto between two places
    of date (deg), the direct way, and the worst way the driver may take.

    Equatorial: the right-ascension axis by the shorter way round, the declination axis by
    the difference; a German mount may instead flip, its declination axis then passing the
    pole and its hour-angle axis going the other way round: *worst* allows for that, so a
    flip is never overdue, while the slew rate is measured on *direct* (a flip then only
    makes the measure slower, never faster). An alt-az driver takes its goto in RA/Dec as
    well (the way the drivers report), so the same measure holds for the time it takes.
    """
    d_ra = abs((ra2_h - ra1_h) * 15.0 + 180.0) % 360.0 - 180.0
    direct = max(abs(d_ra), abs(dec2_deg - dec1_deg))
    if geometry != "german":
        return direct, direct
    pole = 90.0 if dec1_deg + dec2_deg >= 0 else -90.0
    flip_dec = abs(pole - dec1_deg) + abs(pole - dec2_deg)
    return direct, max(direct, 180.0 - abs(d_ra), flip_dec)


@dataclass
class SlewRateMeter:
    """The goto speed the driver has shown: the median of travel / time of landed gotos."""

    rates_deg_s: deque = field(default_factory=lambda: deque(maxlen=20))

    def landed(self, travel_deg: float, seconds: float) -> None:
        if travel_deg >= MIN_MEASURED_TRAVEL_DEG and seconds > 0:
            self.rates_deg_s.append(travel_deg / seconds)

    def rate_deg_s(self) -> float | None:
        return statistics.median(self.rates_deg_s) if self.rates_deg_s else None


@dataclass(frozen=True)
class GotoBudget:
    """How long a goto may take: ``slow_factor × travel / rate + margin``.

    ``rate`` is the measured goto speed, else the one the driver declares, else
    `DEFAULT_SLEW_RATE_DEG_S`; the margin covers the driver's acceleration, its settle and
    the reports that show the end of the slew late (`report_periods` of them).
    """

    margin_s: float = 10.0
    slow_factor: float = 2.0
    report_periods: int = 4

    def bound_s(self, travel_deg: float, *, measured_deg_s: float | None,
                declared_deg_s: float | None, period_s: float | None) -> float:
        rate = measured_deg_s or declared_deg_s or DEFAULT_SLEW_RATE_DEG_S
        if not (math.isfinite(rate) and rate > 0):
            rate = DEFAULT_SLEW_RATE_DEG_S
        return (self.slow_factor * abs(travel_deg) / rate + self.margin_s
                + self.report_periods * (period_s or 0.25))
