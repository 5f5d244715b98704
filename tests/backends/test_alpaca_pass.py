"""The VSS on ASCOM's alpaca-simulators: an ISS-like pass, stop mid-pass, the driver killed (pass_checks.py; real time)."""

import pytest

pytest.register_assert_rewrite("pass_checks")

from pass_checks import *  # noqa: E402, F403
from scenario_run import SCENARIO_TIMEOUT_S, scenario_fixtures  # noqa: E402

pytestmark = pytest.mark.timeout(SCENARIO_TIMEOUT_S + 60)
seen_parts, seen, seen_kill = scenario_fixtures("alpaca", "pass", "kill")


def test_the_vss_reads_the_driver_4_times_a_second_at_rest_and_fast_while_following(seen):
    """The Alpaca driver's requests, counted on the wire between the VSS and the simulator
    (backend_scenario.RequestCounter): while the VSS follows the pass with rate corrections
    it reads at its fast pace (`AlpacaDriver.poll_s`, ~20 reads a second on a quiet host);
    at rest after the stop, once its status says so, at most 1/`rest_poll_s` (4) reads a
    second, each the same three requests (DeviceState, RightAscension, Declination), and
    nothing else."""
    req = seen["requests"]
    assert req["rest"], "the VSS never read at its rest pace after the stop (hang guard)"
    sent = [(float(t), m) for t, m in req["all"]]

    def count(a: float, b: float, member: str | None = None) -> int:
        return sum(a <= t <= b and (member is None or m == member) for t, m in sent)

    start, end = req["rest"]
    span = end - start
    reads_at_rest = count(start, end, "devicestate")
    # the rest pace: a read, then a pause of rest_poll_s (a loaded host only reads less)
    assert 1 <= reads_at_rest <= span / req["rest_poll_s"] + 1, (reads_at_rest, span)
    # three requests a read (the window's edges may cut one read's three)
    assert abs(count(start, end) - 3 * reads_at_rest) <= 2
    assert {m for t, m in sent if start <= t <= end} <= {"devicestate", "rightascension",
                                                         "declination"}
    info = seen["pass_op_before_stop"]["info"]
    a, b = info["tracking_from_us"] / 1e6, seen["stop_sent_s"]
    reads_following = count(a, b, "devicestate")
    following_hz = reads_following / (b - a)
    rest_hz = reads_at_rest / span
    # while following: the fast pace, several times the rest pace (20 vs 4 on a quiet host)
    assert following_hz > 2.0 * max(rest_hz, 1.0 / req["rest_poll_s"] / 2), \
        (following_hz, rest_hz)
    assert count(a, b, "moveaxis") > 0  # it did follow with rate corrections
