"""Password attempts throttled per source address and overall, without I/O or a clock.

An endpoint (the ASTCom `Endpoint`, the VirtualStar Server) asks `AuthThrottle.reserve`
before it checks a password, waits the `Verdict.wait_s` it is given (holding the
attempt; at most `max_hold_s`), checks the password, and reports the outcome with
`failed` or `succeeded`. The caller passes the time (monotonic seconds), so the rules
are tested without waiting:

* **per address**: attempts from one address are checked one after the other, the
  n-th consecutive failure putting ``first_delay_s * 2**(n-1)`` seconds (at most
  ``max_delay_s``) before the next check. The ``lockout_failures``-th failure locks
  the address out for ``lockout_s``; then it starts afresh. A right password forgets
  the address. An address quiet for ``forget_s`` is forgotten, and at most
  ``max_addresses`` are remembered (the least recently seen go first), so a flood of
  addresses cannot grow the table without bound.
* **overall**: at most ``global_rate_per_s`` checks a second over all addresses after
  a burst of ``global_burst`` (a generic cell rate algorithm), so guesses spread over
  many addresses or connections are bounded too.

A legitimate user who mistyped once waits a fraction of a second; a guesser's
attempts queue up behind each other. An attempt that would wait more than
``max_hold_s``, or that comes from a locked-out address, is refused without being
checked: it costs the guesser a round trip and tells it nothing. Those refusals are
counted per address (`Failure.refused`) so that a log can say how many there were
without writing one line each.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

__all__ = ["AuthThrottle", "Failure", "ThrottlePolicy", "Verdict"]


@dataclass(frozen=True)
class ThrottlePolicy:
    """How attempts are throttled (seconds; see the module docstring)."""

    first_delay_s: float = 0.25
    max_delay_s: float = 30.0
    lockout_failures: int = 20
    lockout_s: float = 300.0
    forget_s: float = 900.0
    global_rate_per_s: float = 5.0
    global_burst: int = 10
    max_hold_s: float = 5.0
    max_addresses: int = 10_000

    def __post_init__(self) -> None:
        for name in ("first_delay_s", "max_delay_s", "lockout_s", "forget_s",
                     "global_rate_per_s", "max_hold_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ThrottlePolicy.{name}={getattr(self, name)!r}: expected > 0")
        for name in ("lockout_failures", "global_burst", "max_addresses"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"ThrottlePolicy.{name}={getattr(self, name)!r}: expected >= 1")

    def delay_s(self, failures: int) -> float:
        """The wait before the next check after `failures` consecutive failures."""
        if failures <= 0:
            return 0.0
        return min(self.max_delay_s, self.first_delay_s * 2.0 ** min(failures - 1, 60))


@dataclass(frozen=True)
class Verdict:
    """The answer of `reserve`: check after `wait_s`, or (`refused`) not at all."""

    wait_s: float
    refused: bool = False
    reason: str = ""  # why it waits or is refused: "address", "locked" or "overall"

    def message(self, address: str) -> str:
        """Say why an attempt was refused, and when to try again."""
        if self.reason == "locked":
            why = f"{address} is locked out after too many wrong passwords"
        elif self.reason == "address":
            why = f"too many wrong passwords from {address}"
        else:
            why = "too many login attempts on this server"
        return f"{why}: not checked; try again in {self.wait_s:.0f} s"


@dataclass(frozen=True)
class Failure:
    """What a wrong password costs its address."""

    failures: int  # consecutive failures from the address, this one included
    locked_s: float  # > 0: this failure locked the address out for so long
    refused: int  # attempts from the address refused unchecked since its last failure


@dataclass
class _Address:
    failures: int = 0
    pending: int = 0  # attempts reserved and not yet reported
    next_s: float = 0.0  # the next attempt is not checked before this time
    locked_until_s: float = 0.0
    seen_s: float = 0.0
    refused: int = 0


class AuthThrottle:
    """Per-address and overall limits on password attempts (see the module docstring)."""

    def __init__(self, policy: ThrottlePolicy | None = None) -> None:
        self.policy = policy or ThrottlePolicy()
        self._addresses: OrderedDict[str, _Address] = OrderedDict()
        self._tat_s = 0.0  # the overall limit's theoretical arrival time
        self.checked = 0  # attempts let through to the password check
        self.refused = 0  # attempts refused unchecked
        self.failures = 0  # wrong passwords reported

    def reserve(self, address: str, now_s: float) -> Verdict:
        """Book a check of an attempt from `address`; say how long to hold it first."""
        p = self.policy
        state = self._state(address, now_s)
        if now_s < state.locked_until_s:
            return self._refuse(state, Verdict(state.locked_until_s - now_s, True, "locked"))
        interval = 1.0 / p.global_rate_per_s
        overall_s = max(now_s, self._tat_s - (p.global_burst - 1) * interval)
        at_s = max(overall_s, state.next_s)
        if at_s - now_s > p.max_hold_s:
            reason = "address" if state.next_s >= overall_s else "overall"
            return self._refuse(state, Verdict(at_s - now_s, True, reason))
        self._tat_s = max(self._tat_s, at_s) + interval
        state.pending += 1
        # the next attempt from this address waits as if this one fails (it is forgotten
        # if it does not)
        state.next_s = at_s + p.delay_s(state.failures + state.pending)
        self.checked += 1
        return Verdict(at_s - now_s, False, "address" if at_s > overall_s else
                       ("overall" if at_s > now_s else ""))

    def failed(self, address: str, now_s: float) -> Failure:
        """Report that a reserved attempt from `address` held a wrong password."""
        p = self.policy
        state = self._state(address, now_s)
        state.pending = max(0, state.pending - 1)
        state.failures += 1
        self.failures += 1
        refused, state.refused = state.refused, 0
        if state.failures >= p.lockout_failures:
            failures, state.failures = state.failures, 0  # after the lockout: afresh
            state.locked_until_s = now_s + p.lockout_s
            state.next_s = max(state.next_s, state.locked_until_s)
            return Failure(failures, p.lockout_s, refused)
        return Failure(state.failures, 0.0, refused)

    def succeeded(self, address: str, now_s: float) -> None:
        """Report that a reserved attempt from `address` held a right password."""
        self._addresses.pop(address, None)

    def cancelled(self, address: str, now_s: float) -> None:
        """Report that a reserved attempt was never checked (its connection went away)."""
        state = self._addresses.get(address)
        if state is not None:
            state.pending = max(0, state.pending - 1)

    def tracked(self) -> int:
        """Return how many addresses are remembered."""
        return len(self._addresses)

    def _refuse(self, state: _Address, verdict: Verdict) -> Verdict:
        state.refused += 1
        self.refused += 1
        return verdict

    def _state(self, address: str, now_s: float) -> _Address:
        """Return the state of `address`, remembered from now on; forget stale ones."""
        p = self.policy
        while self._addresses:  # the least recently seen first
            oldest = next(iter(self._addresses.values()))
            if (now_s - oldest.seen_s < p.forget_s or now_s < oldest.locked_until_s
                    or oldest.pending):
                break
            self._addresses.popitem(last=False)
        state = self._addresses.get(address)
        if state is None:
            while len(self._addresses) >= p.max_addresses:
                self._addresses.popitem(last=False)
            state = self._addresses[address] = _Address()
        state.seen_s = now_s
        self._addresses.move_to_end(address)
        return state
