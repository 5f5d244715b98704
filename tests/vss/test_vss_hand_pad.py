"""The hand pad (`move`) acts within 50 ms of mount time: from rest, on a change, on zero.

Lockstep emulator + VSS. What the mount did comes from the test's own 10 kHz stream of
the emulator's controller: its position reference (the demand the axes follow), the
reference's rate and the encoders; the acceleration limit from the emulator's own
parameter. The truth is the rates the test asked for: nothing of the VSS's own
account (its plan, its `lead_ms`) is taken as the measure.
"""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
from signal_recording import recording
from vss_rig import mapping_without, read_emulator, run_lockstep_scenario

from virtualstar.vss_client import VssRequestError

START = "2024-05-18T21:00:00Z"  # night at Poznań: the Sun far below
REF = ["axis.az.reference", "axis.el.reference", "axis.az.reference_velocity",
       "axis.el.reference_velocity", "axis.az.reference_acceleration",
       "axis.el.reference_acceleration", "axis.az.position", "axis.el.position", "mount.state"]
LIMITS = ["axis.az.accel_limit", "axis.el.accel_limit", "time.mount_us"]
MAS_DEG = 1 / 3_600_000  # one milliarcsecond in degrees
FIRST_EFFECT_DEG = 5 * MAS_DEG  # the demand has moved: 5 mas off what it would have done
TRACKING = 3  # mount.state


def _deg(x: np.ndarray) -> np.ndarray:
    return np.degrees(x)


async def _limits(vss) -> tuple[np.ndarray, int]:
    """The emulator's own acceleration limits (deg/s²) and its mount time (µs)."""
    v, t_us = await read_emulator(vss, LIMITS)
    return np.degrees([v[LIMITS[0]], v[LIMITS[1]]]), int(v["time.mount_us"])


def _axes(rec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_us, reference deg (n, 2), reference rate deg/s (n, 2)) from a recording."""
    ref = np.column_stack([_deg(rec["axis.az.reference"]), _deg(rec["axis.el.reference"])])
    rate = np.column_stack([_deg(rec["axis.az.reference_velocity"]),
                            _deg(rec["axis.el.reference_velocity"])])
    return rec.t_us, ref, rate


def _first_effect_us(t: np.ndarray, ref: np.ndarray, rate: np.ndarray, accepted_us: int) -> int:
    """The first tick after acceptance where the demand leaves the line it was on then."""
    k = int(np.searchsorted(t, accepted_us))
    line = ref[k] + rate[k] * ((t - t[k]) * 1e-6)[:, None]
    off = np.abs(ref - line).max(axis=1)
    moved = np.flatnonzero((t > accepted_us) & (off > FIRST_EFFECT_DEG))
    assert moved.size, "the demand never moved"
    return int(t[moved[0]])


def _within_accel(rec, accel: np.ndarray) -> bool:
    """Whether the demand never accelerated beyond `accel` (deg/s², per axis): the controller's
    own acceleration reference at every tick, and its rate's change over 10 ms windows (the
    mount clock's stamps jitter by a tick now and then: 1 %)."""
    t, _, rate = _axes(rec)
    own = np.column_stack([_deg(rec["axis.az.reference_acceleration"]),
                           _deg(rec["axis.el.reference_acceleration"])])
    w = 100
    seen = np.abs(np.diff(rate[::w], axis=0) / (np.diff(t[::w]) * 1e-6)[:, None])
    return bool(np.all(np.abs(own) <= accel * (1 + 1e-6)) and np.all(seen <= accel * 1.01))


def _reached_us(t: np.ndarray, rate: np.ndarray, goal: np.ndarray, after_us: int) -> int:
    """The first tick after `after_us` from which the demand keeps the rates asked for."""
    off = np.abs(rate - goal).max(axis=1) > 1e-6
    late = t > after_us
    bad = np.flatnonzero(late & off)
    last_bad = int(bad[-1]) if bad.size else int(np.flatnonzero(late)[0]) - 1
    assert last_bad + 1 < len(t), "the rates were never reached"
    return int(t[last_bad + 1])


