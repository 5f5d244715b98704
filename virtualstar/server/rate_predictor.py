"""When a rate sent to a driver is in force, learned from its reports; and a driver's tick grid.

Measured on the two simulators we test against (benchmarks/bench_backends.py
``--measure`` repeats it; docs/mount-backends.md has the figures):

* alpaca-simulators: ``RightAscension``/``Declination`` advance the place when read, by
  the rate in force *then* over the whole time since the previous advance (a read by any
  client, or its own 100-ms thread). A ``MoveAxis`` is therefore in force from the
  driver's last update before it: retroactively from the report the loop just read.
* indi_simulator_telescope: every 250.5 ms (±0.2 ms) it moves the place by the rate in
  force at that tick over the whole tick, and pushes it. A ``TELESCOPE_TRACK_RATE`` that
  arrives before the next tick is in force over all of it: again from the last report.
  Its property timestamps have whole seconds only (no use for a 1°/s target); the tick
  grid itself is the driver-side clock (`backends.tick_grid.TickGrid`).

A real mount may take a command later (a serial link, a controller's own cycle). The
loop does not assume either: `ApplicationLag` keeps, for a set of candidate lags
``L`` (a rate sent after the report at ``t_r`` is in force from ``t_r + L``), the
squared mismatch between each reported displacement and the displacement the command
history predicts under that lag, with exponential forgetting, and uses the best. A
rate step (the join's run-up, the sign probe) identifies it within a few reports.

`plan_rate` is the command itself: the place predicted at ``t_r + L`` from the report
and the rates in force, the path's chord from there to the next command's time, and a
fraction ``gain`` of the predicted error (``gain = 1``: deadbeat, on the path at the
next command's time; smaller: less of the report time's noise fed back).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["ApplicationLag", "RateCommand", "integrate_rates", "plan_rate"]

LAG_CANDIDATES = 41  # candidate lags from 0 to LAG_MAX_PERIODS report periods
LAG_MAX_PERIODS = 2.0
FORGET = 0.97  # per report: the evidence of ~30 reports counts
MIN_EVIDENCE = 3  # report intervals with a rate change before the learned lag is used
OUTLIER_WINDOW = 16  # reports whose predicted errors set what counts as an outlier
OUTLIER_FACTOR = 4.0  # an error this many times their median is taken at that size
OUTLIER_FLOOR_RAD = 1.0 / 206264.806  # ... but errors up to 1″ always count in full
SPREAD_WINDOW = 32  # reports whose time uncertainties set what a usual one is
SPREAD_FLOOR_US = 500  # a report known to within this counts as well known as any


@dataclass(frozen=True)
class RateCommand:
    """A rate sent after the report at `report_us` (rad/s per axis); `sent_us` for the log."""

    report_us: int
    sent_us: int
    rates: tuple[float, float]


def integrate_rates(history: list[RateCommand], lag_us: int, initial: tuple[float, float],
                    t0_us: int, t1_us: int) -> np.ndarray:
    """The displacement (rad, per axis) from `t0_us` to `t1_us` when each command of
    `history` (in sending order) is in force from its report time + `lag_us`;
    `initial` is in force before the first."""
    edges = [(c.report_us + lag_us, c.rates) for c in history]
    out = np.zeros(2)
    rate = np.asarray(initial, float)
    t = t0_us
    for start, r in edges:
        if start <= t0_us:
            rate = np.asarray(r, float)
            continue
        if start >= t1_us:
            break
        out += rate * (start - t) / 1e6
        t, rate = start, np.asarray(r, float)
    out += rate * (t1_us - t) / 1e6
    return out


class ApplicationLag:
    """Learn when a command is in force (see the module doc); all times in µs."""

    def __init__(self, period_s: float, initial_lag_s: float = 0.0, *, learn: bool = True) -> None:
        self.period_s = period_s
        self.learn = learn  # False: keep `initial_lag_s` (the loop as it was before learning)
        self.candidates_us = np.linspace(0.0, LAG_MAX_PERIODS * period_s * 1e6,
                                         LAG_CANDIDATES).astype(np.int64)
        self.cost = np.zeros(LAG_CANDIDATES)
        self.evidence = 0.0
        self.initial_lag_us = int(initial_lag_s * 1e6)
        self.history: deque[RateCommand] = deque(maxlen=64)
        self.before: tuple[float, float] = (0.0, 0.0)  # the rates before the kept history
        self._last: tuple[int, np.ndarray] | None = None  # (t_us, place) of the last report

    @property
    def lag_us(self) -> int:
        if self.evidence < MIN_EVIDENCE or not self.learn:
            return self.initial_lag_us
        return int(self.candidates_us[int(np.argmin(self.cost))])

    @property
    def lag_s(self) -> float:
        return self.lag_us / 1e6

    def sent(self, command: RateCommand) -> None:
        if len(self.history) == self.history.maxlen:
            self.before = self.history[0].rates
        self.history.append(command)

    def reported(self, t_us: int, place: tuple[float, float],
                 wrap: Callable[[float], float] = lambda x: x) -> None:
        """A new report: score every candidate lag on the displacement since the last one."""
        here = np.asarray(place, float)
        last, self._last = self._last, (int(t_us), here)
        if last is None or t_us <= last[0]:
            return
        t0, p0 = last
        moved = np.array([wrap(here[0] - p0[0]), here[1] - p0[1]])
        initial, hist = self._from(t0)
        preds = np.array([integrate_rates(hist, int(lag), initial, t0, int(t_us))
                          for lag in self.candidates_us])
        spread = float(np.ptp(np.hypot(preds[:, 0], preds[:, 1])))
        err = np.hypot(preds[:, 0] - moved[0], preds[:, 1] - moved[1])
        self.cost = FORGET * self.cost + err**2
        # only an interval whose prediction depends on the lag is evidence about it
        if spread > 0.0 and spread > 1e-3 * float(np.hypot(*moved)):
            self.evidence = FORGET * self.evidence + 1.0

    def place_at(self, t_us: int) -> np.ndarray:
        """The place predicted at `t_us` from the last report and the commands in force."""
        if self._last is None:
            raise ValueError("no report yet")
        t0, p0 = self._last
        initial, hist = self._from(t0)
        return p0 + integrate_rates(hist, self.lag_us, initial, t0, int(t_us))

    def _from(self, t0_us: int) -> tuple[tuple[float, float], list[RateCommand]]:
        """The commands that may start after `t0_us` under any candidate lag, and the rates
        in force at `t0_us` before them (whatever the lag: they all started by then)."""
        horizon = t0_us - int(self.candidates_us[-1])
        initial = self.before
        tail: list[RateCommand] = []
        for c in self.history:
            if c.report_us <= horizon:
                initial = c.rates
            else:
                tail.append(c)
        return initial, tail


def plan_rate(place_at_effect: np.ndarray, path_at: Callable[[int], np.ndarray],
              effect_us: int, period_us: int, gain: float,
              wrap: Callable[[float], float] = lambda x: x) -> tuple[np.ndarray, np.ndarray,
                                                                     np.ndarray]:
    """(rate, feed-forward, predicted error) for a command in force from `effect_us` until
    the next one (a period later): the chord of the path plus `gain` × the error / period."""
    a = path_at(effect_us)
    b = path_at(effect_us + period_us)
    dt = period_us / 1e6
    ff = np.array([wrap(b[0] - a[0]), b[1] - a[1]]) / dt
    err = np.array([wrap(a[0] - place_at_effect[0]), a[1] - place_at_effect[1]])
    return ff + gain * err / dt, ff, err


class RatePredictor:
    """The rate loop's arithmetic, without I/O: reports in, the next command out.

    `RateFollower` calls `reported` at each new report, `command` for the rates to send
    and `sent` once they are sent; a test drives it the same way with a simulated driver.
    """

    def __init__(self, period_s: float, gain: float, initial_lag_s: float,
                 rates_in_force: tuple[float, float] = (0.0, 0.0),
                 wrap: Callable[[float], float] = lambda x: x, *, learn: bool = True) -> None:
        self.period_us = int(period_s * 1e6)
        self.gain = gain
        self.wrap = wrap
        self.lag = ApplicationLag(period_s, initial_lag_s, learn=learn)
        self.lag.before = rates_in_force
        self._t_rep = 0
        self._recent: deque[float] = deque(maxlen=OUTLIER_WINDOW)  # |predicted error|, rad
        self._large = False  # the last report's error was beyond the outlier limit
        self._spread_us = 0
        self._spreads: deque[int] = deque(maxlen=SPREAD_WINDOW)

    def reported(self, t_us: int, place: tuple[float, float], spread_us: int = 0) -> None:
        """A new report: the place at `t_us`, known to ±`spread_us` in time (a polled
        driver: half the read's own length; see `weight`)."""
        self._t_rep = int(t_us)
        self._spread_us = max(int(spread_us), 0)
        self._spreads.append(self._spread_us)
        self.lag.reported(t_us, place, self.wrap)

    @property
    def spread_us(self) -> int:
        """The newest report's time uncertainty (µs), as given to `reported`."""
        return self._spread_us

    def weight(self) -> float:
        """How much of the gain the newest report earns: 1 for a report whose time is known
        as well as usual (the median of the recent ones) or better, (usual / its own)² for
        a worse one. A polled report's time is only known to its read's length, which a
        busy host stretches now and then (20 ms is 70″ at 1°/s); the error it shows is then
        mostly that, so it is fed back in proportion to its inverse variance instead of in
        full (a least-squares filter's weighting, relative to the usual report)."""
        usual = max(float(np.median(self._spreads)) if self._spreads else 0.0, SPREAD_FLOOR_US)
        return min(1.0, (usual / max(self._spread_us, 1)) ** 2)

    def effect_us(self, now_us: int) -> int:
        """When a command sent now is in force: the last report + the learned lag, or now
        when the command comes so late that a newer driver update has been missed."""
        t_a = self._t_rep + self.lag.lag_us
        return t_a if now_us <= t_a + self.period_us else int(now_us)

    def command(self, now_us: int, path_at: Callable[[int], np.ndarray]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """(rate, feed-forward, predicted error, in force from) for a command sent now."""
        t_a = self.effect_us(now_us)
        place = self.lag.place_at(t_a)
        gain = self.gain * self.weight()
        rate, ff, err = plan_rate(place, path_at, t_a, self.period_us, gain, self.wrap)
        size = float(np.hypot(*err))
        large = False
        if len(self._recent) >= OUTLIER_WINDOW // 2:
            # one report stamped late by a busy host (20 ms is 70″ at 1°/s) is not where the
            # mount is: its error counts only up to a few times the recent ones' median. A
            # large error after a large one is a real change (an offset, a guide pulse, the
            # run-up's start): in full, and so on while they stay large (clipping every
            # other one, as the first version did, halved the speed of a real convergence)
            limit = max(OUTLIER_FACTOR * float(np.median(self._recent)), OUTLIER_FLOOR_RAD)
            large = size > limit
            if large and not self._large:
                err = err * (limit / size)
                rate = ff + gain * err / (self.period_us / 1e6)
        self._large = large
        self._recent.append(size)
        return rate, ff, err, t_a

    def sent(self, rates: tuple[float, float], now_us: int) -> None:
        self.lag.sent(RateCommand(self._t_rep, int(now_us), (float(rates[0]), float(rates[1]))))
