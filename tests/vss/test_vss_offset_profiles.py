"""Offset profiles (offsets.py): time-optimal moves within the limits, without a step.

Synthetic truth: the profile is sampled every 0.1 ms and its position, rate and
acceleration are checked by finite differences against the limits and the goal.
"""

from __future__ import annotations

import numpy as np
import pytest

from virtualstar.server.offsets import OffsetLimits, OffsetProfile, Offsets, time_optimal

T0 = 1_700_000_000_000_000


def _run(prof: OffsetProfile, start_us: int, seconds: float):
    t = start_us + np.arange(int(seconds * 1e4)) * 100
    p, v = prof.sample(t)
    return t, p, v


@pytest.mark.parametrize("seed", range(40))
def test_a_move_from_any_state_reaches_its_goal_within_the_limits_without_a_step(seed):
    rng = np.random.default_rng(seed)
    v_max, a_max = rng.uniform(5, 100), rng.uniform(10, 400)
    prof = OffsetProfile()
    # an earlier move still running, then a new goal given half-way
    prof.plan(T0, float(rng.normal(0, 50)), 0.0, v_max, a_max)
    change = T0 + int(rng.uniform(0.01, 0.5) * 1e6)
    p0, v0 = prof.at(change)
    goal, goal_rate = float(rng.normal(0, 80)), float(rng.uniform(-0.3, 0.3) * v_max)
    reached = prof.plan(change, goal, goal_rate, v_max, a_max)
    t, p, v = _run(prof, change - 50_000, (reached - change) / 1e6 + 0.5)
    k = np.searchsorted(t, change)
    # the rate goes on from where it was (a ramp shorter than the 1 µs grid acts at once)
    assert p[k] == pytest.approx(p0, abs=1e-9) and v[k] == pytest.approx(v0, abs=a_max * 1e-6)
    assert np.abs(np.diff(p)).max() <= max(v_max, abs(v0)) * 1e-4 * 1.001 + 1e-9  # no step
    acc = np.diff(v) / 1e-4
    assert np.abs(acc).max() <= a_max * 1.001 + 1e-6
    if abs(v0) <= v_max:
        assert np.abs(v).max() <= v_max * 1.001
    after = t >= reached
    expect = goal + goal_rate * (t[after] - change) * 1e-6
    assert np.abs(p[after] - expect).max() < 1e-6


def test_time_optimal_is_the_classic_triangle_and_trapezoid():
    # 30″ from rest at 3600″/s²: a triangle, 2·sqrt(30/3600) s, peak sqrt(30·3600)″/s
    segs = time_optimal(-30.0, 0.0, 1800.0, 3600.0)
    assert len(segs) == 2 and sum(d for d, _ in segs) == pytest.approx(2 * (30 / 3600) ** 0.5)
    # 30″ at 20″/s and 40″/s²: 0.5 s up, 1 s at 20″/s, 0.5 s down
    segs = time_optimal(-30.0, 0.0, 20.0, 40.0)
    assert [round(d, 9) for d, _ in segs] == [0.5, 1.0, 0.5]
    assert time_optimal(0.0, 0.0, 1.0, 1.0) == []


def test_operations_add_set_rate_reset_as_pwi4_has_them():
    o = Offsets(OffsetLimits(100.0, 400.0))
    o.change("dec", "add", 10.0, T0)
    o.change("dec", "add", 5.0, T0 + 10_000)  # during the first move: adds to its goal
    assert o.axes["dec"].at(T0 + 5_000_000)[0] == pytest.approx(15.0)
    o.change("ra", "rate", 2.0, T0)
    assert o.axes["ra"].at(T0 + 10_000_000) == pytest.approx((20.0 - 2.0 ** 2 / 800.0, 2.0))
    o.change("ra", "set", 0.0, T0 + 10_000_000)  # the total becomes 0; the drift goes on
    assert o.axes["ra"].at(T0 + 20_000_000)[0] == pytest.approx(20.0, abs=0.1)
    o.change("ra", "reset", 0.0, T0 + 20_000_000)
    assert o.axes["ra"].at(T0 + 30_000_000) == pytest.approx((0.0, 0.0))
    with pytest.raises(ValueError, match="path axis needs"):
        o.change("path", "add", 1.0, T0)
    reached = o.change("path", "add", 1.0, T0, sky_rate_arcsec_s=1000.0)  # 0.1 s/s, 0.4 s/s²
    assert o.axes["path"].at(reached)[0] == pytest.approx(1.0)
    assert (reached - T0) / 1e6 == pytest.approx(1.0 / 0.1 + 0.1 / 0.4, rel=1e-3)
