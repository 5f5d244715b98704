"""Bounded driver waits: the cause of the Alpaca sky scenario's hang, and the goto bound.

The link (`RateMountLink`) runs for real over `SimGotoDriver`, a small goto mount written
here (a slew moves RA and Dec linearly at its rate, as the Alpaca simulator's does) with
the faults a real driver shows: a Slewing flag that never clears, a read that completes
at the very moment the link is being stopped.
"""

from __future__ import annotations

import asyncio
import math
import re
import time

import erfa
import pytest

from virtualstar.astro import EarthOrientation, Site
from virtualstar.server.backends.driver_waits import (
    GotoBudget,
    SlewRateMeter,
    axis_travel_deg,
    within,
)
from virtualstar.server.backends.rate_mount import (
    DriverInfo,
    DriverReport,
    RateLinkConfig,
    RateMountLink,
)
from virtualstar.server.exceptions import MountFault, MountUnavailable

HANG_GUARD_S = 60.0  # a hang guard, not a speed bound: the bounds under test are seconds


class SimGotoDriver:
    """A goto mount on the host clock: gotos move RA/Dec linearly at `rate_deg_s`."""

    poll_s = 0.02

    def __init__(self, *, rate_deg_s: float = 40.0, stuck: bool = False,
                 stuck_after_abort: bool = False, geometry: str = "fork") -> None:
        self.url = "sim://goto"
        self.geometry = geometry
        self.rate_deg_s = rate_deg_s
        self.stuck = stuck  # a goto reaches its place but the driver never clears Slewing
        self.stuck_after_abort = stuck_after_abort  # ... not even after an abort
        self.drop_gotos = 0  # this many gotos are accepted and dropped (the mount stays)
        self.early_idle_s = 0.0  # a goto is not flagged as a slew for its first seconds
        self._goto_at = 0.0
        self.ra_h, self.dec_deg = 6.0, 10.0
        self.target: tuple[float, float] | None = None
        self.slewing = False
        self.tracking = False
        self.rates = (0.0, 0.0)
        self.calls: list[str] = []
        self.gate: asyncio.Future | None = None  # a read waits on it when set
        self.silent = False  # reads fail (a network gone) while set
        self.held: asyncio.Future | None = None  # a held command is applied once it is done
        self._t = time.monotonic()

    def _advance(self) -> None:
        now = time.monotonic()
        dt, self._t = now - self._t, now
        if self.target is not None:
            d_ra = ((self.target[0] - self.ra_h) * 15.0 + 180.0) % 360.0 - 180.0
            d_dec = self.target[1] - self.dec_deg
            dist = math.hypot(d_ra, d_dec)
            step = self.rate_deg_s * dt
            if dist <= step:
                self.ra_h, self.dec_deg = self.target
                self.target = None
                self.slewing = self.stuck
            else:
                self.ra_h = (self.ra_h + step / dist * d_ra / 15.0) % 24.0
                self.dec_deg += step / dist * d_dec
            return
        sidereal_h_s = 24.0 / 86164.0905
        self.ra_h = (self.ra_h + dt * ((0.0 if self.tracking else sidereal_h_s)
                                       + self.rates[0] / 15.0)) % 24.0
        self.dec_deg += dt * self.rates[1]

    async def open(self, site: Site) -> DriverInfo:
        return DriverInfo(name="sim", geometry=self.geometry, max_rate_deg_s=5.0,
                          rate_step_arcsec_s=None, can_park=False, can_pulse_guide=False,
                          site=None, slew_rate_deg_s=self.rate_deg_s)

    async def close(self) -> None:
        pass

    async def read(self) -> DriverReport:
        if self.silent:
            raise OSError("no route to host")
        if self.gate is not None:
            await self.gate
        await asyncio.sleep(0)
        self._advance()
        slewing = self.slewing and time.monotonic() - self._goto_at >= self.early_idle_s
        return DriverReport(self.ra_h, self.dec_deg, slewing, self.tracking, False, 1)

    async def goto_radec(self, ra_h: float, dec_deg: float) -> None:
        self._advance()
        self.calls.append("goto")
        if self.drop_gotos:
            self.drop_gotos -= 1
            return
        self.target, self.slewing = (ra_h, dec_deg), True
        self._goto_at = time.monotonic()

    async def set_rates(self, ra_deg_s: float, dec_deg_s: float) -> None:
        self._advance()
        self.calls.append(f"rates {ra_deg_s:g} {dec_deg_s:g}")
        self.rates = (ra_deg_s, dec_deg_s)

    async def set_tracking(self, on: bool) -> None:
        self._advance()
        self.calls.append(f"tracking {on}")
        self.tracking = on

    async def abort(self) -> None:
        self._advance()
        self.calls.append("abort")
        self.target = None
        self.slewing = self.stuck_after_abort

    async def _hold(self, sent: str) -> None:
        """A command taken off the wire (`sent` in the calls) waits for `held`, if set, before
        it is applied: applied by the driver even if the VSS gives up on it."""
        if self.held is not None:
            self.calls.append(sent)
            await asyncio.shield(self.held)

    async def park(self) -> None:
        pass

    async def unpark(self) -> None:
        pass


