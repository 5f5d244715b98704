"""A mount driven through a driver's goto and axis rates (ASCOM Alpaca, INDI), spoken in roles.

`RateMountLink` implements the mount-link interface (`link_interface.MountBackend`)
over a `Driver`, the protocol adapter of one driver family (`alpaca.py`, `indi.py`).
It keeps the newest *report* of the driver (position, slewing, tracking, park, pier
side), each stamped with the mount time it describes, and serves the VSS's roles
from it:

* positions: ``az_position``/``el_position`` are the observed place (refraction from
  the site's weather) of the reported right ascension and declination of date;
  ``axis1_position``/``axis2_position`` the native axes themselves (radians);
  ``report_time`` the mount time of the report; ``mount_time`` the host's UTC (a
  driver has no mount clock of its own: mount time is UTC on the host, and a report
  is mapped onto it by when it arrived).
* ``mount_state``: off (parked), slewing (a goto), manual (moving at commanded rates),
  tracking (the mount's own sidereal tracking), holding (verified at rest from two
  reports a driver period apart), fault (the driver stopped answering).
* functions: ``slew`` (a fixed observed place: gotos until the reports land within
  `PLACE_TOLERANCE_ARCSEC`, tracking off so the place holds), ``goto_native`` (a place
  of date, tracking on: the join point of a path), ``set_rates`` (native coordinate
  rates, rad/s), ``stop``/``traj_reset`` (abort, zero rates, tracking off),
  ``power_on`` (unpark), ``power_off`` (park), ``reset_faults``.

The report period is measured, not assumed: the driver is polled (or pushes) faster
than it updates, a change of the reported place marks a new report, and its mount
time is the middle of the interval in which it appeared (`age` and `period` in
`describe()`). A driver that stops answering for `STALE_S` is lost: the link tries to
stop the mount, marks itself lost and reconnects in the background.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import math
import statistics
import time
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import erfa
import numpy as np

from virtualstar.astro import EarthOrientation, Site
from virtualstar.astro.constants import ARCSEC_PER_RAD, SIDEREAL_RATE_ARCSEC_S
from virtualstar.astro.mount_frames import apparent_radec_to_observed, observed_to_apparent_radec

from ..exceptions import MountFault, MountRejected, MountUnavailable
from ..link_interface import ConnectionWaits, MountCapabilities
from ..mapping import STATE_NAMES, RoleMapping
from ..operations import current_operation
from .driver_waits import GotoBudget, SlewRateMeter, axis_travel_deg, within
from .poll_pace import DEMAND_LOOKAHEAD_S, PollPace
from .tick_grid import TickGrid

__all__ = ["Driver", "DriverInfo", "DriverReport", "RateLinkConfig", "RateMountLink"]

T = TypeVar("T")

log = logging.getLogger("virtualstar.server.mount")

STATE_CODES = {name: code for code, name in enumerate(STATE_NAMES)}
PLACE_TOLERANCE_ARCSEC = 2.0  # a fixed place is reached within this (then held, tracking off)
GOTO_TOLERANCE_ARCSEC = 15.0  # a fixed place held by a goto mount is verified within this
REST_TOLERANCE_ARCSEC = 1.0  # two reports this close, a driver period apart: at rest
STALE_S = 3.0  # wall seconds without an answer from the driver: lost
GOTO_ROLES = frozenset({"slew", "goto_place", "goto_native"})  # bounded by their own budget
GOTO_LANDED_DEG = 0.1  # a goto has landed when the reports are this close to its place
REST_WAIT_S = 10.0  # after a stop, wall seconds (plus a few report periods) to see it at rest
CALL_LOG = 4096
_ROLES = ("az_position", "el_position", "axis1_position", "axis2_position", "report_time",
          "report_age", "az_state", "el_state", "az_faults", "el_faults", "mount_state",
          "mount_time", "free_points", "az_error", "el_error", "az_fault_text", "el_fault_text",
          "az_slew_rate_limit", "el_slew_rate_limit", "az_track_rate_limit",
          "el_track_rate_limit", "slewing", "side_of_pier", "axis1_rate", "axis2_rate")
_FUNCTIONS = ("power_on", "power_off", "stop", "slew", "goto_place", "goto_native", "set_rates",
              "traj_reset", "reset_faults")

DEMAND_STILL_ARCSEC = 1.0  # a followed path that moves less than this within
# `DEMAND_LOOKAHEAD_S` is still (a star on an equatorial mount): it leaves the reads at rest
RATE_AT_REST_ARCSEC_S = 1.0  # commanded rates below this move the place < 0.25″ in a rest
# period: a star's fine corrections, not a motion that needs fast reads
ERROR_AT_REST_ARCSEC = 1.0  # a followed path held within this needs no fast reads
DEMAND_CHECK_S = 1.0  # how often (wall s) whether the followed path moves is worked out
PUSH_SILENCE_ARCSEC = 1.0  # a silent pushing driver's last place counts as current while the
# commanded rates could have moved it less than this since it was pushed


async def _seen_through(command: Awaitable[T]) -> T:
    """Await a driver command; cancelled meanwhile, still wait for its answer, then re-raise.

    A command on the wire is applied by the driver whether or not we wait (alpaca-simulators
    runs each request in a thread pool): released at once, the link's lock let a stop's
    commands reach the driver first and the abandoned command (a MoveAxis of the rate loop,
    a goto of a slew the stop cancelled) was applied after them, a runaway after `stop`.
    Held until answered, the lock makes the stop's commands the driver's last. A second
    cancel gives up the wait; the command's outcome is still collected (`_collect`).
    """
    sent = asyncio.ensure_future(command)
    sent.add_done_callback(_collect)
    try:
        return await asyncio.shield(sent)
    except asyncio.CancelledError:
        with contextlib.suppress(Exception):
            await asyncio.shield(sent)
        raise


def _collect(task: asyncio.Future) -> None:
    """Retrieve a finished command's exception, so that one nobody awaited is not reported."""
    if not task.cancelled():
        task.exception()


