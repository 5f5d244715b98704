"""Follow a path on a mount that takes axis rates: goto a point ahead, then a closed rate loop.

For a mount whose capabilities have ``rate_axes`` and no trajectory buffer (ASCOM
Alpaca ``MoveAxis``, INDI ``TELESCOPE_TRACK_RATE``), the VSS closes the loop itself:

1. **Join** (`acquire_by_rates`): goto (the driver's own slew) to the start of a
   *run-up*: the place from which moving at the path's rate at the join instant (a
   straight line in the native axes) reaches the path's place at the join, chosen
   from the distance and the driver's rate; hold there with the mount's own tracking
   (an equatorial mount keeps its place of date). The loop follows the run-up line
   from `run_up_us` before the join, so the step from rest to the path's rate (up to
   about 1°/s for a low satellite) is taken, and its error removed, before the join:
   at the join the demand is continuous in place and rate (`run_up_s`: 8 report periods,
   at least `RUN_UP_MIN_S`).
2. **Signs**: once per connection and pier side, a short probe at a small rate on each
   axis measures which way each driver axis moves the place (drivers and pier sides
   differ): measured, not assumed.
3. **Loop** (`RateFollower.run`): at every new report of the driver (its period is
   measured by the backend), the place the mount will have when the next command takes
   effect is predicted from the report and the commands in force; when a command takes
   effect is *learned* from the reports (`rate_predictor.ApplicationLag`: both simulators
   apply a rate retroactively from their last update, a real mount may take it later).
   The command for the next report period is the feed-forward (the path's chord from the
   time it takes effect to the next command's) plus a fraction `gain` of the predicted
   error then, within the driver's rate limit (`rate_predictor.plan_rate`). Rates too
   close to the last to matter are not sent, so a sidereal target on an equatorial mount
   is left to the mount's own tracking.

Every report is compared with the path *at that report's own mount time* (the middle
of the interval in which it appeared): that error goes to the tracking-error history,
and the time's uncertainty × the path's rate is kept beside it. Paths are in the
VSS's encoder frame (observed az/el); `NativeFrame` turns them into the mount's axes
(right ascension and declination of date for an equatorial mount).

Safety: a German mount's track stops before the target crosses the meridian (it would
need a flip, which is never done in the middle of a track); a report older than
`STALE_REPORTS` periods, or a driver that does not take a command, ends the operation
with `MountFault` after telling the mount to stop (a rate once sent keeps it moving).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from virtualstar.astro import EarthOrientation, Site
from virtualstar.astro.constants import ARCSEC_PER_RAD
from virtualstar.astro.mount_frames import (
    apparent_radec_to_observed,
    hour_angle_rad,
    observed_to_apparent_radec,
)

from .exceptions import (
    MountFault,
    MountUnavailable,
    NotArrived,
    OperationAborted,
    TargetUnreachable,
)
from .link_interface import MountCapabilities
from .rate_predictor import RatePredictor
from .trajectories import Path, Points

__all__ = ["FollowStats", "NativeFrame", "RateFollower", "RateJoin", "gain_per_period", "run_up_s",
           "run_up_start"]

log = logging.getLogger("virtualstar.server")

GAIN = 0.6  # fraction of the predicted error removed per GAIN_PERIOD_S (1: deadbeat; less
GAIN_PERIOD_S = 0.25  # feeds back less of the report time's noise: a 1-ms stamp error is
# 3.6″ at 1°/s). A driver that reports more often gets the same rate of removal in time,
# so a smaller fraction per report (`gain_per_period`): 0.18 at Alpaca's ~55 ms, whose
# reports' time noise is then averaged over ~5 reports instead of fed back at 0.6 each
INITIAL_LAG_PERIODS = 0.25  # when a command takes effect, until the reports have told
RATE_STEP_H_S = 0.2  # mount seconds between the two samples that give the path's rate
STALE_REPORTS = 12  # reports missed (or STALE_MIN_S, the larger) before the driver counts as lost
STALE_MIN_S = 5.0  # a loaded host (load average 20+ on 2 cores) was seen to leave 3 s without a push
PROBE_RATE_ARCSEC_S = 60.0  # the sign probe: small, a few arcseconds of motion
PROBE_S = 0.4  # wall seconds each axis moves in the probe (at least 2.5 driver periods)
MIN_RATE_CHANGE_ARCSEC_S = 0.05  # a smaller change of rate is not sent
MERIDIAN_LIMIT_DEG = 0.0  # how far past the meridian a German mount may track (hour angle)
RUN_UP_MIN_S = 1.5  # the run-up lasts at least this long ...
RUN_UP_PERIODS = 8  # ... and this many report periods (the loop removes 60 % per period)
SETTLE_PERIODS = 8  # report periods from the join to the landing check
LANDING_REPORTS = 4  # the landing check takes the median of this many last reports
LANDING_GRACE_PERIODS = 12  # ... and may wait this many more periods for them to come within


def gain_per_period(period_s: float) -> float:
    """The fraction of the predicted error removed per report period of `period_s`: GAIN
    per GAIN_PERIOD_S, the same removal in time whatever the report rate (at most GAIN)."""
    return 1.0 - (1.0 - GAIN) ** min(1.0, max(period_s, 1e-3) / GAIN_PERIOD_S)


def run_up_s(period_s: float | None) -> float:
    """How long before the join the loop starts the path's rate (see the module doc)."""
    return max(RUN_UP_MIN_S, RUN_UP_PERIODS * (period_s or 0.25))