def test_a_move_from_rest_acts_within_50_ms_and_reaches_its_rates_at_the_acceleration_limit():
    goal = np.array([2.0, -0.5])

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 120.0, "el_deg": 40.0})
        async with recording(vss, REF, clock=clock) as rec:
            await clock.sleep(0.2)
            accel, before_us = await _limits(vss)
            op = await c.request("move", {"az_rate_deg_s": goal[0], "el_rate_deg_s": goal[1]})
            await clock.sleep(2.0)
        return op, accel, before_us, rec

    op, accel, before_us, rec = run_lockstep_scenario(START, scenario)
    t, ref, rate = _axes(rec)
    start = op["info"]["start"]
    assert op["info"]["rate_changes"] == "replace_from"
    assert start["accepted_us"] == before_us  # lockstep: accepted at the mount time we read
    held = t < before_us
    assert np.abs(rate[held]).max() == 0.0  # at rest before
    first = _first_effect_us(t, ref, rate, before_us)
    assert 20_000 <= first - before_us <= 50_000
    # no step: the demand leaves from where it was held, at no rate
    k = np.searchsorted(t, first)
    assert np.abs(ref[k] - ref[k - 1]).max() < 0.01 / 3600 and np.abs(rate[k]).max() < 0.01
    # the rates, within what the acceleration limit allows (+ one tick), and no faster
    ramp_s = float(np.max(np.abs(goal) / accel))
    reached = _reached_us(t, rate, goal, first)
    assert (reached - first) / 1e6 <= ramp_s + 2e-4
    assert _within_accel(rec, accel)
    after = t > reached + 300_000  # the encoders follow at the rates
    enc = np.column_stack([_deg(rec["axis.az.position"]), _deg(rec["axis.el.position"])])[after]
    enc_rate = (enc[-1] - enc[0]) / ((t[after][-1] - t[after][0]) * 1e-6)
    assert enc_rate == pytest.approx(goal, rel=1e-4)


def test_a_new_move_changes_the_running_moves_rates_within_50_ms_within_the_limits():
    first_rates, new_rates = np.array([2.0, 0.5]), np.array([-1.0, 0.0])

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 120.0, "el_deg": 40.0})
        op1 = await c.request("move", {"az_rate_deg_s": 2.0, "el_rate_deg_s": 0.5})
        await clock.sleep(2.0)
        replaces0 = (await read_emulator(vss, ["traj.replaces"]))[0]["traj.replaces"]
        async with recording(vss, REF, clock=clock) as rec:
            await clock.sleep(0.3)
            accel, before_us = await _limits(vss)
            op2 = await c.request("move", {"az_rate_deg_s": -1.0, "el_rate_deg_s": 0.0})
            await clock.sleep(2.5)
        replaces = (await read_emulator(vss, ["traj.replaces"]))[0]["traj.replaces"]
        return op1, op2, accel, before_us, rec, replaces - replaces0

    op1, op2, accel, before_us, rec, replaces = run_lockstep_scenario(START, scenario)
    t, ref, rate = _axes(rec)
    assert op2["id"] == op1["id"] and op2["kind"] == "move"  # the same move, not a new one
    change = op2["info"]["last_change"]
    assert change["sent"] == "replace_from" and change["accepted_us"] == before_us
    assert replaces == 1  # the emulator's own count of buffered futures replaced
    assert np.abs(rate[t <= before_us] - first_rates).max() < 1e-9
    first = _first_effect_us(t, ref, rate, before_us)
    assert 20_000 <= first - before_us <= 50_000
    ramp_s = float(np.max(np.abs(new_rates - first_rates) / accel))  # 1 s for az at 3°/s²
    reached = _reached_us(t, rate, new_rates, first)
    assert (reached - first) / 1e6 <= ramp_s + 2e-4
    assert _within_accel(rec, accel)
    assert np.all(rec["mount.state"] == TRACKING)  # never left the trajectory
    assert op2["info"]["az_rate_deg_s"] == -1.0 and op2["info"]["el_rate_deg_s"] == 0.0


