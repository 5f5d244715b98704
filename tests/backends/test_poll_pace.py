"""How often a polled driver is read: fast while latency matters, at its rest pace otherwise.

`PollPace` is checked alone (no I/O, times given); then the link (`RateMountLink`) runs for
real over `SimGotoDriver` (test_driver_waits.py), a goto mount on the host clock. The
rest period is made so long (`NEVER_S`) that a read at rest would not come within any
test's life: whether the poller reads, stops reading or is woken by a command is then
seen as an event, not timed. The real Alpaca simulator's requests per second at rest and
while following are counted in the Alpaca pass scenario (test_alpaca_pass.py).
"""

from __future__ import annotations

import asyncio
import math
import time

import pytest
from test_driver_waits import SimGotoDriver, _link

from virtualstar.astro import EarthOrientation
from virtualstar.astro.constants import ARCSEC_PER_RAD
from virtualstar.server.backends.alpaca import AlpacaDriver
from virtualstar.server.backends.poll_pace import FAST_HOLD_S, PollPace

HANG_GUARD_S = 60.0  # a hang guard, not a speed bound
NEVER_S = 3600.0  # a rest period no test outlives
STILL_S = 1.0  # how long "no read" is watched for (a loaded host only makes it emptier)


@pytest.fixture(scope="module")
def eop() -> EarthOrientation:
    return EarthOrientation.from_astropy_iers_data()


# ---------------------------------------------------------------------- the choice alone
def test_busy_is_fast_then_the_hold_then_rest_and_a_command_is_fast_at_once():
    pace = PollPace(fast_s=0.04, rest_s=0.25)
    assert pace.period_s(100.0, busy=False) == 0.25  # never commanded: at rest
    assert pace.period_s(100.0, busy=True) == 0.04
    # no longer busy: fast for the hold after it, then at rest
    assert pace.period_s(100.0 + FAST_HOLD_S - 0.01, busy=False) == 0.04
    assert pace.fast(100.0 + FAST_HOLD_S - 0.01)
    assert pace.period_s(100.0 + FAST_HOLD_S + 0.01, busy=False) == 0.25
    assert not pace.fast(100.0 + FAST_HOLD_S + 0.01)
    pace.commanded(200.0)
    assert pace.period_s(200.0, busy=False) == 0.04
    assert pace.period_s(200.0 + FAST_HOLD_S + 0.01, busy=False) == 0.25


def test_a_driver_without_a_rest_pace_is_always_read_at_its_own():
    pace = PollPace(fast_s=0.04, rest_s=0.0)  # rest_s below fast_s: the fast one
    assert pace.period_s(0.0, busy=False) == pace.period_s(0.0, busy=True) == 0.04
    assert pace.fast(1e9)


def test_the_alpaca_driver_is_read_about_20_times_a_second_moving_and_4_at_rest():
    assert AlpacaDriver.poll_s == pytest.approx(0.04)
    assert AlpacaDriver.rest_poll_s == pytest.approx(0.25)


# ---------------------------------------------------------------------- the link
class MoveAxisDriver(SimGotoDriver):
    """As ASCOM's simulator: Slewing is true while any MoveAxis rate is on."""

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.rest_poll_s = NEVER_S

    async def read(self):
        rep = await super().read()
        if self.rates != (0.0, 0.0):
            from dataclasses import replace

            rep = replace(rep, slewing=True)
        return rep


async def _until(what, guard_s: float = HANG_GUARD_S) -> None:
    deadline = time.monotonic() + guard_s
    while not what():
        assert time.monotonic() < deadline, "hang guard"
        await asyncio.sleep(0.02)


async def _reads_stop(link) -> int:
    """Wait until the poller sleeps its rest period; then no read comes (over `STILL_S`):
    the reads so far."""
    await _until(lambda: link.describe()["poll_period_s"] == link.pace.rest_s)
    n = link.stats.reads
    await asyncio.sleep(STILL_S)
    assert link.stats.reads == n, "read at rest"
    return n


async def _more_reads(link, n: int, k: int = 5) -> None:
    await _until(lambda: link.stats.reads >= n + k)


def _arcsec_s(x: float) -> float:
    return x / ARCSEC_PER_RAD