def run_up_start(frame: NativeFrame, path: Path, join_us: int,
                 run_up_us: int) -> tuple[float, float]:
    """The native place the run-up starts from (where the goto goes), rad."""
    p = _run_up_points(frame, path, join_us, run_up_us, np.array([join_us - run_up_us]))
    return float(p.az_rad[0]), float(p.el_rad[0])


def _run_up_points(frame: NativeFrame, path: Path, join_us: int, run_up_us: int,
                   t_us: np.ndarray) -> Points:
    """Native demand at `t_us`: the path from the join; before it, the straight run-up line
    at the path's rate at the join for `run_up_us`; before that, at rest at its start."""
    t = np.asarray(t_us, np.int64)
    p = frame.sample(path, np.maximum(t, join_us))
    before = t < join_us
    if not before.any():
        return p
    j = frame.sample(path, np.array([join_us], np.int64))
    dt_s = (np.clip(t, join_us - run_up_us, join_us) - join_us) / 1e6  # ≤ 0
    moving = before & (t >= join_us - run_up_us) if run_up_us else np.zeros_like(before)
    a1 = np.where(before, j.az_rad[0] + j.az_rate_rad_s[0] * dt_s, p.az_rad)
    a2 = np.where(before, j.el_rad[0] + j.el_rate_rad_s[0] * dt_s, p.el_rad)
    r1 = np.where(before, np.where(moving, j.az_rate_rad_s[0], 0.0), p.az_rate_rad_s)
    r2 = np.where(before, np.where(moving, j.el_rate_rad_s[0], 0.0), p.el_rate_rad_s)
    return Points(t, a1, a2, r1, r2)