def test_zero_rates_ramp_the_move_down_at_once_and_end_it_at_rest():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 200.0, "el_deg": 50.0})
        op = await c.request("move", {"az_rate_deg_s": -1.5, "el_rate_deg_s": 1.0})
        await clock.sleep(3.0)
        async with recording(vss, REF, clock=clock) as rec:
            await clock.sleep(0.2)
            accel, before_us = await _limits(vss)
            await c.request("move", {"az_rate_deg_s": 0.0, "el_rate_deg_s": 0.0})
            done = await c.request("wait", {"id": op["id"]})
            await clock.sleep(1.0)
        return done, accel, before_us, rec

    done, accel, before_us, rec = run_lockstep_scenario(START, scenario)
    t, ref, rate = _axes(rec)
    first = _first_effect_us(t, ref, rate, before_us)
    assert 20_000 <= first - before_us <= 50_000
    at_rest = _reached_us(t, rate, np.zeros(2), first)
    assert (at_rest - first) / 1e6 <= float(np.max(np.array([1.5, 1.0]) / accel)) + 2e-4
    assert _within_accel(rec, accel)
    assert done["phase"] == "done" and "set to 0" in done["info"]["ended"]
    still = t > at_rest
    assert np.ptp(ref[still], axis=0).max() < MAS_DEG  # and it stays there


def test_stop_of_a_move_ramps_down_at_once_and_is_final():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 120.0, "el_deg": 40.0})
        await c.request("move", {"az_rate_deg_s": 2.0})
        await clock.sleep(2.0)
        async with recording(vss, REF, clock=clock) as rec:
            await clock.sleep(0.2)
            accel, before_us = await _limits(vss)
            # a change and a stop sent at the same instant: the stop comes last, and is final
            c2 = vss.client()
            answers = await asyncio.gather(
                c.request("move", {"az_rate_deg_s": 1.0}), c2.request("stop"),
                return_exceptions=True)
            await clock.sleep(3.0)
        status = await c.request("status")
        return answers, accel, before_us, rec, status

    answers, accel, before_us, rec, status = run_lockstep_scenario(START, scenario)
    moved, stopped = answers
    assert not isinstance(moved, Exception) and stopped == {"mount_state": "holding"}
    t, ref, rate = _axes(rec)
    first = _first_effect_us(t, ref, rate, before_us)
    assert first - before_us <= 50_000
    at_rest = _reached_us(t, rate, np.zeros(2), first)
    assert (at_rest - first) / 1e6 <= 2.0 / accel[0] + 2e-4
    assert _within_accel(rec, accel)
    assert np.ptp(ref[t > at_rest], axis=0).max() < MAS_DEG
    assert status["operation"]["phase"] == "aborted"


def test_a_rate_change_plans_the_stop_before_the_elevation_limit_again():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 200.0, "el_deg": 84.0})
        op = await c.request("move", {"az_rate_deg_s": 1.0})
        first_stop = op["info"]["stops_for"]
        await clock.sleep(1.0)
        changed = await c.request("move", {"az_rate_deg_s": 1.0, "el_rate_deg_s": 1.0})
        done = await c.request("wait", {"id": op["id"]})
        v, _ = await read_emulator(vss, ["axis.el.position"])
        return first_stop, changed, done, math.degrees(v["axis.el.position"])

    first_stop, changed, done, el = run_lockstep_scenario(START, scenario)
    assert "cable wrap" in first_stop
    assert changed["id"] == done["id"] and "elevation limit" in changed["info"]["stops_for"]
    assert done["phase"] == "done" and "elevation limit" in done["info"]["ended"]
    assert 89.3 < el <= 89.5 + 1e-3