def test_at_rest_the_link_stops_reading_and_any_command_wakes_it_at_once(eop):
    """Holding still (tracking off, no rates): after the hold the poller sleeps its rest
    period; a command is followed by reads at once (with a rest period of an hour, a read
    that waited for it would never come); moving at rates keeps it reading; back at rest
    it sleeps again."""
    async def main():
        driver = MoveAxisDriver()
        link = _link(driver, eop)
        link.start()
        await link.wait_connected(10)
        await link.call("stop")  # tracking off, no rates: seen at rest while read fast
        n = await _reads_stop(link)
        assert link.state_name() == "holding"
        status = link.describe()
        assert status["poll_period_s"] == NEVER_S
        assert status["poll_fast_period_s"] == driver.poll_s
        # a command wakes it: reads come at once, and go on while the mount moves
        await link.call("set_rates", _arcsec_s(30.0), 0.0)
        await _more_reads(link, n, 20)
        assert link.describe()["poll_period_s"] == driver.poll_s
        assert link.state_name() == "manual"
        # still moving after the hold: the rates keep it fast
        t_cmd = time.monotonic()
        await _until(lambda: time.monotonic() > t_cmd + FAST_HOLD_S + 0.5)
        n = link.stats.reads
        await _more_reads(link, n, 5)
        # stopped: at rest again once the hold is over
        await link.call("stop")
        await _reads_stop(link)
        await link.stop()

    asyncio.run(main())


def test_a_star_held_by_the_mounts_tracking_is_read_at_rest_a_satellite_fast(eop):
    """Following a path: a still one (a star's place of date) with the loop's noise-level
    corrections (0.03″/s, which set Alpaca's Slewing flag) lets the reads rest; a moving
    one (1°/s, or a join 3 s ahead) keeps them fast, and so does an error above 1″."""
    async def main():
        driver = MoveAxisDriver()
        driver.rest_poll_s = 0.25  # the demand is looked at between reads: they must come
        link = _link(driver, eop)
        link.start()
        await link.wait_connected(10)
        await link.call("set_rates", 0.0, 0.0)  # tracking on, as the rate loop leaves it
        here = (math.radians(driver.ra_h * 15.0), math.radians(driver.dec_deg))
        link.demand = lambda t_us: here
        await link.call("set_rates", _arcsec_s(0.03), _arcsec_s(-0.02))
        link.last_error_arcsec = 0.01
        await _until(lambda: link.describe()["poll_period_s"] == 0.25)
        assert link.state_name() == "manual"  # rates on, Slewing flagged: still at rest
        periods = len(link.stats.periods_s)
        n = link.stats.reads
        await _more_reads(link, n, 3)
        # reads at rest measure nothing of the driver's period
        assert len(link.stats.periods_s) == periods
        # a satellite's join 3 s ahead: the demand moves within the lookahead
        t_join = time.time_ns() // 1000 + 3_000_000

        def satellite(t_us):
            dt = max(0, t_us - t_join) / 1e6
            return here[0] + math.radians(dt), here[1]

        link.demand = satellite
        await _until(lambda: link.describe()["poll_period_s"] == driver.poll_s)
        # the path still, but the loop 5″ off it: fast as well
        link.demand = lambda t_us: here
        link.last_error_arcsec = 5.0
        await asyncio.sleep(FAST_HOLD_S + 0.5)
        n = link.stats.reads
        await _more_reads(link, n, 3)  # each read's pause chosen anew: still fast
        assert link.describe()["poll_period_s"] == driver.poll_s
        link.last_error_arcsec = 0.01
        await _until(lambda: link.describe()["poll_period_s"] == 0.25)
        await link.stop()

    asyncio.run(main())


def test_a_goto_is_read_fast_until_it_lands(eop):
    """A goto waits on the slew's end with fresh reads (the call holds the link), the rest
    period of an hour notwithstanding; the reads rest again after it."""
    async def main():
        driver = MoveAxisDriver(rate_deg_s=10.0)
        link = _link(driver, eop)
        link.start()
        await link.wait_connected(10)
        n = await _reads_stop(link)
        await asyncio.wait_for(link.call("goto_native", math.radians(6.5 * 15.0),
                                         math.radians(15.0)), HANG_GUARD_S)
        # landed (the goto sees its end in the reports: read at the rest period of an
        # hour, it would have been overdue and a fault), read all along
        assert link.stats.reads - n >= 2 and not link.goto_fault
        assert driver.target is None and driver.dec_deg == pytest.approx(15.0)
        await _reads_stop(link)
        await link.stop()

    asyncio.run(main())