SITE = Site(lat_deg=-30.0, lon_deg=70.0, height_m=1500.0)


@pytest.fixture(scope="module")
def eop() -> EarthOrientation:
    return EarthOrientation.from_astropy_iers_data()


def _link(driver, eop, **config) -> RateMountLink:
    return RateMountLink(driver, RateLinkConfig(driver.url, SITE, eop, **config), backend="sim")


# ---------------------------------------------------------------------- the cause of the hang
async def _poll_with_wait_for(read, stop_reads: list) -> None:
    """The poll loop as it was: each read through `asyncio.wait_for`."""
    while True:
        stop_reads.append(await asyncio.wait_for(read(), 2.0))
        await asyncio.sleep(0.01)


async def _cancel_as_read_lands(poll_factory) -> bool:
    """Start a poll loop blocked in a read, let the read complete and cancel the loop in the
    same loop iteration (what `RateMountLink.stop` does to its poller while a report comes
    in); return whether the loop ended."""
    gate = asyncio.get_running_loop().create_future()

    async def read():
        await gate
        return 1

    reads: list = []
    poller = asyncio.ensure_future(poll_factory(read, reads))
    for _ in range(5):
        await asyncio.sleep(0)  # the poller is now waiting inside its read
    gate.set_result(None)  # the driver's answer arrives ...
    await asyncio.sleep(0)  # ... the read finishes, its waiter is not woken yet
    poller.cancel()  # ... and the link is stopped in that iteration
    done, _ = await asyncio.wait({poller}, timeout=1.0)
    if not done:
        poller.cancel()  # the second cancel lands in the sleep: clean up
        await asyncio.wait({poller}, timeout=1.0)
    return bool(done)


async def _poll_with_within(read, stop_reads: list) -> None:
    while True:
        stop_reads.append(await within(read(), 2.0))
        await asyncio.sleep(0.01)


def test_python311_wait_for_drops_a_cancel_that_meets_a_finished_read():
    """The hang's mechanism, reproduced deterministically: with `asyncio.wait_for` the
    cancellation is swallowed and the poll loop runs on (the VSS polled the simulator for
    12 minutes after the test closed it); with `driver_waits.within` it ends."""
    import sys

    async def main():
        return await _cancel_as_read_lands(_poll_with_wait_for), \
            await _cancel_as_read_lands(_poll_with_within)

    ended_wait_for, ended_within = asyncio.run(main())
    if sys.version_info < (3, 12):
        assert not ended_wait_for  # the defect this module works round (CPython gh-86296)
    assert ended_within


def test_stopping_the_link_while_a_report_lands_ends_the_link(eop):
    """`RateMountLink.stop` cancels its poller; done at the moment a driver read completes
    it must still end (before the fix: awaited forever, the scenario's 720-s hang)."""
    async def main():
        driver = SimGotoDriver()
        link = _link(driver, eop)
        link.start()
        await link.wait_connected(10)
        ended = 0
        for k in range(20):
            driver.gate = asyncio.get_running_loop().create_future()
            await asyncio.sleep(0.05)  # the poller now waits in a read
            for _ in range(k % 4):
                await asyncio.sleep(0)
            driver.gate.set_result(None)
            driver.gate = None
            await asyncio.sleep(0)
            stopping = asyncio.ensure_future(link.stop())
            done, _ = await asyncio.wait({stopping}, timeout=HANG_GUARD_S / 10)
            assert done, f"link.stop() did not end (round {k})"
            ended += 1
            link.start()
            await link.wait_connected(10)
        await link.stop()
        return ended

    assert asyncio.run(main()) == 20