def _moves_the_place(rates_rad_s) -> bool:
    """Whether commanded rates (rad/s) are a motion that needs fast reads, not a star's fine
    corrections (`RATE_AT_REST_ARCSEC_S`)."""
    return math.hypot(*rates_rad_s) * ARCSEC_PER_RAD > RATE_AT_REST_ARCSEC_S


@dataclass(frozen=True)
class DriverReport:
    """One reading of the driver: the place of date (hours, degrees) and its flags."""

    ra_h: float
    dec_deg: float
    slewing: bool
    tracking: bool
    at_park: bool
    side_of_pier: int = -1  # ASCOM's numbers: 0 east, 1 west, -1 unknown
    received_us: int | None = None  # a pushed report: when it arrived (polled: None)
    answered: bool = False  # pushed in answer to a fresh read (off the driver's tick grid)
    # polled: when the reads of the place left and were answered (µs), if the driver knows;
    # the place was computed inside it (else: the span around the whole read)
    window_us: tuple[int, int] | None = None


@dataclass(frozen=True)
class DriverInfo:
    """What a driver says about itself once connected."""

    name: str
    geometry: str  # "altaz", "german", "fork"
    max_rate_deg_s: float
    rate_step_arcsec_s: float | None
    can_park: bool
    can_pulse_guide: bool
    site: tuple[float, float, float] | None  # lat_deg, lon_deg, height_m, if the driver has one
    slew_rate_deg_s: float | None = None  # the goto speed, when the driver says it


class Driver(Protocol):
    """One driver family's protocol, as `RateMountLink` needs it (all may raise OSError)."""

    url: str
    poll_s: float  # 0: the driver pushes its reports (`wait_report`), else poll this often
    # (a polled driver may say `rest_poll_s`: how often it is read at rest, `poll_pace`)

    async def open(self, site: Site) -> DriverInfo: ...

    async def close(self) -> None: ...

    async def read(self) -> DriverReport: ...

    async def goto_radec(self, ra_h: float, dec_deg: float) -> None: ...

    async def set_rates(self, ra_deg_s: float, dec_deg_s: float) -> None:
        """Move the place of date at these rates (the mount's own tracking included)."""

    async def set_tracking(self, on: bool) -> None: ...

    async def abort(self) -> None: ...

    async def park(self) -> None: ...

    async def unpark(self) -> None: ...


@dataclass(frozen=True)
class RateLinkConfig:
    """Where the driver is and how the VSS treats it."""

    url: str
    site: Site
    eop: EarthOrientation
    timeout_s: float = 2.0
    backoff_min_s: float = 0.2
    backoff_max_s: float = 5.0
    stale_s: float = STALE_S
    accel_deg_s2: float = 5.0  # the drivers say nothing about it: a cautious figure
    goto_budget: GotoBudget = field(default_factory=GotoBudget)  # when a goto is overdue
    rest_wait_s: float = REST_WAIT_S


@dataclass(frozen=True)
class MountCall:
    seq: int
    role: str
    operation: int | None


@dataclass
class _Report:
    """A report as the VSS keeps it: the place, when it describes the mount, and flags."""

    ra_rad: float
    dec_rad: float
    t_us: int  # mount time the place describes (middle of the interval it appeared in)
    read_us: int  # when it was last read
    flags: DriverReport
    spread_us: int = 0  # half the interval it appeared in: the report time's uncertainty
    first_t_us: int = 0  # the mount time it described when it first appeared


@dataclass
class ReportStats:
    """The measured report stream: intervals between new places, request latency."""

    periods_s: deque = field(default_factory=lambda: deque(maxlen=200))
    latency_s: deque = field(default_factory=lambda: deque(maxlen=200))
    reports: int = 0
    reads: int = 0

    def period_s(self) -> float | None:
        return statistics.median(self.periods_s) if len(self.periods_s) >= 3 else None

    def jitter_s(self) -> float:
        """How irregularly new places arrive: the median absolute deviation of the last 20
        intervals from their median (a loaded host handles a push late by this much)."""
        last = list(self.periods_s)[-20:]
        if len(last) < 3:
            return 0.0
        mid = statistics.median(last)
        return statistics.median(abs(x - mid) for x in last)


def _now_us() -> int:
    return time.time_ns() // 1000


