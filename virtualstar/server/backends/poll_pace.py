"""How often a polled driver is read: fast while latency matters, slowly at rest.

An Alpaca driver is read with three requests (DeviceState, RightAscension, Declination),
and the rate loop runs once per new report, so a follower wants ~20 reports a second.
A mount at rest does not: parked, holding a place, or tracking a star by its own
sidereal tracking (the rate loop then sends nothing: the rates stay within its
deadband), three requests twenty times a second only cost the driver's host and the
VSS's (~0.15 core each on alpaca-simulators). `PollPace` is the choice, free of I/O:

* **fast** (`fast_s`, the driver's ``poll_s``) while the link says it is *busy*
  (`RateMountLink._busy`): a call in progress (a goto waits on the slew's end), rates
  commanded that move the place (more than ~1″/s), the driver flags a goto, a followed
  path more than ~1″ off, or one that
  moves within `DEMAND_LOOKAHEAD_S` (a satellite's run-up and pass, an offset); and for
  `hold_s` after any of these and after every command, so that a procedure's next step
  (the loop's sign probe and join after a goto) still sees fresh reports;
* **at rest** (`rest_s`, the driver's ``rest_poll_s``) otherwise. A command wakes the
  poller at once (`RateMountLink.call`), so it never waits out a rest period.

Only reports read at the fast pace measure the driver's report period (the rate loop's
gain and lag are set from it): a place that moved between two reads at rest moved over
the rest period, not the driver's.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DEMAND_LOOKAHEAD_S", "FAST_HOLD_S", "PollPace"]

FAST_HOLD_S = 2.0  # reads stay fast this long after a command or the end of a motion
DEMAND_LOOKAHEAD_S = 5.0  # a followed path that moves within this long keeps reads fast
# (before the join the demand is the join point; the run-up starts ≤ 2 s before it)


@dataclass
class PollPace:
    """The read period of a polled driver (`fast_s` when busy or lately busy, else `rest_s`)."""

    fast_s: float
    rest_s: float
    hold_s: float = FAST_HOLD_S
    fast_until_s: float = 0.0  # monotonic seconds: fast at least until then

    def __post_init__(self) -> None:
        self.rest_s = max(self.rest_s, self.fast_s)

    def commanded(self, now_s: float) -> None:
        """A command was sent (or is being sent): fast from now for `hold_s` at least."""
        self.fast_until_s = max(self.fast_until_s, now_s + self.hold_s)

    def period_s(self, now_s: float, busy: bool) -> float:
        """The pause before the next read (seconds of monotonic time)."""
        if busy:
            self.commanded(now_s)
        return self.fast_s if now_s < self.fast_until_s else self.rest_s

    def fast(self, now_s: float) -> bool:
        """Whether reads are at the fast pace now (after the last `period_s`)."""
        return now_s < self.fast_until_s or self.rest_s == self.fast_s