# ---------------------------------------------------------------------- the goto bound
def test_a_goto_that_never_lands_is_aborted_retried_then_a_fault_with_the_mount_stopped(eop):
    async def main():
        driver = SimGotoDriver(stuck=True)
        link = _link(driver, eop, goto_budget=GotoBudget(margin_s=0.5, report_periods=2),
                     rest_wait_s=2.0)
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        driver.calls.clear()
        t0 = time.monotonic()
        with pytest.raises(MountFault) as err:
            await asyncio.wait_for(link.call("goto_native", math.radians(7.0 * 15),
                                             math.radians(20.0)), HANG_GUARD_S)
        waited = time.monotonic() - t0
        status = link.describe()
        state = link.state_name()
        read = await link.read(["mount_state", "az_fault_text"])
        await link.stop()
        return driver, err.value, waited, status, state, read

    driver, err, waited, status, state, read = asyncio.run(main())
    # the goto was sent, overdue, aborted, sent once more, overdue, then the mount stopped
    gotos = [k for k, c in enumerate(driver.calls) if c == "goto"]
    aborts = [k for k, c in enumerate(driver.calls) if c == "abort"]
    assert len(gotos) == 2 and len(aborts) == 3
    assert gotos[0] < aborts[0] < gotos[1] < aborts[1] < aborts[2]
    after = driver.calls[aborts[2]:]
    assert "rates 0 0" in after and "tracking False" in after
    assert driver.rates == (0.0, 0.0) and not driver.tracking and driver.target is None
    # each wait was its budget: 15° of RA (the larger axis turn of a fork) at the 40°/s
    # the driver declares (none measured yet), doubled, plus the margin and two report
    # periods; the second goto starts where the first left the mount (at the place)
    travel, _ = axis_travel_deg(6.0, 10.0, 7.0, 20.0, "fork")
    assert travel == pytest.approx(15.0, abs=0.01)
    found = re.search(r"did not land within ([0-9.]+) s, then ([0-9.]+) s", str(err))
    assert found, str(err)
    first, second = float(found[1]), float(found[2])
    assert 2 * travel / 40.0 + 0.5 <= first + 0.05 <= 2 * travel / 40.0 + 0.5 + 2 * 0.25 + 0.1
    assert 0.5 <= second + 0.05 < first
    assert waited >= 0.9 * (first + second)  # it did wait out both budgets
    assert "it is at rest" in str(err)
    assert state == "fault" and status["goto_fault"] == str(err) and status["fault"]
    assert read["az_fault_text"] == str(err)


def test_a_driver_that_flags_a_slew_even_after_the_abort_is_judged_at_rest_by_its_places(eop):
    async def main():
        driver = SimGotoDriver(stuck=True, stuck_after_abort=True)
        link = _link(driver, eop, goto_budget=GotoBudget(margin_s=0.3, report_periods=1),
                     rest_wait_s=2.0)
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        with pytest.raises(MountFault) as err:
            await asyncio.wait_for(link.call("slew", 120.0, 40.0), HANG_GUARD_S)
        after_reset_state = None
        await link.call("reset_faults")
        after_reset_state = link.state_name()
        await link.stop()
        return str(err.value), after_reset_state

    text, after_reset = asyncio.run(main())
    assert "still flags a slew" in text and "it is at rest" in text
    assert after_reset != "fault"


