"""traj.replace_from: the future of the trajectory buffer replaced between two ticks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from emulator_helpers import ONE_ARCSEC, holding_mount, ticks

from mount_emulator import layout as L
from mount_emulator.exceptions import ReplaceRefused
from mount_emulator.states import AxisState

RATE = math.radians(0.3)  # rad/s, both axes
STEP_US = 50_000


def _line(m, t_us: np.ndarray, t0_us: int, p0: np.ndarray, rate: float = RATE):
    """Points of a constant-rate line on both axes through p0 at t0_us."""
    s = (t_us - t0_us) * 1e-6
    return (t_us, p0[0] + rate * s, p0[1] + rate * s, np.full(len(t_us), rate),
            np.full(len(t_us), rate))


def _tracking(seconds: float = 10.0):
    """A mount following a constant-rate line (run-up first) for a while."""
    m = holding_mount()
    p0 = np.array([m.axis_slot(0, L.A_REF), m.axis_slot(1, L.A_REF)])
    t0 = m.mount_time_us
    # a 1 s constant-acceleration run-up from rest joins the line at t0 + 1.1 s
    ramp_t = t0 + np.arange(1, 23) * STEP_US
    s = np.clip((ramp_t - t0) * 1e-6 - 0.1, 0.0, 1.0)
    pos = 0.5 * RATE * s**2
    vel = RATE * s
    m.traj_push(ramp_t, p0[0] + pos, p0[1] + pos, vel, vel)
    join = int(ramp_t[-1])
    start = p0 + 0.5 * RATE
    t = join + np.arange(1, int(seconds * 20)) * STEP_US
    m.traj_push(*_line(m, t, join, start))
    m.traj_start()
    m.run(ticks(2.0))
    return m, join, start


def test_replace_from_drops_the_future_and_follows_the_new_points_at_once():
    m, join, start = _tracking()
    now = m.mount_time_us
    count = m.traj_count()
    from_us = now + 20_000
    # the new future: the same line, but 10″ higher in elevation from `from_us`, reached by
    # a smooth (constant-jerk-free, quadratic) blend over 0.2 s
    t = from_us + np.arange(0, 300) * 10_000
    az = start[0] + RATE * (t - join) * 1e-6
    blend_s = np.clip((t - from_us) * 1e-6 / 0.2, 0.0, 1.0)
    shape = np.where(blend_s < 0.5, 2 * blend_s**2, 1 - 2 * (1 - blend_s) ** 2)
    d_shape = np.where(blend_s < 0.5, 4 * blend_s, 4 * (1 - blend_s)) / 0.2
    d_shape[blend_s >= 1.0] = 0.0
    el = start[1] + RATE * (t - join) * 1e-6 + 10 * ONE_ARCSEC * shape
    vel = RATE + 10 * ONE_ARCSEC * d_shape
    accepted = m.traj_replace_from(from_us, t, az, el, np.full(len(t), RATE), vel)
    assert accepted == len(t)
    dropped = int(m.state[L.G_TRAJ_DROPPED])
    assert dropped > 0 and m.traj_count() == count - dropped + len(t)
    assert m.state[L.G_TRAJ_REPLACES] == 1
    assert m.state[L.G_TRAJ_REPLACE_LEAD_US] == 20_000
    trace = m.record(ticks(0.5), ["axis.el.reference", "time.mount_us"])
    ref, t_ref = trace[:, 0], trace[:, 1]
    nominal = start[1] + RATE * (t_ref - join) * 1e-6
    off = (ref - nominal) / ONE_ARCSEC
    # nothing moves before from_us; the difference begins within 1 ms after it
    assert np.abs(off[t_ref < from_us]).max() < 1e-6
    first = t_ref[np.argmax(np.abs(off) > 1e-5)]
    assert from_us <= first <= from_us + 1_000
    assert off[-1] == pytest.approx(10.0, abs=1e-3)
    # no step: the reference never moves more per tick than the rate allows
    assert np.abs(np.diff(ref)).max() < (RATE + 10 * ONE_ARCSEC / 0.1) * 1e-4 * 1.01
    m.run(ticks(1.0))
    assert m.axis_state(1) == AxisState.TRACKING
    assert abs(m.axis_slot(1, L.A_ERR_AS)) < 0.5


def test_replace_from_is_refused_for_a_time_closer_than_the_minimum_lead():
    m, _, start = _tracking()
    before = (m.traj_count(), int(m.state[L.G_TRAJ_LAST_US]))
    now = m.mount_time_us
    lead = int(m.param("traj.replace_min_lead_us"))
    assert lead == 20_000
    t = now + np.arange(1, 5) * 10_000
    for from_us in (now - 1_000, now, now + lead - 100):
        with pytest.raises(ReplaceRefused, match="traj.replace_min_lead_us"):
            m.traj_replace_from(from_us, t + lead, *_line(m, t, now, start)[1:])
    assert m.state[L.G_TRAJ_REPLACE_REFUSED] == 3
    assert (m.traj_count(), int(m.state[L.G_TRAJ_LAST_US])) == before  # untouched
    m.set_param("traj.replace_min_lead_us", 5_000.0)
    assert m.traj_replace_from(now + 5_000, *_line(m, now + 5_000 + t - now, now, start)) == 4


def test_replace_from_refuses_bad_points_whole_and_leaves_the_buffer_alone():
    m, _, start = _tracking()
    before = (m.traj_count(), int(m.state[L.G_TRAJ_LAST_US]))
    from_us = m.mount_time_us + 50_000
    t = from_us + np.arange(0, 4) * 10_000
    pts = list(_line(m, t, from_us, start))
    with pytest.raises(ReplaceRefused, match="at or after from_us"):
        m.traj_replace_from(from_us + 1, *pts)  # the first point before from_us
    bad_el = pts[2].copy()
    bad_el[2] = math.radians(120.0)
    with pytest.raises(ReplaceRefused, match="axis limits"):
        m.traj_replace_from(from_us, pts[0], pts[1], bad_el, pts[3], pts[4])
    backwards = pts[0][::-1].copy()
    with pytest.raises(ReplaceRefused, match="increasing"):
        m.traj_replace_from(from_us, backwards, *pts[1:])
    assert (m.traj_count(), int(m.state[L.G_TRAJ_LAST_US])) == before


def test_replace_from_with_no_points_cuts_the_buffer_short_and_the_mount_runs_out():
    m, _, _ = _tracking()
    from_us = m.mount_time_us + 300_000
    assert m.traj_replace_from(from_us, [], [], [], [], []) == 0
    assert m.state[L.G_TRAJ_LAST_US] < from_us
    m.run(ticks(2.0))
    assert m.state[L.G_TRAJ_UNDERRUNS] == 1  # the cut buffer ran dry: a controlled stop


def test_traj_init_zeroes_the_replace_counters():
    m, _, start = _tracking()
    with pytest.raises(ReplaceRefused):
        m.traj_replace_from(m.mount_time_us, [], [], [], [], [])
    m.traj_replace_from(m.mount_time_us + 30_000, [], [], [], [], [])
    m.traj_reset()
    m.run(ticks(1.0))
    m.traj_init()
    for i in (L.G_TRAJ_REPLACES, L.G_TRAJ_REPLACE_REFUSED, L.G_TRAJ_DROPPED):
        assert m.state[i] == 0


def test_an_increasing_batch_is_stored_and_counted_as_pushing_its_points_one_by_one():
    from mount_emulator.model import MountModel

    rng = np.random.default_rng(5)
    for trial in range(200):
        cap = int(rng.integers(3, 40))
        batched = MountModel(start_us=10**15, traj_capacity=cap)
        single = MountModel(start_us=10**15, traj_capacity=cap)
        for _ in range(4):
            n = int(rng.integers(2, 30))
            t = np.sort(rng.choice(np.arange(10**15 - 50, 10**15 + 300), n, replace=False))
            az, el = rng.uniform(-6, 6, n), rng.uniform(-0.5, 2.0, n)  # some out of range
            v = rng.normal(size=n)
            v[rng.random(n) < 0.05] = np.inf
            got = batched.traj_push(t.astype(np.int64), az, el, v, v)  # the array path
            one = sum(single.traj_push(t[k:k + 1].astype(np.int64), az[k:k + 1], el[k:k + 1],
                                       v[k:k + 1], v[k:k + 1]) for k in range(n))
            assert got == one, trial
            for i in (L.G_TRAJ_TAIL, L.G_TRAJ_LATE, L.G_TRAJ_ACCEPTED, L.G_TRAJ_OUT_OF_RANGE,
                      L.G_TRAJ_LAST_US):
                assert batched.state[i] == single.state[i], (trial, i)
        k = int(batched.state[L.G_TRAJ_TAIL])
        idx = np.arange(k) % cap
        assert np.array_equal(batched.traj_t[idx], single.traj_t[idx])
        assert np.array_equal(batched.traj_p[idx], single.traj_p[idx])
