"""The times of a pushing driver's regular ticks, from its pushes' arrival (µs).

The INDI simulator moves its place and pushes it every 250.5 ± 0.2 ms; the timestamp on
the push has whole seconds only. The host stamps a push when it handles it, which a busy
host does late: the tick grid fitted to the arrivals is a better clock for the place.
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["TickGrid"]


class TickGrid:
    """The times of a pushing driver's regular ticks, from its pushes' arrival (µs).

    A push arrives after its tick by the driver's and the host's handling, never before:
    the grid (period fitted over the window, phase from the earliest arrival relative to
    it) gives each push the time of its tick, without the host's jitter. Irregular pushes
    (no fixed tick, or a gap that breaks the count) fall back to the arrival itself.
    """

    WINDOW = 24  # arrivals the period is fitted over
    PHASE = 8  # the last arrivals the phase is taken from: short, so a driver whose tick
    # slipped (its timer late on a loaded host) is followed again within two seconds
    TOLERANCE = 0.15  # of a period: how far an arrival may lie from the grid and count
    LATE = 0.45  # ... and how late one push may be and still be given its tick

    def __init__(self) -> None:
        self.arrivals: deque[int] = deque(maxlen=self.WINDOW)
        self.period_us: float | None = None
        self.residual_us: float = 0.0  # the median arrival delay behind the grid
        self._tick: int | None = None  # the last tick given

    def add(self, arrival_us: int) -> int:
        """Record a push and return the time of the tick it describes."""
        a = self.arrivals
        if a and arrival_us <= a[-1]:
            return arrival_us
        if self.period_us is not None and self._tick is not None:
            n = max(1, round((arrival_us - self._tick) / self.period_us))
            expected = self._tick + n * self.period_us
            late = arrival_us - expected
            if self.TOLERANCE * self.period_us < late < self.LATE * self.period_us:
                # one push handled late (a busy host): the grid's tick, kept out of the fit
                self._tick = int(expected)
                return self._tick
        a.append(int(arrival_us))
        if len(a) < 6:
            return arrival_us
        t = np.asarray(a, np.int64)
        gaps = np.diff(t)
        base = float(np.median(gaps))
        k = np.round((t - t[0]) / base)
        if np.any(np.abs((t - t[0]) - k * base) > self.TOLERANCE * base):
            # not one grid over the window (a gap, a stall): restart from here
            self.arrivals = deque([int(arrival_us)], maxlen=self.WINDOW)
            self.period_us, self._tick = None, None
            return arrival_us
        period = float(np.polyfit(k, t - t[0], 1)[0])
        offsets = (t - t[0]) - k * period
        phase = float(np.min(offsets[-self.PHASE:]))
        self.period_us = period
        self.residual_us = float(np.median(offsets - phase))
        tick = min(int(t[0] + phase + k[-1] * period), int(arrival_us))
        self._tick = tick
        return tick