def test_a_goto_that_lands_is_not_cut_short_and_teaches_the_link_the_slew_rate(eop):
    async def main():
        driver = SimGotoDriver(rate_deg_s=40.0)
        link = _link(driver, eop, goto_budget=GotoBudget(margin_s=5.0))
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        driver.calls.clear()  # the halt on connecting
        await asyncio.wait_for(link.call("goto_native", math.radians(8.0 * 15),
                                         math.radians(-20.0)), HANG_GUARD_S)
        rate = link.slew_rate.rate_deg_s()
        await link.stop()
        return driver, rate, link

    driver, rate, link = asyncio.run(main())
    assert driver.calls.count("goto") == 1 and "abort" not in driver.calls
    assert abs(driver.ra_h - 8.0) < 1e-9 and abs(driver.dec_deg + 20.0) < 1e-9
    assert link.goto_fault == ""
    # measured: a 30° Dec / 30° RA goto at 40°/s along the diagonal; the reports show its
    # end a poll late, so the measure is a little under the true rate and never above it
    assert rate is not None and 0.0 < rate <= 40.0 * 1.01


def test_goto_budget_and_axis_travel():
    b = GotoBudget(margin_s=10.0, slow_factor=2.0, report_periods=4)
    # 90° at a measured 15°/s: 12 s, plus 10 s, plus 4 periods of 0.1 s
    assert b.bound_s(90.0, measured_deg_s=15.0, declared_deg_s=3.0, period_s=0.1) == \
        pytest.approx(22.4)
    # nothing measured: the declared rate; nothing declared: the cautious default (1°/s)
    assert b.bound_s(90.0, measured_deg_s=None, declared_deg_s=3.0, period_s=None) == \
        pytest.approx(60 + 10 + 1.0)
    assert b.bound_s(10.0, measured_deg_s=None, declared_deg_s=None, period_s=0.25) == \
        pytest.approx(20 + 10 + 1.0)
    # axis travel: the larger axis turn; RA the short way round; a German flip allowed for
    assert axis_travel_deg(23.5, 0.0, 0.5, 10.0, "fork") == pytest.approx((15.0, 15.0))
    assert axis_travel_deg(1.0, 10.0, 2.0, 40.0, "fork") == pytest.approx((30.0, 30.0))
    # German: the direct way for the rate measure, a flip (165° of hour angle) for the budget
    assert axis_travel_deg(1.0, 10.0, 2.0, 40.0, "german") == pytest.approx((30.0, 165.0))
    meter = SlewRateMeter()
    meter.landed(1.0, 0.01)  # too short to say anything
    assert meter.rate_deg_s() is None
    meter.landed(30.0, 2.0)
    meter.landed(60.0, 4.0)
    assert meter.rate_deg_s() == pytest.approx(15.0)


# ---------------------------------------------------------------------- through the VSS
def test_a_slew_on_a_goto_that_never_lands_ends_with_mount_fault_shown_and_logged(eop,
                                                                                 monkeypatch):
    """The VSS (`vs server --mount alpaca://…` with the driver swapped for `SimGotoDriver`):
    the slew operation fails with `mount_fault`, `status` shows the fault and the stopped
    mount, the event log has it, and the server closes (no hang)."""
    from virtualstar.server import assembly, build_server

    driver = SimGotoDriver(stuck=True)

    def open_sim(url, site, eop_=None, **options):
        return _link(driver, eop, goto_budget=GotoBudget(margin_s=0.5, report_periods=2),
                     rest_wait_s=2.0)

    monkeypatch.setattr(assembly, "open_rate_mount", open_sim)

    async def main():
        vss = build_server(mount_url="alpaca://127.0.0.1:9/0", site=SITE)
        await vss.start("ws://127.0.0.1:0")
        try:
            t = vss.telescope
            await t.link.wait_connected(10)
            await asyncio.sleep(0.5)
            op = await t.slew_altaz(200.0, 50.0)
            await asyncio.wait_for(asyncio.shield(op.done), HANG_GUARD_S)
            status = await t.status()
            events = [(e.level, e.kind, e.message) for e in t.log.since(0)]
            return op.as_dict(), op.done.exception() if op.done.done() else None, status, \
                events
        finally:
            await asyncio.wait_for(vss.close(), HANG_GUARD_S)

    op, exc, status, events = asyncio.run(main())
    assert op["phase"] == "failed", op
    assert getattr(exc, "code", None) == "mount_fault" or "mount_fault" in str(op), (op, exc)
    assert status["backend"]["goto_fault"] and "did not land" in status["backend"]["goto_fault"]
    assert driver.rates == (0.0, 0.0) and not driver.tracking and driver.target is None
    assert any(level == "error" and kind == "fault" and "did not land" in message
               for level, kind, message in events), events