class RateMountLink(ConnectionWaits):
    """The mount link over a rate-driven driver (see the module doc)."""

    def __init__(self, driver: Driver, config: RateLinkConfig, *, backend: str,
                 on_event: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self.driver = driver
        self.config = config
        self.backend = backend
        self.on_event = on_event or (lambda kind, data: None)
        self.mapping = RoleMapping({r: r for r in _ROLES}, {f: f for f in _FUNCTIONS},
                                   dict(STATE_CODES), park_az_deg=0.0,
                                   park_el_deg=abs(config.site.lat_deg), source=backend)
        self.info: DriverInfo | None = None
        self.calls: deque[MountCall] = deque(maxlen=CALL_LOG)
        self._call_seq = itertools.count(1)
        self.connects = 0
        self.last_error = ""
        self.fault_text = ""
        self.goto_fault = ""  # a goto that never landed: latched until `reset_faults`
        self.slew_rate = SlewRateMeter()
        self.stats = ReportStats()
        self._ticks = TickGrid()  # a pushing driver's ticks
        self._lock = asyncio.Lock()
        self._connected = asyncio.Event()
        self._changed = asyncio.Condition()
        self._lost = asyncio.Event()
        self._task: asyncio.Task | None = None
        self._report: _Report | None = None
        self._new_report = asyncio.Event()
        self._rates_rad_s = (0.0, 0.0)  # the coordinate rates last commanded
        self._rest: tuple[int, float, float] | None = None  # (t_us, az, el) of a still report
        self._fresh: deque[bool] = deque(maxlen=40)  # did each read of a moving mount move?
        self._at_rest = False
        # a polled driver is read at its `poll_s` while latency matters, else at its
        # `rest_poll_s` (poll_pace.py); a command wakes the poller at once
        self.pace = PollPace(driver.poll_s, getattr(driver, "rest_poll_s", 0.0) or driver.poll_s)
        self._wake = asyncio.Event()
        self._read_fast = True  # the pause before the newest read was the fast one
        self._pause_s = driver.poll_s  # the pause chosen last (`_pause`)
        self._demand_seen: tuple[object, float, bool] = (None, 0.0, False)
        self.last_error_arcsec: float | None = None  # set by the rate loop (status)
        # how each driver axis moves the place of date: measured by the rate loop's first
        # commands (`rate_loop.RateFollower`), kept for the connection
        self.axis_signs = (1.0, 1.0)
        self.signs_measured = False
        self._signs_side: int | None = None  # the pier side the signs were measured on
        # the place the followed path wants at a mount time (native axes, rad), set by the
        # rate loop while it follows: each report's error is taken against it on arrival
        self.demand: Callable[[int], tuple[float, float]] | None = None
        self.report_listeners: list[Callable[[dict[str, Any]], None]] = []

    # ------------------------------------------------------------------ interface
    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    @property
    def capabilities(self) -> MountCapabilities:
        info = self.info
        if info is None:
            return MountCapabilities(backend=self.backend, geometry="german", goto=True,
                                     rate_axes=True)
        return MountCapabilities(
            backend=self.backend, geometry=info.geometry, trajectory_buffer=False,
            rate_axes=True, goto=True, park=info.can_park, guide=True, time_sync=False,
            error_stream=False, max_rate_deg_s=info.max_rate_deg_s,
            rate_step_arcsec_s=info.rate_step_arcsec_s, tracks_sidereal=True,
            goto_tolerance_arcsec=GOTO_TOLERANCE_ARCSEC)

    def describe(self) -> dict[str, Any]:
        rep = self._report
        period = self.stats.period_s()
        out: dict[str, Any] = {
            "backend": self.backend, "url": self.config.url,
            "driver": None if self.info is None else self.info.name,
            "capabilities": self.capabilities.as_dict(),
            "report_period_s": period,
            "report_rate_hz": None if not period else 1.0 / period,
            "poll_period_s": self._pause_s or None,  # the pause the poller is in
            "poll_fast_period_s": self.driver.poll_s or None,
            "poll_rest_period_s": self.pace.rest_s if self.driver.poll_s else None,
            "reads": self.stats.reads,
            "fresh_reads": self.fresh_reads(),
            "request_latency_s": (statistics.median(self.stats.latency_s)
                                  if self.stats.latency_s else None),
            "reports": self.stats.reports,
            "commanded_rates_arcsec_s": [r * ARCSEC_PER_RAD for r in self._rates_rad_s],
            "error_arcsec": self.last_error_arcsec,
            "fault": self.fault_text or None,
            "goto_fault": self.goto_fault or None,
            "measured_slew_rate_deg_s": self.slew_rate.rate_deg_s(),
        }
        if rep is not None:
            out["reported"] = {"ra_deg": math.degrees(rep.ra_rad) % 360.0,
                               "dec_deg": math.degrees(rep.dec_rad),
                               "t_us": rep.t_us, "age_s": (_now_us() - rep.t_us) / 1e6,
                               "time_uncertainty_s": self.report_spread_us() / 1e6,
                               "slewing": rep.flags.slewing, "tracking": rep.flags.tracking,
                               "at_park": rep.flags.at_park,
                               "side_of_pier": {0: "east", 1: "west"}.get(
                                   rep.flags.side_of_pier, "unknown")}
        if self.info is not None and self.info.site is not None:
            lat, lon, h = self.info.site
            s = self.config.site
            out["driver_site"] = {"lat_deg": lat, "lon_deg": lon, "height_m": h}
            out["site_mismatch"] = abs(lat - s.lat_deg) > 1e-3 or abs(
                (lon - s.lon_deg + 180) % 360 - 180) > 1e-3
        return out

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._manage(),
                                                                name=f"{self.backend}-link")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        with contextlib.suppress(Exception):
            await self.driver.close()
        self._connected.clear()

    def mark_lost(self) -> None:
        self._lost.set()

    def scale(self, role: str) -> float:
        return 1.0

    # ------------------------------------------------------------------ connection
    async def _manage(self) -> None:
        delay = self.config.backoff_min_s
        while True:
            try:
                self.info = await within(self.driver.open(self.config.site),
                                         self.config.timeout_s * 5)
                await self._first_report()
                # whatever moved before (a VSS that crashed, a restarted driver): at rest
                await self._halt_driver()
            except (OSError, MountRejected, TimeoutError) as exc:
                self._failed(str(exc) or type(exc).__name__)
                with contextlib.suppress(Exception):
                    await self.driver.close()
                await asyncio.sleep(delay)
                delay = min(2 * delay, self.config.backoff_max_s)
                continue
            delay = self.config.backoff_min_s
            self._lost.clear()
            self.fault_text = self.goto_fault = ""
            self.axis_signs, self.signs_measured = (1.0, 1.0), False
            self.connects += 1
            self._connected.set()
            await self._notify()
            log.info("%s mount connected at %s (%s)", self.backend, self.config.url,
                     self.info.name)
            self.on_event("mount_connected", {"url": self.config.url, "connects": self.connects,
                                              "backend": self.backend})
            poller = asyncio.get_running_loop().create_task(self._poll(), name="rate-mount-poll")
            try:
                done, _ = await asyncio.wait({poller, asyncio.ensure_future(self._lost.wait())},
                                             return_when=asyncio.FIRST_COMPLETED)
            finally:
                poller.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await poller
            reason = self.last_error or "connection lost"
            self.fault_text = f"the driver stopped answering ({reason})"
            # not connected from now on, before the halt: a procedure still running (a goto
            # whose budget runs out while the halt is on the wire) stops at its next
            # `_require` instead of sending its next command after the halt's abort
            self._connected.clear()
            # a command on the wire (its caller holds the lock until it is answered: `_send`),
            # or queued behind it, may be applied by a driver that still takes commands after
            # the halt below, or between its steps, and may be answered before that halt ends
            commanding = self._lock.locked()
            # tell it to stop, should it still listen (a rate once sent keeps the mount moving)
            with contextlib.suppress(Exception):
                await within(self._halt_driver(), self.config.timeout_s)
            if commanding or self._lock.locked():
                # once those commands are answered, halt again, last
                with contextlib.suppress(Exception):
                    async with asyncio.timeout(3 * self.config.timeout_s):
                        async with self._lock:
                            await self._halt_driver()
            await self._notify()
            with contextlib.suppress(Exception):
                await self.driver.close()
            log.warning("%s mount lost: %s", self.backend, reason)
            self.on_event("mount_disconnected", {"url": self.config.url, "reason": reason,
                                                 "backend": self.backend})

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    def _failed(self, reason: str) -> None:
        if reason != self.last_error:
            log.warning("cannot connect to the %s mount at %s: %s", self.backend,
                        self.config.url, reason)
            self.on_event("mount_connect_failed", {"url": self.config.url, "reason": reason})
        self.last_error = reason

    async def _first_report(self) -> None:
        self._report = None
        self._rest = None
        self._at_rest = False
        await self._take(await self._driver_read())

    async def _driver_read(self) -> tuple[DriverReport, int, int]:
        before = _now_us()
        rep = await within(self.driver.read(), self.config.timeout_s)
        after = _now_us()
        if rep.window_us is not None and before <= rep.window_us[0] <= rep.window_us[1] <= after:
            before, after = rep.window_us
        if rep.received_us is not None:
            # pushed: it describes its driver's tick, which it follows by the handling
            # delay (the INDI simulator ticks every 250.5 ± 0.2 ms; its property timestamps
            # have whole seconds only): the tick grid fitted to the arrivals
            before = after = (rep.received_us if rep.answered
                              else self._ticks.add(rep.received_us))
        self.stats.reads += 1
        self.stats.latency_s.append((after - before) / 1e6)
        return rep, before, after

    async def _poll(self) -> None:
        """Read the driver as fast as it updates (or take its pushes) until it stops answering."""
        last_ok = time.monotonic()
        failures = 0
        while True:
            try:
                got = await self._driver_read()
            except (OSError, TimeoutError, MountRejected) as exc:
                failures += 1
                # lost: no answer for `stale_s`, and more than one try (a host that stalled
                # this loop for seconds makes one request time out, not the driver)
                if failures >= 3 and time.monotonic() - last_ok > self.config.stale_s:
                    self.last_error = (f"no answer for {self.config.stale_s:g} s: "
                                       f"{exc or type(exc).__name__}")
                    return
                await asyncio.sleep(0.05)
                continue
            failures = 0
            last_ok = time.monotonic()
            await self._take(got)
            if self.driver.poll_s:
                await self._pause()

    async def _pause(self) -> None:
        """Wait before the next read: the fast period while busy (`_busy`) or lately so,
        else the rest period, cut short by a command (`call` sets `_wake`)."""
        period = self._pause_s = self.pace.period_s(time.monotonic(), self._busy())
        self._read_fast = period <= self.pace.fast_s
        if self._read_fast:
            await asyncio.sleep(period)
            return
        self._wake.clear()
        with contextlib.suppress(TimeoutError):
            await within(self._wake.wait(), period)

    def _busy(self) -> bool:
        """Whether fresh reports matter now: a call in progress (a goto waits on its slew's
        end), the mount moving at commanded rates or slewing, or a followed path that moves
        soon or is not yet held (`poll_pace`). The rate loop's corrections of a star held by
        the mount's own tracking (hundredths of an arcsecond a second, errors of hundredths
        of an arcsecond) are not motion."""
        rep = self._report
        if self._lock.locked() or rep is None:
            return True
        if _moves_the_place(self._rates_rad_s):
            return True
        # an Alpaca driver flags Slewing while any MoveAxis rate is on, however small: a
        # slew is a goto only when no rates are commanded. (Whether the mount is seen at
        # rest is not asked: a stop is a command, read fast for the hold after it, and a
        # mount held with tracking off moves 15″/s in right ascension, so a read a loaded
        # host delayed by 70 ms no longer looks at rest; that judgement goes on at the
        # rest pace.)
        if rep.flags.slewing and self._rates_rad_s == (0.0, 0.0):
            return True
        if self.demand is None:
            return False
        return (self.last_error_arcsec or 0.0) > ERROR_AT_REST_ARCSEC or self._demand_moves()

    def _demand_moves(self) -> bool:
        """Whether the followed path's native place moves by more than `DEMAND_STILL_ARCSEC`
        within `DEMAND_LOOKAHEAD_S` (a satellite, its join near, an offset being taken
        up), worked out at most every `DEMAND_CHECK_S`."""
        demand, checked, moves = self._demand_seen
        now = time.monotonic()
        if demand is self.demand and now - checked < DEMAND_CHECK_S:
            return moves
        t = _now_us()
        try:
            a1, a2 = self.demand(t)
            b1, b2 = self.demand(t + int(DEMAND_LOOKAHEAD_S * 1e6))
            moves = float(erfa.seps(a1, a2, b1, b2)) * ARCSEC_PER_RAD > DEMAND_STILL_ARCSEC
        except Exception:  # noqa: BLE001 - a path that cannot say: treat it as moving
            moves = True
        self._demand_seen = (self.demand, now, moves)
        return moves

    async def _take(self, got: tuple[DriverReport, int, int]) -> None:
        rep, before, after = got
        mid = (before + after) // 2
        ra = math.radians(rep.ra_h * 15.0)
        dec = math.radians(rep.dec_deg)
        old = self._report
        moved = old is None or (ra, dec) != (old.ra_rad, old.dec_rad)
        moving = self._rates_rad_s != (0.0, 0.0) or rep.slewing
        # the driver's period and freshness are measured from fast-paced reads only (a
        # place that moved between reads at rest moved over the rest period, `poll_pace`)
        paced = self._read_fast or not self.driver.poll_s
        if moving and paced:
            self._fresh.append(moved)
        if moved:
            if old is None or self.fresh_reads() or rep.received_us is not None:
                # the driver answers with where the mount is when asked
                t_us, spread = mid, (after - before) // 2
            else:
                # a new place appeared between the previous reading and this one
                t_us, spread = (old.read_us + mid) // 2, (mid - old.read_us) // 2
            if old is not None and old.t_us < t_us and paced:
                self.stats.periods_s.append((t_us - old.t_us) / 1e6)
            self._report = _Report(ra, dec, t_us, mid, rep, spread, t_us)
            self.stats.reports += 1
            self._new_report.set()
            self._new_report = asyncio.Event()
            self._tell(self._report, after - before if rep.received_us is None else 0)
        else:
            old.read_us = mid
            old.flags = rep
            still = self._rates_rad_s == (0.0, 0.0) and (rep.tracking or rep.at_park)
            # a pushing driver pushes a place only when it has changed enough (the INDI
            # simulator: a few tenths of an arcsecond): at a tiny commanded rate its silence
            # means it moved less than `PUSH_SILENCE_ARCSEC` since its last push
            drift = math.hypot(*self._rates_rad_s) * (mid - old.first_t_us) / 1e6
            quiet = (not self.driver.poll_s and rep.tracking
                     and drift * ARCSEC_PER_RAD < PUSH_SILENCE_ARCSEC)
            if still or quiet:
                # a place that stands still on the sky describes now as well (with tracking
                # off the place of date moves: a silent driver's report is then just old)
                old.t_us, old.spread_us = mid, 0
                self._new_report.set()
                self._new_report = asyncio.Event()
                self._tell(old, after - before if rep.received_us is None else 0)
        self._update_rest()

    def _tell(self, rep: _Report, latency_us: int) -> None:
        """Hand a new report to the listeners (the recorder's signals), with its error."""
        if not self.report_listeners:
            return
        az, el = self._observed(rep.ra_rad, rep.dec_rad, rep.t_us)
        row: dict[str, Any] = {
            "t_us": rep.t_us, "report.ra_deg": math.degrees(rep.ra_rad) % 360.0,
            "report.dec_deg": math.degrees(rep.dec_rad), "report.az_deg": math.degrees(az),
            "report.el_deg": math.degrees(el), "report.age_s": latency_us / 2e6,
            "report.time_uncertainty_s": rep.spread_us / 1e6,
            "rate.axis1_arcsec_s": self._rates_rad_s[0] * ARCSEC_PER_RAD,
            "rate.axis2_arcsec_s": self._rates_rad_s[1] * ARCSEC_PER_RAD}
        if self.demand is not None:
            d1, d2 = self.demand(rep.t_us)
            e1 = ((d1 - rep.ra_rad + math.pi) % (2 * math.pi) - math.pi) * math.cos(rep.dec_rad)
            e2 = d2 - rep.dec_rad
            row.update({"error.axis1_arcsec": e1 * ARCSEC_PER_RAD,
                        "error.axis2_arcsec": e2 * ARCSEC_PER_RAD,
                        "error.sky_arcsec": math.hypot(e1, e2) * ARCSEC_PER_RAD})
        for listener in self.report_listeners:
            try:
                listener(row)
            except Exception:  # a listener never breaks the link
                log.exception("report listener failed")

    def fresh_reads(self) -> bool:
        """Measured: nearly every read of a moving mount gave a new place (the driver answers
        with the place at the request, not at an update of its own)."""
        return len(self._fresh) >= 10 and sum(self._fresh) >= 0.9 * len(self._fresh)

    def _update_rest(self) -> None:
        """At rest: not slewing, no rates, and the observed place still over a driver period."""
        rep = self._report
        if rep is None:
            return
        f = rep.flags
        if f.slewing or f.tracking or self._rates_rad_s != (0.0, 0.0):
            self._rest, self._at_rest = None, False
            return
        az, el = self._observed(rep.ra_rad, rep.dec_rad, rep.read_us)
        period_us = int((self.stats.period_s() or 0.25) * 1e6)
        if self._rest is None:
            self._rest = (rep.read_us, az, el)
            return
        t0, az0, el0 = self._rest
        moved = math.hypot((az - az0) * math.cos(el), el - el0) * ARCSEC_PER_RAD
        if moved > REST_TOLERANCE_ARCSEC:
            self._rest, self._at_rest = (rep.read_us, az, el), False
        elif rep.read_us - t0 >= period_us:
            self._at_rest = True

    def _observed(self, ra_rad: float, dec_rad: float, t_us: int) -> tuple[float, float]:
        az, el = apparent_radec_to_observed(np.array([ra_rad]), np.array([dec_rad]),
                                            np.array([t_us], np.int64), self.config.site,
                                            self.config.eop)
        return float(az[0]), float(el[0])

    # ------------------------------------------------------------------ roles
    def _require(self) -> _Report:
        if not self.connected or self._report is None:
            raise MountUnavailable(f"the {self.backend} mount at {self.config.url} is not "
                                   f"connected ({self.last_error or 'connecting'}); the server "
                                   "keeps retrying")
        return self._report

    def state_name(self) -> str:
        rep = self._report
        if self.goto_fault or (self.fault_text and not self.connected):
            return "fault"
        if rep is None:
            return "off"
        f = rep.flags
        if f.at_park:
            return "off"
        if self._rates_rad_s != (0.0, 0.0):
            return "manual"
        if f.slewing:
            return "slewing"
        if f.tracking:
            return "tracking"
        return "holding" if self._at_rest else "stopping"

    async def read(self, roles: Sequence[str]) -> dict[str, Any]:
        """Serve roles from the newest report (no request to the driver)."""
        rep = self._require()
        out: dict[str, Any] = {}
        observed = None
        info = self.info
        max_rate = math.radians(info.max_rate_deg_s if info else 1.0)
        state = STATE_CODES[self.state_name()]
        for role in roles:
            if role in ("az_position", "el_position"):
                if observed is None:
                    observed = self._observed(rep.ra_rad, rep.dec_rad, rep.t_us)
                out[role] = observed[0] if role == "az_position" else observed[1]
            elif role == "axis1_position":
                out[role] = rep.ra_rad
            elif role == "axis2_position":
                out[role] = rep.dec_rad
            elif role == "report_time":
                out[role] = rep.t_us
            elif role == "report_age":
                out[role] = (_now_us() - rep.t_us) / 1e6
            elif role == "mount_time":
                out[role] = _now_us()
            elif role == "mount_state":
                out[role] = state
            elif role in ("az_state", "el_state"):
                out[role] = STATE_CODES["off"] if rep.flags.at_park else STATE_CODES["holding"]
            elif role in ("az_faults", "el_faults"):
                out[role] = 0
            elif role in ("az_fault_text", "el_fault_text"):
                out[role] = self.fault_text
            elif role == "free_points":
                out[role] = 0
            elif role in ("az_error", "el_error"):
                out[role] = 0.0
            elif role in ("az_slew_rate_limit", "el_slew_rate_limit", "az_track_rate_limit",
                          "el_track_rate_limit"):
                out[role] = max_rate
            elif role == "slewing":
                out[role] = rep.flags.slewing
            elif role == "side_of_pier":
                out[role] = rep.flags.side_of_pier
            elif role in ("axis1_rate", "axis2_rate"):
                out[role] = self._rates_rad_s[0 if role == "axis1_rate" else 1]
            else:
                raise MountRejected(f"the {self.backend} mount has no {role!r}")
        return out

    async def wait_report(self, after_us: int, timeout_s: float) -> None:
        """Wait (wall time) for a report newer than `after_us`."""
        deadline = time.monotonic() + timeout_s
        while self._report is None or self._report.t_us <= after_us:
            left = deadline - time.monotonic()
            if left <= 0 or not self.connected:
                return
            # asyncio.wait, not wait_for: Python 3.11's wait_for can swallow a cancellation
            # that arrives as the event is set (set at every read of a quiet driver), and
            # the rate loop waiting here would outlive its operation
            waiter = asyncio.ensure_future(self._new_report.wait())
            try:
                await asyncio.wait({waiter}, timeout=left)
            finally:
                waiter.cancel()

    def read_spread_us(self) -> int:
        """How well a *polled* report's time is known: half the read it came in (0 for a
        push, whose time is its driver's tick, `TickGrid`). The rate loop weighs each
        report's correction by it (`RatePredictor.weight`)."""
        rep = self._report
        if rep is None or rep.flags.received_us is not None:
            return 0
        return rep.spread_us

    def report_spread_us(self) -> int:
        """The uncertainty of the newest report's time: half the interval it appeared in
        (polled), or for a push the jitter of the pushes' arrival (its handling delay)."""
        if self._report is None:
            return 0
        if self._report.flags.received_us is not None:
            return max(self._report.spread_us, int(self.stats.jitter_s() * 1e6))
        return self._report.spread_us

    async def call(self, role: str, *args: Any) -> Any:
        self.calls.append(MountCall(next(self._call_seq), role, current_operation.get()))
        self._require()
        if role != "set_rates" or _moves_the_place(args[:2]):
            # reads fast from now on, at once (a star's fine corrections excepted: `_busy`)
            self.pace.commanded(time.monotonic())
            self._wake.set()
        fn = getattr(self, f"_do_{role}", None)
        if fn is None:
            raise MountRejected(f"the {self.backend} mount cannot do {role!r}: it has no "
                                "trajectory buffer (capabilities: rate axes and goto)")
        async with self._lock:
            try:
                if role in GOTO_ROLES:  # bounded by their goto budget, then a fault
                    return await fn(*args)
                # each driver command in it is seen through if the caller is cancelled (`_send`)
                return await within(fn(*args), self.config.timeout_s * 30)
            except (OSError, TimeoutError) as exc:
                self.last_error = f"{role}: {exc or type(exc).__name__}"
                err = MountUnavailable(f"the {self.backend} driver did not answer {role}: "
                                       f"{exc or type(exc).__name__}")
                # slow (a loaded host), not gone: the caller may try once more
                err.timed_out = isinstance(exc, TimeoutError) and self.connected
                raise err from None

    async def _send(self, coro) -> None:
        await _seen_through(within(coro, self.config.timeout_s))

    async def _halt_driver(self) -> None:
        """Abort a goto, zero the rates, tracking off (a parked mount refuses them: it is at rest)."""
        self._rates_rad_s = (0.0, 0.0)
        for step in (self.driver.abort, lambda: self.driver.set_rates(0.0, 0.0),
                     lambda: self.driver.set_tracking(False)):
            with contextlib.suppress(MountRejected):
                await self._send(step())
        self._rest, self._at_rest = None, False

    async def _do_stop(self) -> None:
        await self._halt_driver()

    async def _do_traj_reset(self) -> None:
        await self._halt_driver()

    async def _do_reset_faults(self) -> None:
        self.fault_text = self.goto_fault = ""

    async def _do_power_on(self) -> None:
        if self._report is not None and self._report.flags.at_park:
            await self._send(self.driver.unpark())
            await self._send(self.driver.set_tracking(False))

    async def _do_power_off(self) -> None:
        await self._halt_driver()
        await self._send(self.driver.park())

    async def _do_set_rates(self, axis1_rad_s: float, axis2_rad_s: float) -> None:
        """Move the place of date at these coordinate rates (rad/s) beside sidereal tracking."""
        max_rate = math.radians(self.info.max_rate_deg_s) if self.info else 0.0
        a1 = float(np.clip(axis1_rad_s, -max_rate, max_rate))
        a2 = float(np.clip(axis2_rad_s, -max_rate, max_rate))
        if self._report is not None and not self._report.flags.tracking:
            await self._send(self.driver.set_tracking(True))
        s1, s2 = self.axis_signs
        await self._send(self.driver.set_rates(s1 * math.degrees(a1), s2 * math.degrees(a2)))
        self._rates_rad_s = (a1, a2)

    async def _do_goto_native(self, ra_rad: float, dec_rad: float) -> None:
        """Goto a place of date and hold it there with the mount's tracking (a join point).

        A German mount may land on the other side of its pier, where its declination axis
        turns the other way: the axis signs are then measured again.
        """
        self._rates_rad_s = (0.0, 0.0)
        await self._send(self.driver.set_rates(0.0, 0.0))
        await self._send(self.driver.set_tracking(True))
        await self._goto_and_wait(ra_rad, dec_rad)
        side = self._require().flags.side_of_pier
        if side != self._signs_side or side not in (0, 1):
            self.signs_measured = False
        self._signs_side = side

    async def _do_goto_place(self, az_deg: float, el_deg: float) -> None:
        """One goto to a fixed observed place (a waypoint round a zone), tracking off: it
        has landed only when the reports show that place (`_goto_once`), the next leg's way
        being planned from it."""
        await self._do_slew(az_deg, el_deg, attempts=1)

    async def _do_slew(self, az_deg: float, el_deg: float, attempts: int = 3) -> None:
        """Go to a fixed observed place and stay there (tracking off): gotos to where that
        place is on the sky when the mount lands, until the reports agree within
        `PLACE_TOLERANCE_ARCSEC` or a goto no longer gets closer (the driver's accuracy)."""
        self._rates_rad_s = (0.0, 0.0)
        await self._send(self.driver.set_rates(0.0, 0.0))
        await self._send(self.driver.set_tracking(False))
        az, el = math.radians(az_deg % 360.0), math.radians(el_deg)
        speed = math.radians((self.info.slew_rate_deg_s if self.info else None) or 5.0)
        last = math.inf
        for _attempt in range(attempts):
            rep = self._require()
            here_az, here_el = self._observed(rep.ra_rad, rep.dec_rad, _now_us())
            dist = float(erfa.seps(az, el, here_az, here_el))
            if dist * ARCSEC_PER_RAD <= PLACE_TOLERANCE_ARCSEC or dist >= 0.7 * last:
                break
            last = dist
            land_us = _now_us() + int((dist / speed + 2 * (self.stats.period_s() or 0.25)) * 1e6)
            ra, dec = observed_to_apparent_radec(np.array([az]), np.array([el]),
                                                 np.array([land_us], np.int64),
                                                 self.config.site, self.config.eop)
            await self._goto_and_wait(float(ra[0]), float(dec[0]))
            await self._send(self.driver.set_tracking(False))
            await self.wait_report(_now_us(), 2.0)
        self._rest, self._at_rest = None, False

    async def _goto_and_wait(self, ra_rad: float, dec_rad: float) -> None:
        """Goto a place of date and wait until the driver says it landed, within a bound.

        A goto overdue by its budget (`driver_waits.GotoBudget`: the axis travel at the
        measured slew rate, doubled, plus a margin) is aborted and sent once more; overdue
        again, the mount is told to stop, its rest is checked from its reported places, and
        the link latches a fault (`goto_fault`, state ``fault`` until ``reset_faults``)
        that ends the operation with `MountFault`.
        """
        overdue = []
        for attempt in (1, 2):
            bound_s = await self._goto_once(ra_rad, dec_rad)
            if bound_s is None:
                return
            overdue.append(bound_s)
            log.warning("%s goto to RA %.4f h Dec %.4f° did not land within %.1f s "
                        "(attempt %d): aborting it", self.backend,
                        math.degrees(ra_rad) % 360.0 / 15.0, math.degrees(dec_rad), bound_s,
                        attempt)
            with contextlib.suppress(MountRejected):
                await self._send(self.driver.abort())
        await self._goto_fault(ra_rad, dec_rad, overdue)

    async def _goto_once(self, ra_rad: float, dec_rad: float) -> float | None:
        """One goto; None when it landed, else the budget (s) it overran."""
        ra_h = math.degrees(ra_rad) % 360.0 / 15.0
        rep = self._require()
        direct, worst = axis_travel_deg(math.degrees(rep.ra_rad) / 15.0,
                                        math.degrees(rep.dec_rad), ra_h, math.degrees(dec_rad),
                                        self.info.geometry if self.info else "german")
        bound_s = self.config.goto_budget.bound_s(
            worst, measured_deg_s=self.slew_rate.rate_deg_s(),
            declared_deg_s=self.info.slew_rate_deg_s if self.info else None,
            period_s=self.stats.period_s())
        await self._send(self.driver.goto_radec(ra_h, math.degrees(dec_rad)))
        self._rest, self._at_rest = None, False
        sent = _now_us()
        deadline = time.monotonic() + bound_s
        # a driver that flags the goto a little later than it accepted it: see it start first
        await self.wait_report(sent, min(1.0, bound_s))
        while True:
            rep = self._require()
            # landed: the driver says it no longer slews *and* reports the place it was sent
            # to (a driver may flag the end early, or not yet have flagged the start: the
            # INDI simulator's star goto was taken as landed 4.6° short, and the rate loop
            # then measured its axis signs on a moving mount)
            if (not rep.flags.slewing and rep.read_us > sent
                    and math.degrees(erfa.seps(rep.ra_rad, rep.dec_rad, ra_rad, dec_rad))
                    <= GOTO_LANDED_DEG):
                self.slew_rate.landed(direct, (rep.read_us - sent) / 1e6)
                return None
            if time.monotonic() > deadline:
                return bound_s
            await asyncio.sleep(max(self.driver.poll_s, 0.02))

    async def _goto_fault(self, ra_rad: float, dec_rad: float, overdue: list[float]) -> None:
        """Stop the mount, check it came to rest, latch the fault and end the operation."""
        await self._halt_driver()
        still = await self._wait_still(self.config.rest_wait_s
                                       + 4 * (self.stats.period_s() or 0.25))
        rep = self._report
        flag = " (the driver still flags a slew)" if rep is not None and rep.flags.slewing else ""
        rest = ("it is at rest" + flag if still else
                "its reported place was still moving: check the mount")
        text = (f"the {self.backend} goto to RA {math.degrees(ra_rad) % 360.0 / 15.0:.4f} h "
                f"Dec {math.degrees(dec_rad):.4f}° did not land within "
                f"{' s, then '.join(f'{b:.1f}' for b in overdue)} s (aborted, sent again, "
                f"aborted); the mount was told to stop and {rest}. Reset the fault to go on "
                "(vs stop --reset-faults)")
        self._latch_fault(text, at_rest=still)

    def _latch_fault(self, text: str, **data: Any) -> None:
        """Latch a goto fault (state ``fault`` until ``reset_faults``), log it, tell the
        server (its event log, its clients) and end the operation with `MountFault`."""
        self.goto_fault = self.fault_text = text
        log.error("%s", text)
        self.on_event("fault", {"state": "fault", "faults": text, "backend": self.backend,
                                **data})
        raise MountFault(text)

    async def _wait_still(self, timeout_s: float) -> bool:
        """Wait until the reported place stands still (the observed place, within
        `REST_TOLERANCE_ARCSEC`) over a report period or more: judged from the places alone,
        since a driver whose goto never ended may flag a slew whatever it does."""
        deadline = time.monotonic() + timeout_s
        first: tuple[int, float, float] | None = None
        while time.monotonic() < deadline:
            rep = self._report
            if rep is not None:
                az, el = self._observed(rep.ra_rad, rep.dec_rad, rep.read_us)
                period_us = int((self.stats.period_s() or 0.25) * 1e6)
                if first is None:
                    first = (rep.read_us, az, el)
                else:
                    t0, az0, el0 = first
                    moved = math.hypot((az - az0) * math.cos(el), el - el0) * ARCSEC_PER_RAD
                    if moved > REST_TOLERANCE_ARCSEC:
                        first = (rep.read_us, az, el)
                    elif rep.read_us - t0 >= period_us:
                        return True
            await asyncio.sleep(max(self.driver.poll_s, 0.02))
        return False


def sidereal_rate_rad_s() -> float:
    """The sky's turn, radians per second (for drivers whose rates include it)."""
    return SIDEREAL_RATE_ARCSEC_S / ARCSEC_PER_RAD