def test_a_change_that_would_have_to_stop_at_once_is_refused_and_the_move_goes_on():
    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 200.0, "el_deg": 89.6})  # above the 89.5° margin
        op = await c.request("move", {"az_rate_deg_s": 1.0})
        await clock.sleep(1.0)
        with pytest.raises(VssRequestError) as refused:
            await c.request("move", {"az_rate_deg_s": 1.0, "el_rate_deg_s": 0.5})
        status = await c.request("status")
        return op, refused.value, status

    op, refused, status = run_lockstep_scenario(START, scenario)
    assert refused.code == "unreachable" and "elevation limit" in refused.message
    assert "goes on" in refused.message
    running = status["operation"]
    assert running["id"] == op["id"] and running["phase"] == "slewing"
    assert running["info"]["el_rate_deg_s"] == 0.0


def test_a_controller_without_replace_from_starts_each_move_anew_as_before_and_says_so(tmp_path):
    mapping = mapping_without(tmp_path, "traj_replace")

    async def scenario(vss, clock):
        c = vss.client()
        await c.request("slew", {"az_deg": 120.0, "el_deg": 40.0})
        async with recording(vss, REF, rate_hz=1000.0, clock=clock) as rec:
            await clock.sleep(0.2)
            _accel, before_us = await _limits(vss)
            op1 = await c.request("move", {"az_rate_deg_s": 2.0})
            await clock.sleep(6.0)
            op2 = await c.request("move", {"az_rate_deg_s": -1.0})
            await clock.sleep(1.0)
        with pytest.raises(VssRequestError) as zero:
            await c.request("move", {})
        return op1, op2, before_us, rec, zero.value

    op1, op2, before_us, rec, zero = run_lockstep_scenario(START, scenario, mapping_path=mapping)
    assert op1["info"]["rate_changes"] == "restart"
    assert "traj_replace" in op1["info"]["rate_changes_note"]
    assert op2["id"] != op1["id"]  # a new operation, as before
    t, ref, rate = _axes(rec)
    first = _first_effect_us(t, ref, rate, before_us)
    assert first - before_us >= 1_000_000  # after the start lead (1 s in lockstep)
    assert zero.code == "bad_request" and "stop" in zero.message


def test_move_paths_change_rates_without_a_step_and_within_the_acceleration_limits():
    from virtualstar.server.hand_pad import MovePath

    rng = np.random.default_rng(28)
    accel = np.radians([3.0, 2.0])
    for _case in range(20):
        t0 = 1_700_000_000_000_000
        path = MovePath(t0, 1.0, 0.7)
        changes = np.sort(rng.integers(0, 8_000_000, 6)) + t0
        goals = np.radians(rng.uniform(-5, 5, (6, 2)))
        for at_us, goal in zip(changes, goals, strict=True):
            reached = path.change_rates(int(at_us), goal, accel)
            _, before = path.state(np.array([at_us], np.int64))
            need_s = float(np.max(np.abs(goal - before[0]) / accel))
            assert (reached - at_us) / 1e6 == pytest.approx(need_s, abs=2e-6)
        t = t0 + np.arange(0, 12_000_000, 100, dtype=np.int64)  # the emulator's tick
        p, v = path.state(t)
        dt = np.diff(t) * 1e-6
        # rates change no faster than the limits; positions follow the rates (no step: the
        # mean rate over a tick moves them, to a·dt²/4 where the acceleration changes)
        assert np.all(np.abs(np.diff(v, axis=0)) <= accel * dt[:, None] * (1 + 1e-9) + 1e-15)
        mid = 0.5 * (v[1:] + v[:-1]) * dt[:, None]
        assert np.abs(np.diff(p, axis=0) - mid).max() < accel.max() * dt.max() ** 2 / 4 + 1e-15
        assert np.allclose(v[-1], goals[-1], rtol=0, atol=1e-12)  # the last rates kept
