"""The times of a pushing driver's ticks, from its pushes' arrival (µs).

The INDI simulator moves its place and pushes it every 250.5 ± 0.2 ms; the timestamp on
the push has whole seconds only. The host stamps a push when it handles it, which a busy
host does late: a grid of the driver's ticks is a better clock for the place.

But the grid is not fixed: libindi's drivers re-arm their timer after each tick, so a
tick the driver's process was late for (a loaded host) delays every tick after it — the
grid *slips*, later, and stays there. One late arrival cannot tell a push handled late
(the next push is back on the grid) from a slip (the next one is late too). So the tick
of a push is the earliest of the last few arrivals carried forward by whole periods (and
never later than its own arrival), and two pushes in a row later than that by more than
the usual lateness are a slip: the grid starts again from them.

(main lost an INDI pass to the first version of this grid, which held one fixed grid:
after a slip of more than its tolerance every later push was given the old grid's tick,
stamped early by the slip, and the loop held the mount that far behind the path for
ever; tests/backends/test_rate_predictor.py has the case.)
"""

from __future__ import annotations

import statistics
from collections import deque

__all__ = ["TickGrid"]


class TickGrid:
    """The times of a pushing driver's ticks, from its pushes' arrival (µs); see the module doc."""

    SPAN = 8  # the period is measured over this many ticks (one gap's jitter, divided by it)
    PERIODS = 48  # ... as the median of this many such measurements (a slip in a few of
    # them does not move it)
    MIN_PERIODS = 3  # ... before the grid is used at all (until then: the arrivals)
    WINDOW = 8  # the last pushes whose arrivals, carried forward by whole periods, bound
    # the next tick from above (the earliest of them is the tick)
    SLIP_PUSHES = 2  # this many pushes in a row later than the grid by more than
    SLIP_MIN_US = 2_000  # ... this (or 3 × their usual lateness): the grid slipped
    REANCHOR_PERIODS = 4  # a silence longer than this (a driver that pushes a place only
    # when it changed) starts the grid again: the period's error over it is not known

    def __init__(self) -> None:
        self.periods: deque[float] = deque(maxlen=self.PERIODS)
        self.period_us: float | None = None
        self._span: deque[int] = deque(maxlen=self.SPAN + 1)  # arrivals one tick apart
        self._recent: deque[tuple[int, int]] = deque(maxlen=self.WINDOW)  # (tick no., arrival)
        self._n = 0  # the number of the last tick
        self._lateness: deque[int] = deque(maxlen=self.PERIODS)  # arrival − tick given, µs
        self._late_run = 0  # pushes in a row later than the grid by more than the slip limit
        self.slips = 0  # times the grid was found to have slipped

    @property
    def residual_us(self) -> float:
        """The median lateness of the pushes behind the ticks they were given."""
        return float(statistics.median(self._lateness)) if self._lateness else 0.0

    def add(self, arrival_us: int) -> int:
        """Record a push and return the time of the tick it describes."""
        arrival_us = int(arrival_us)
        recent = self._recent
        last = recent[-1][1] if recent else None
        if last is not None and arrival_us <= last:
            return arrival_us  # out of order: not a tick
        if last is not None:
            self._measure_period(arrival_us - last, arrival_us)
        period = self.period_us
        if period is None or last is None or arrival_us - last > self.REANCHOR_PERIODS * period:
            recent.clear()
            self._n, self._late_run = 0, 0
            recent.append((0, arrival_us))
            return arrival_us
        self._n += max(1, round((arrival_us - last) / period))
        grid = min(a + (self._n - n) * period for n, a in recent)
        late = arrival_us - grid
        limit = max(self.SLIP_MIN_US, 3.0 * self.residual_us)
        self._late_run = self._late_run + 1 if late > limit else 0
        recent.append((self._n, arrival_us))
        if self._late_run >= self.SLIP_PUSHES:
            # the driver's ticks slipped (its timer re-armed late): only the pushes since
            # count; the earliest of them, carried forward, is the tick
            self.slips += 1
            for _ in range(len(recent) - self.SLIP_PUSHES):
                recent.popleft()
            grid = min(a + (self._n - n) * period for n, a in recent)
            self._late_run = 0
        tick = int(min(grid, arrival_us))
        self._lateness.append(arrival_us - tick)
        return tick

    def _measure_period(self, gap_us: int, arrival_us: int) -> None:
        """One more arrival for the period: the time over `SPAN` consecutive single-tick
        gaps, / SPAN (a gap that is not one tick, by the period so far, starts again)."""
        span = self._span
        guess = self.period_us or (span[-1] - span[-2] if len(span) >= 2 else gap_us)
        if abs(gap_us - guess) > 0.4 * guess:
            span.clear()
        span.append(arrival_us)
        if len(span) == span.maxlen:
            self.periods.append((span[-1] - span[0]) / self.SPAN)
            if len(self.periods) >= self.MIN_PERIODS:
                self.period_us = float(statistics.median(self.periods))