class NativeFrame:
    """Sample a path in the mount's native axes: (az, el) or (RA, Dec) of date, rad and rad/s."""

    def __init__(self, caps: MountCapabilities, site: Site, eop: EarthOrientation) -> None:
        self.caps = caps
        self.site = site
        self.eop = eop

    def place(self, path: Path, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = path.sample(np.asarray(t_us, np.int64))
        if not self.caps.equatorial:
            return p.az_rad, p.el_rad
        return observed_to_apparent_radec(p.az_rad, p.el_rad, p.t_us, self.site, self.eop)

    def sample(self, path: Path, t_us: np.ndarray) -> Points:
        """Native places at `t_us` and their rates (differences over RATE_STEP_H_S).

        The difference is central, but kept inside the path: a finite path (a pass, or
        the stretch of it on one side of the meridian) stands still outside its ends, and
        a central difference at its start would see half the motion (the run-up, whose
        rate is the path's at the join, ran at half of it on main: a step of ~900″/s at
        the join of an ISS pass that the loop removed only after it)."""
        t = np.asarray(t_us, np.int64)
        h = int(RATE_STEP_H_S * 1e6)
        lo, hi = t - h // 2, t + h // 2
        start = getattr(path, "start_us", None)
        end = getattr(path, "end_us", None)
        if start is not None and end is not None and end - start >= h:
            shift = np.clip(start - lo, 0, None) - np.clip(hi - end, 0, None)
            lo, hi = lo + shift, hi + shift
        a1, a2 = self.place(path, np.concatenate([t, lo, hi]))
        n = len(t)
        d1 = _wrap(a1[2 * n:] - a1[n:2 * n])
        d2 = a2[2 * n:] - a2[n:2 * n]
        return Points(t, a1[:n], a2[:n], d1 / (h / 1e6), d2 / (h / 1e6))

    def observed(self, native: tuple[float, float], t_us: int) -> tuple[float, float]:
        """Observed (az, el) of a native place at a mount time, rad (the VSS's checks)."""
        if not self.caps.equatorial:
            return native
        t = np.array([t_us], np.int64)
        az, el = apparent_radec_to_observed(np.array([native[0]]), np.array([native[1]]), t,
                                            self.site, self.eop)
        return float(az[0]), float(el[0])

    def hour_angle(self, ra_rad: np.ndarray, t_us: np.ndarray) -> np.ndarray:
        return hour_angle_rad(ra_rad, t_us, self.site, self.eop)

    def sky_error_arcsec(self, d1: float, d2: float, axis2_rad: float) -> tuple[float, float]:
        """(first axis × cos second, second axis) errors on the sky, arcsec."""
        return _wrap(d1) * math.cos(axis2_rad) * ARCSEC_PER_RAD, d2 * ARCSEC_PER_RAD


def _wrap(x):
    return (np.asarray(x) + math.pi) % (2 * math.pi) - math.pi if not isinstance(x, float) \
        else (x + math.pi) % (2 * math.pi) - math.pi


@dataclass
class FollowStats:
    """What the rate loop did (the rate-mount counterpart of the feeder's statistics)."""

    reports: int = 0
    commands: int = 0
    skipped: int = 0  # commands not sent: too close to the rates in force
    clipped: int = 0  # commands at the driver's rate limit
    first_point_us: int = 0
    last_point_us: int = 0  # the mount time the last command was meant to last until
    max_report_age_s: float = 0.0
    signs: tuple[float, float] = (1.0, 1.0)
    ended: str = ""
    application_lag_s: float | None = None  # learned: a rate is in force this long after
    # the report it answers
    last_error_arcsec: float | None = None
    last_error_uncertainty_arcsec: float = 0.0
    recent_errors: list[tuple[float, float]] = field(default_factory=list)  # (error, its
    # time's uncertainty × rate) of the last `LANDING_REPORTS` reports, arcsec

    def as_dict(self) -> dict:
        return {"reports": self.reports, "commands": self.commands, "skipped": self.skipped,
                "clipped": self.clipped, "max_report_age_s": self.max_report_age_s,
                "axis_signs": list(self.signs), "ended": self.ended,
                "application_lag_s": self.application_lag_s}


@dataclass(frozen=True)
class RateJoin:
    """Where a rate-driven mount joins a path: the join instant and the path (RampIn's shape)."""

    path: Path
    join_us: int
    begin_us: int

    @property
    def end_us(self) -> int | None:
        return self.path.end_us

    def sample(self, t_us: np.ndarray) -> Points:
        return self.path.sample(t_us)


class RateFollower:
    """Hold a rate-driven mount on a path from `join_us` (see the module doc)."""

    def __init__(self, link, frame: NativeFrame, path: Path, join_us: int, *, errors,
                 gain: float | None = None, note_rates=None, run_up_us: int = 0) -> None:
        self.link = link
        self.frame = frame
        self.path = path
        self.join_us = int(join_us)
        self.run_up_us = int(run_up_us)
        self.errors = errors
        self.gain = gain  # None: `gain_per_period` of the measured report period
        self.note_rates = note_rates
        self.stats = FollowStats(first_point_us=self.join_us)
        self.done = False
        self._rates = (0.0, 0.0)
        self._predictor: RatePredictor | None = None  # created at the first report (its period)
        self._side: float | None = None  # the sign of the hour angle at the join (German)
        # the path's native samples at the newest mount times asked (`_sample_at`)
        self._samples: dict[int, Points] = {}
        caps = link.capabilities
        self.max_rate = math.radians(caps.max_rate_deg_s or 1.0)
        # rates closer than this to those in force are not sent: a star is left to the
        # mount's own tracking (its place of date moves by hundredths of an arcsecond a second)
        step = max(caps.rate_step_arcsec_s or 0.0, MIN_RATE_CHANGE_ARCSEC_S)
        self.deadband = step / ARCSEC_PER_RAD

    # ------------------------------------------------------------------ the loop
    async def run(self) -> None:
        try:
            await self._run()
        finally:
            if hasattr(self.link, "demand"):
                self.link.demand = None

    def _demand(self, t_us: int) -> tuple[float, float]:
        """The path's native place at a mount time (the link's per-report error)."""
        p = self._sample_at(max(t_us, self.join_us))
        return float(p.az_rad[0]), float(p.el_rad[0])

    def _sample_at(self, t_us: int) -> Points:
        """The path's native sample at one mount time, kept for the next few calls: the
        link takes each report's error on arrival (`_demand`) and the loop records the same
        report (`_record`), one astrometric conversion for both. A report's time is past,
        and an offset applies from when it is given on, so a kept sample stays true."""
        p = self._samples.get(t_us)
        if p is None:
            p = self._samples[t_us] = self.frame.sample(self.path, np.array([t_us], np.int64))
            if len(self._samples) > 4:
                del self._samples[next(iter(self._samples))]
        return p

    async def _run(self) -> None:
        if not getattr(self.link, "signs_measured", True):
            await self._probe_signs()
        if hasattr(self.link, "demand"):
            self.link.demand = self._demand
        self.stats.signs = tuple(getattr(self.link, "axis_signs", (1.0, 1.0)))
        last_t = 0
        last_cycle = time.monotonic()
        while not self.done:
            task = asyncio.current_task()
            if task is not None and task.cancelling():
                raise asyncio.CancelledError  # a cancellation swallowed on the way (3.11)
            period = self._period_s()
            stale_s = max(STALE_MIN_S, STALE_REPORTS * period)
            await self.link.wait_report(last_t, stale_s)
            v = await self.link.read(["axis1_position", "axis2_position", "report_time",
                                      "mount_time", "mount_state"])
            t_rep, now = int(v["report_time"]), int(v["mount_time"])
            age_s = (now - t_rep) / 1e6
            self.stats.max_report_age_s = max(self.stats.max_report_age_s, age_s)
            stalled = time.monotonic() - last_cycle > stale_s + 1.0
            last_cycle = time.monotonic()
            if t_rep <= last_t:
                # a report this old while rates are commanded: the driver froze (a host that
                # stalled this loop is not the driver's fault: the next report decides)
                if age_s > stale_s and not stalled:
                    await self._stop(f"no report from the driver for {age_s:.1f} s")
                continue
            last_t = t_rep
            self._check_state(int(v["mount_state"]))
            if self._predictor is None:
                self._predictor = RatePredictor(period, self._gain(period),
                                                INITIAL_LAG_PERIODS * period,
                                                self._rates, _wrap)
            # the report's time uncertainty, read before any await (the same report)
            spread = int(getattr(self.link, "read_spread_us", lambda: 0)())
            self._predictor.reported(t_rep, (float(v["axis1_position"]),
                                             float(v["axis2_position"])), spread)
            self.stats.application_lag_s = self._predictor.lag.lag_s
            started = time.monotonic()
            await self._cycle(float(v["axis1_position"]), float(v["axis2_position"]), t_rep, now,
                              period)
            # at most one command per driver period (a still place is reported at every poll)
            await self._sleep(max(0.0, 0.8 * period - (time.monotonic() - started)))

    def _gain(self, period_s: float) -> float:
        return self.gain if self.gain is not None else gain_per_period(period_s)

    def _period_s(self) -> float:
        stats = getattr(self.link, "stats", None)
        period = stats.period_s() if stats is not None else None
        return period or 0.25

    def _check_state(self, state: int) -> None:
        codes = self.link.mapping.state_codes
        if state == codes["fault"]:
            raise MountFault(f"the mount faulted while following: {self.link.fault_text}")
        if state == codes["off"]:
            raise OperationAborted("the mount was parked outside the VSS while following")

    async def _cycle(self, a1: float, a2: float, t_rep: int, now: int, period_s: float) -> None:
        self._predictor.period_us = int(period_s * 1e6)  # as measured now
        self._predictor.gain = self._gain(period_s)
        end = self.path.end_us
        if t_rep >= self.join_us:
            self._record(a1, a2, t_rep)
        # when this command will be in force (learned), and the next one
        pred = self._predictor
        t_a = pred.effect_us(now)
        if end is not None and t_a >= end:
            await self._set((0.0, 0.0))
            self.done, self.stats.ended = True, "path ended"
            return
        t_b = t_a + pred.period_us
        self._guard_meridian(t_b)

        def path_at(t_us: int) -> np.ndarray:
            # before the run-up the demand is its start (the mount's own tracking holds
            # it), then the run-up line, then the path
            p = _run_up_points(self.frame, self.path, self.join_us, self.run_up_us,
                               np.array([t_us], np.int64))
            return np.array([float(p.az_rad[0]), float(p.el_rad[0])])

        rate, ff, err, _ = pred.command(now, path_at)
        if self.note_rates is not None:
            self.note_rates(_run_up_points(self.frame, self.path, self.join_us, self.run_up_us,
                                           np.array([t_a, t_b], np.int64)))
        self.stats.last_point_us = t_b
        log.debug("rate loop: report %d ±%.1f ms (weight %.2f) now %d lag %.1f ms e=(%.2f, %.2f)″ "
                  "ff=(%.2f, %.2f)″/s cmd=(%.2f, %.2f)″/s", t_rep, pred.spread_us / 1e3,
                  pred.weight(), now, (t_a - t_rep) / 1e3, err[0] * ARCSEC_PER_RAD,
                  err[1] * ARCSEC_PER_RAD, ff[0] * ARCSEC_PER_RAD, ff[1] * ARCSEC_PER_RAD,
                  rate[0] * ARCSEC_PER_RAD, rate[1] * ARCSEC_PER_RAD)
        await self._set((float(rate[0]), float(rate[1])))

    def _record(self, a1: float, a2: float, t_rep: int) -> None:
        d = self._sample_at(t_rep)
        err1, err2 = self.frame.sky_error_arcsec(float(d.az_rad[0]) - a1,
                                                 float(d.el_rad[0]) - a2, a2)
        self.errors.add(np.array([t_rep], np.int64), np.array([err1 / max(math.cos(a2), 1e-9)]),
                        np.array([err2]), np.array([a2]))
        self.stats.reports += 1
        err = math.hypot(err1, err2)
        rate = math.hypot(float(d.az_rate_rad_s[0]) * math.cos(a2), float(d.el_rate_rad_s[0]))
        spread = getattr(self.link, "report_spread_us", lambda: 0)()
        self.stats.last_error_arcsec = err
        self.stats.last_error_uncertainty_arcsec = rate * ARCSEC_PER_RAD * spread / 1e6
        self.stats.recent_errors = (self.stats.recent_errors + [
            (err, self.stats.last_error_uncertainty_arcsec)])[-LANDING_REPORTS:]
        if hasattr(self.link, "last_error_arcsec"):
            self.link.last_error_arcsec = err

    def _guard_meridian(self, t_b: int) -> None:
        """The path's side of the meridian at the join is kept (the run-up before it may
        start on the other side: the goto put the pier where the join needs it)."""
        if self.frame.caps.geometry != "german" or t_b < self.join_us:
            return
        if self._side is None:
            at = np.array([self.join_us], np.int64)
            ha0 = self.frame.hour_angle(self.frame.place(self.path, at)[0], at)
            self._side = 1.0 if ha0[0] >= 0 else -1.0
        at = np.array([t_b], np.int64)
        ha = self.frame.hour_angle(self.frame.place(self.path, at)[0], at)
        limit = math.radians(MERIDIAN_LIMIT_DEG)
        if self._side < 0 and float(ha[-1]) > limit:
            raise TargetUnreachable(
                "the target reaches the meridian: a German mount must flip to follow it "
                "further, which is never done in the middle of a track (slew again to go on "
                "from the other side of the pier)")

    async def _set(self, r: tuple[float, float]) -> None:
        r = (float(np.clip(r[0], -self.max_rate, self.max_rate)),
             float(np.clip(r[1], -self.max_rate, self.max_rate)))
        if abs(r[0]) == self.max_rate or abs(r[1]) == self.max_rate:
            self.stats.clipped += 1
        if abs(r[0] - self._rates[0]) < self.deadband and abs(r[1] - self._rates[1]) < self.deadband:
            self.stats.skipped += 1
            return
        before_us = int((await self.link.read(["report_time"]))["report_time"])
        try:
            await self.link.call("set_rates", r[0], r[1])
        except MountUnavailable as exc:
            try:
                newer = int((await self.link.read(["report_time"]))["report_time"]) > before_us
            except Exception:  # noqa: BLE001 - no report at all: the driver is gone
                newer = False
            if not getattr(exc, "timed_out", False) or not newer:
                # refused or gone, or silent since the command was sent (a killed driver)
                await self._stop(str(exc))
            # one request timed out while the driver still reports (a loaded host): once more
            log.warning("%s: %s; sending the rates once more", self.frame.caps.backend, exc)
            try:
                await self.link.call("set_rates", r[0], r[1])
            except MountUnavailable as again:
                await self._stop(str(again))
        self._rates = r
        self.stats.commands += 1
        if self._predictor is not None:
            self._predictor.sent(r, time.time_ns() // 1000)

    async def _stop(self, why: str) -> None:
        """Tell the mount to stop (it may not listen) and end with a fault."""
        with contextlib.suppress(Exception):
            await self.link.call("stop")
        self.done, self.stats.ended = True, f"fault: {why}"
        raise MountFault(f"the {self.frame.caps.backend} driver stopped answering while the "
                         f"mount was moving at commanded rates ({why}); the mount was told to "
                         "stop, and nothing more is sent")

    async def halt_rates(self) -> None:
        """Zero the rates (the mount's own tracking holds the place): the path stopped early."""
        with contextlib.suppress(Exception):
            await self._set((0.0, 0.0))

    # ------------------------------------------------------------------ signs and checks
    async def _probe_signs(self) -> None:
        """Move each axis at a small rate for two report periods and see which way it went."""
        period = self._period_s()
        rate = PROBE_RATE_ARCSEC_S / ARCSEC_PER_RAD
        signs = [1.0, 1.0]
        self.link.axis_signs = (1.0, 1.0)
        for axis in (0, 1):
            before = await self._fresh_place()
            r = (rate, 0.0) if axis == 0 else (0.0, rate)
            await self.link.call("set_rates", *r)
            await self._sleep(max(2.5 * period, PROBE_S))
            await self.link.call("set_rates", 0.0, 0.0)
            after = await self._fresh_place()
            moved = _wrap(after[axis] - before[axis]) if axis == 0 else after[1] - before[1]
            if abs(moved) * ARCSEC_PER_RAD < 0.2 * PROBE_RATE_ARCSEC_S * PROBE_S:
                raise MountFault(f"the {self.frame.caps.backend} mount did not move its "
                                 f"{('first', 'second')[axis]} axis when told to "
                                 f"({moved * ARCSEC_PER_RAD:.2f}″ in "
                                 f"{max(2.5 * period, PROBE_S):.2f} s)")
            signs[axis] = 1.0 if moved > 0 else -1.0
        self.link.axis_signs = (signs[0], signs[1])
        self.link.signs_measured = True
        log.info("%s mount: axis signs measured %s", self.frame.caps.backend, signs)

    async def _fresh_place(self) -> tuple[float, float]:
        v = await self.link.read(["report_time"])
        await self.link.wait_report(int(v["report_time"]), 3.0)
        await self.link.wait_report(int((await self.link.read(["report_time"]))["report_time"]),
                                    3.0)
        v = await self.link.read(["axis1_position", "axis2_position"])
        return float(v["axis1_position"]), float(v["axis2_position"])

    @staticmethod
    async def _sleep(s: float) -> None:
        await asyncio.sleep(s)

    def settle_s(self, settle_s: float) -> float:
        """How long after the join to verify: `SETTLE_PERIODS` report periods, at least
        `settle_s` (the rate step itself was taken in the run-up)."""
        return max(settle_s, SETTLE_PERIODS * self._period_s())

    async def verify(self, tolerance_arcsec: float, what: str) -> float:
        """The landing error (arcsec): the median of the last `LANDING_REPORTS` reports'
        errors; NotArrived beyond tolerance + their time uncertainty × the path's rate.

        The median, because one report stamped late by a stalled host (a push handled
        20 ms late is 70″ at 1°/s) says nothing about where the mount is. Waits (wall time,
        at most `max(3 s, STALE_REPORTS` periods)) for the first report after the join: on
        a loaded host the sign probe may still be running at the join.
        """
        deadline = time.monotonic() + max(3.0, STALE_REPORTS * self._period_s())
        while self.stats.last_error_arcsec is None and time.monotonic() < deadline \
                and not self.done:
            await self._sleep(0.05)
        if self.stats.last_error_arcsec is None:
            raise NotArrived(f"{what}: no report from the mount since the join", math.inf)
        # a host that stalled the reports for a while (seen: 3 s without an INDI push under
        # load 18) leaves the loop converging at the check: it may take LANDING_GRACE_PERIODS
        # more report periods (at least 3 s) to come within tolerance
        grace = time.monotonic() + max(3.0, LANDING_GRACE_PERIODS * self._period_s())
        while True:
            recent = self.stats.recent_errors
            err = float(np.median([e for e, _u in recent]))
            unc = float(np.median([u for _e, u in recent]))
            allowed = tolerance_arcsec + unc
            if err <= allowed or time.monotonic() > grace or self.done:
                break
            await self._sleep(self._period_s())
        if err > allowed:
            raise NotArrived(f"{what}: the reported place is {err:.1f}″ from the path at the "
                             f"report's time (median of the last {len(recent)} reports; "
                             f"tolerance {tolerance_arcsec:g}″ + {unc:.1f}″ for the report "
                             "time's uncertainty)", err)
        return err