@pytest.mark.parametrize("dropped", [1, 2])
def test_a_waypoint_goto_the_driver_drops_is_sent_again_then_a_fault(eop, dropped):
    """A driver that accepts a goto and stays where it is, not slewing (the Alpaca simulator
    can lose a goto sent as its previous slew completes): not taken as landed (the detour's
    next leg would start from the wrong place); overdue, it is sent again, then a fault."""
    async def main():
        driver = SimGotoDriver()
        link = _link(driver, eop, goto_budget=GotoBudget(margin_s=0.5, report_periods=2),
                     rest_wait_s=2.0)
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        here = link._report
        az, el = link._observed(here.ra_rad, here.dec_rad, here.read_us)
        az_deg, el_deg = math.degrees(az) + 10.0, math.degrees(el) + 5.0
        driver.calls.clear()
        driver.drop_gotos = dropped
        try:
            await asyncio.wait_for(link.call("goto_place", az_deg, el_deg), HANG_GUARD_S)
            outcome = None
        except MountFault as exc:
            outcome = str(exc)
        rep = link._report
        a, e = link._observed(rep.ra_rad, rep.dec_rad, rep.read_us)
        # the target's azimuth may pass 360° (+10° from where the mount stands)
        off = math.degrees(erfa.seps(a, e, math.radians(az_deg), math.radians(el_deg)))
        state = link.state_name()
        await link.stop()
        return driver, outcome, off, state

    driver, outcome, off, state = asyncio.run(main())
    assert driver.calls.count("goto") == 2
    if dropped == 1:
        assert outcome is None and off < 0.1 and state != "fault"
    else:
        assert outcome and "did not land within" in outcome and state == "fault"
        assert driver.rates == (0.0, 0.0) and not driver.tracking


def test_a_goto_flagged_late_is_waited_for_until_the_mount_reports_its_place(eop):
    """A driver that does not flag its goto as a slew for its first 1.5 s (the INDI
    simulator's star goto was once taken as landed 4.6° short): the link waits until the
    reports show the place, not for the first report without the flag."""
    async def main():
        driver = SimGotoDriver(rate_deg_s=10.0)
        driver.early_idle_s = 1.5
        link = _link(driver, eop)
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        driver.calls.clear()
        await asyncio.wait_for(link.call("goto_native", math.radians(7.0 * 15),
                                         math.radians(20.0)), HANG_GUARD_S)
        rep = link._report
        await link.stop()
        return driver, rep

    driver, rep = asyncio.run(main())
    assert driver.calls.count("goto") == 1 and "abort" not in driver.calls
    assert abs(math.degrees(rep.ra_rad) / 15.0 - 7.0) < 1e-6
    assert abs(math.degrees(rep.dec_rad) - 20.0) < 1e-6


# ---------------------------------------------------------------------- stop is final
class SlowRatesDriver(SimGotoDriver):
    """A driver that takes a MoveAxis off the wire at once but applies it only when `held`
    is released (alpaca-simulators runs each request in a thread pool)."""

    async def set_rates(self, ra_deg_s: float, dec_deg_s: float) -> None:
        if (ra_deg_s, dec_deg_s) != (0.0, 0.0):
            await self._hold("rates sent")
        await super().set_rates(ra_deg_s, dec_deg_s)


async def _stop_while_held(driver, eop, role: str, *args, sent: str):
    """Start `role` on a link, cancel it (as a stop does to its operation) once the driver
    has taken its command off the wire (`sent` in its calls) but not applied it (`held`),
    then stop; release the command once the stop has had time to overtake it. Return the
    link (stopped) and whether the stop's abort waited for the held command."""
    link = _link(driver, eop)
    link.start()
    await link.wait_connected(10)
    await link.wait_report(0, 5)
    driver.calls.clear()
    driver.held = asyncio.get_running_loop().create_future()
    command = asyncio.ensure_future(link.call(role, *args))
    while sent not in driver.calls:
        await asyncio.sleep(0)
    command.cancel()
    stopping = asyncio.ensure_future(link.call("stop"))
    for _ in range(20):
        await asyncio.sleep(0)
    waited = "abort" not in driver.calls
    driver.held.set_result(None)
    await asyncio.wait_for(stopping, HANG_GUARD_S)
    with pytest.raises(asyncio.CancelledError):
        await command
    return link, waited


