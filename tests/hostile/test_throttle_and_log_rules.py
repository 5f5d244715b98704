"""The rules without I/O: the password throttle on a given clock, the log's rings."""

from __future__ import annotations

import pytest

from astcom_client.events import EventLog
from astcom_client.throttle import AuthThrottle, ThrottlePolicy

T0 = 1000.0


def test_a_first_attempt_is_checked_at_once_and_a_right_password_forgets_the_address():
    throttle = AuthThrottle()
    assert throttle.reserve("10.0.0.1", T0).wait_s == 0.0
    throttle.succeeded("10.0.0.1", T0)
    assert throttle.tracked() == 0
    assert throttle.reserve("10.0.0.1", T0).wait_s == 0.0


def test_failures_from_one_address_double_the_wait_then_lock_it_out_until_it_expires():
    policy = ThrottlePolicy(first_delay_s=1.0, max_delay_s=8.0, lockout_failures=6,
                            lockout_s=100.0, global_rate_per_s=1000.0, max_hold_s=50.0)
    throttle = AuthThrottle(policy)
    now, waits = T0, []
    for _ in range(5):
        verdict = throttle.reserve("a", now)
        assert not verdict.refused
        waits.append(verdict.wait_s)
        now += verdict.wait_s
        assert throttle.failed("a", now).locked_s == 0.0
    assert waits == [0.0, 1.0, 2.0, 4.0, 8.0]  # doubling, capped at max_delay_s
    now += throttle.reserve("a", now).wait_s
    assert throttle.failed("a", now).locked_s == 100.0  # the sixth failure locks it out
    locked = throttle.reserve("a", now + 50.0)
    assert locked.refused and locked.reason == "locked" and locked.wait_s == pytest.approx(50.0)
    assert "locked out" in locked.message("a")
    assert throttle.reserve("b", now + 50.0).wait_s == 0.0  # another address is not held
    assert throttle.reserve("a", now + 100.0).wait_s == 0.0  # expired: afresh


def test_an_attempt_that_would_wait_longer_than_the_hold_is_refused_unchecked_and_counted():
    throttle = AuthThrottle(ThrottlePolicy(first_delay_s=10.0, max_hold_s=5.0))
    throttle.reserve("a", T0)
    throttle.failed("a", T0)
    refused = throttle.reserve("a", T0 + 1.0)
    assert refused.refused and refused.reason == "address" and refused.wait_s == 9.0
    throttle.reserve("a", T0 + 2.0)
    now = T0 + 10.0
    throttle.reserve("a", now)
    assert throttle.failed("a", now).refused == 2  # reported with the next failure
    assert throttle.checked == 2 and throttle.refused == 2


def test_checks_over_all_addresses_are_bounded_by_the_overall_rate():
    throttle = AuthThrottle(ThrottlePolicy(global_rate_per_s=5.0, global_burst=10,
                                           max_hold_s=1.0))
    checked = 0
    for k in range(1000):  # 1000 addresses, one attempt each, within 10 s
        now = T0 + k * 0.01
        verdict = throttle.reserve(f"10.0.{k // 250}.{k % 250}", now)
        if not verdict.refused:
            checked += 1
            throttle.failed(f"10.0.{k // 250}.{k % 250}", now + verdict.wait_s)
    # at most the burst plus 5 per second over the 10 s (and the last hold of 1 s)
    assert checked <= 10 + 5 * 11
    assert checked >= 5 * 9


def test_the_table_of_addresses_stays_bounded_and_forgets_quiet_ones():
    throttle = AuthThrottle(ThrottlePolicy(max_addresses=100, forget_s=60.0,
                                           global_rate_per_s=1e6, global_burst=10**6))
    for k in range(1000):
        throttle.reserve(f"a{k}", T0)
        throttle.failed(f"a{k}", T0)
    assert throttle.tracked() == 100
    throttle.reserve("late", T0 + 61.0)
    assert throttle.tracked() == 1


def test_connection_churn_pushes_out_only_connections_and_counts_what_fell_out():
    log = EventLog("vss", capacity=100, kept_apart={"connection": 10, "auth": 5})
    log.add(1, "info", "operation", "track 1: tracking", id=1)
    log.add(2, "warning", "safety", "sun zone")
    for k in range(10_000):
        log.add(3 + k, "info", "connection", f"client {k} connected")
    for k in range(8):
        log.add(20_000 + k, "warning", "auth", f"wrong password {k}")
    log.add(30_000, "info", "mode", "mode passive")
    events = log.since(0)
    kinds = [e.kind for e in events]
    assert kinds.count("operation") == 1 and kinds.count("safety") == 1
    assert kinds.count("mode") == 1
    assert kinds.count("connection") == 10 and kinds.count("auth") == 5
    assert [e.seq for e in events] == sorted(e.seq for e in events)  # one order, by seq
    assert dict(log.dropped) == {"connection": 9_990, "auth": 3}
    assert [e.kind for e in log.since(events[-2].seq)] == ["mode"]
    assert len(log) == 18