def test_a_stop_during_a_rate_command_reaches_the_driver_after_it_and_the_mount_rests(eop):
    """The rate loop is cancelled by a stop while its MoveAxis is on the wire: the stop's
    commands wait for that one's answer, so the driver ends with zero rates (before, the
    abandoned command overtook the stop's zeros and the mount ran away at its rate)."""
    async def main():
        driver = SlowRatesDriver()
        link, waited = await _stop_while_held(driver, eop, "set_rates", 1e-3, 5e-4,
                                              sent="rates sent")
        await link.stop()
        return driver, waited

    driver, waited = asyncio.run(main())
    assert waited, driver.calls
    assert driver.rates == (0.0, 0.0), driver.calls
    applied = [c for c in driver.calls if c.startswith("rates ") and c != "rates sent"]
    assert applied[0] != "rates 0 0" and applied[-1] == "rates 0 0", driver.calls
    assert driver.calls.index("abort") > driver.calls.index(applied[0]), driver.calls


class SlowGotoDriver(SimGotoDriver):
    """A driver that takes a goto off the wire at once but applies it only when `held` is
    released (a request in alpaca-simulators' thread pool)."""

    def __init__(self) -> None:
        super().__init__(rate_deg_s=2.0)

    async def goto_radec(self, ra_h: float, dec_deg: float) -> None:
        await self._hold("goto sent")
        await super().goto_radec(ra_h, dec_deg)


def test_a_stop_during_a_goto_command_reaches_the_driver_after_it_and_the_mount_rests(eop):
    """A slew is cancelled by a stop while its goto is on the wire: the stop's abort waits
    for that goto's answer, so the driver's last word is the abort and the mount does not
    slew on to the goto's place (before, the abort could overtake the abandoned goto)."""
    async def main():
        driver = SlowGotoDriver()
        link, waited = await _stop_while_held(driver, eop, "goto_native", math.radians(9.0 * 15),
                                              math.radians(40.0), sent="goto sent")
        at_stop = (driver.ra_h, driver.dec_deg)
        await asyncio.sleep(0.3)  # 0.6° of slew at the driver's 2°/s, were it still going
        driver._advance()
        moved_deg = math.hypot((driver.ra_h - at_stop[0]) * 15.0, driver.dec_deg - at_stop[1])
        await link.stop()
        return driver, waited, moved_deg

    driver, waited, moved_deg = asyncio.run(main())
    assert waited, driver.calls
    assert driver.calls.index("goto") < driver.calls.index("abort"), driver.calls
    assert driver.target is None and not driver.slewing, driver.calls
    assert driver.rates == (0.0, 0.0) and not driver.tracking
    assert moved_deg < 0.01  # at rest: not tracking, so RA drifts at the sidereal rate only


class SilentDuringGotoDriver(SimGotoDriver):
    """A goto driver that stops answering reads once `silent` is set (a network that
    failed mid-slew), and whose first abort takes `slow_abort_s` to be answered (a
    driver, or a link, as slow to take the lost link's halt as the network that failed)."""

    def __init__(self) -> None:
        super().__init__(stuck=True)
        self.slow_abort_s = 0.0

    async def goto_radec(self, ra_h: float, dec_deg: float) -> None:
        await super().goto_radec(ra_h, dec_deg)
        self.silent = True

    async def abort(self) -> None:
        if self.slow_abort_s:
            self.calls.append("abort sent")
            slow, self.slow_abort_s = self.slow_abort_s, 0.0
            await asyncio.sleep(slow)
        await super().abort()


def test_once_the_mount_is_declared_lost_a_goto_in_progress_sends_nothing_more(eop):
    """The driver goes silent after a goto; the link declares it lost and halts it (abort,
    zero rates, tracking off). A goto still waiting for its landing runs out of budget
    during that halt: it must not send its second attempt (before, the link counted as
    connected until its halt was answered, and that goto went out after the halt's abort)."""
    async def main():
        driver = SilentDuringGotoDriver()
        link = _link(driver, eop, goto_budget=GotoBudget(margin_s=0.6, report_periods=0),
                     stale_s=0.2, rest_wait_s=0.5)
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        driver.calls.clear()
        driver.slow_abort_s = 1.0  # the next abort, the lost link's halt: the goto's budget ends in it
        with pytest.raises(MountUnavailable):
            await asyncio.wait_for(link.call("goto_native", math.radians(6.2 * 15),
                                             math.radians(12.0)), HANG_GUARD_S)
        await link.stop()
        return driver

    driver = asyncio.run(main())
    assert "abort sent" in driver.calls, driver.calls
    halt = driver.calls.index("abort sent")
    assert driver.calls.count("goto") == 1, driver.calls
    assert driver.calls.index("goto") < halt, driver.calls


class SilentWhileRatesHeldDriver(SlowRatesDriver):
    """A SlowRatesDriver whose reads fail from the moment it takes a MoveAxis off the wire
    (a network that fails then): it applies the MoveAxis once `held` is released, after
    the lost link's halt, as a request queued in alpaca-simulators' thread pool would be."""

    async def set_rates(self, ra_deg_s: float, dec_deg_s: float) -> None:
        if self.held is not None and (ra_deg_s, dec_deg_s) != (0.0, 0.0):
            self.silent = True
        await super().set_rates(ra_deg_s, dec_deg_s)


class TrackingOffAfterTheCommandDriver(SilentWhileRatesHeldDriver):
    """A SilentWhileRatesHeldDriver whose "tracking off" is applied only once `answered` is
    done: the held MoveAxis is then applied and answered while the lost link's first halt is
    still on the wire (a loaded host once did this)."""

    answered: asyncio.Future | None = None

    async def set_tracking(self, on: bool) -> None:
        if not on and self.answered is not None:
            await asyncio.shield(self.answered)
        await super().set_tracking(on)


@pytest.mark.parametrize("answered", ["after the first halt", "during the first halt"])
def test_a_rate_command_on_the_wire_when_the_mount_is_lost_is_followed_by_a_halt(eop,
                                                                                 answered):
    """The link is declared lost while a MoveAxis is on the wire; its halt goes out at once,
    and the MoveAxis is applied after it. Once that command is answered the link halts the
    mount again, so the driver's last word is zero rates (before, the lost link's halt ran
    beside the command, and a mount that still took commands ran on at the rate; then, a
    command answered before the first halt's end was taken for none)."""
    async def main():
        driver = (SilentWhileRatesHeldDriver() if answered == "after the first halt"
                  else TrackingOffAfterTheCommandDriver())
        link = _link(driver, eop, stale_s=0.2, timeout_s=2.0)
        lost = asyncio.Event()
        link.on_event = lambda kind, data: lost.set() if kind == "mount_disconnected" else None
        link.start()
        await link.wait_connected(10)
        await link.wait_report(0, 5)
        driver.calls.clear()
        driver.held = asyncio.get_running_loop().create_future()
        command = asyncio.ensure_future(link.call("set_rates", 1e-3, 5e-4))
        driver.answered = command
        async with asyncio.timeout(HANG_GUARD_S):
            while "abort" not in driver.calls:  # lost: the first halt is under way
                await asyncio.sleep(0.01)
        driver.held.set_result(None)
        async with asyncio.timeout(HANG_GUARD_S):
            await asyncio.gather(command, return_exceptions=True)
            await lost.wait()  # said once the lost link has halted the mount
        await link.stop()
        return driver, link

    driver, link = asyncio.run(main())
    applied = [c for c in driver.calls if c.startswith("rates ") and c != "rates sent"]
    moving = driver.calls.index(next(c for c in applied if c != "rates 0 0"))
    assert driver.calls.index("abort") < moving, driver.calls  # the first halt came first
    assert "abort" in driver.calls[moving:], driver.calls
    assert applied[-1] == "rates 0 0" and driver.rates == (0.0, 0.0), driver.calls
    assert not driver.tracking and link._rates_rad_s == (0.0, 0.0)
