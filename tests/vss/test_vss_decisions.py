"""The VSS's pure decisions: which pass to join, what the phases allow, when to resume, sky error.

No mount and no event loop: synthetic inputs whose answer is known.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from virtualstar.server.exceptions import (
    MountFault,
    MountUnavailable,
    NotArrived,
    TargetUnreachable,
    TrackingLost,
)
from virtualstar.server.operations import (
    TERMINAL,
    TRANSITIONS,
    IllegalTransition,
    Operation,
    Phase,
    Resume,
    resume_decision,
)
from virtualstar.server.pass_selection import PassWindow, choose_pass
from virtualstar.server.tracking_errors import TrackingErrorHistory

S = 1_000_000  # µs per second
NOW = 1_716_060_000 * S


def window(rise_s: float | None, culm_s: float, set_s: float | None, el: float = 60.0):
    return PassWindow(None if rise_s is None else NOW + int(rise_s * S),
                      None if set_s is None else NOW + int(set_s * S), NOW + int(culm_s * S), el)


def constant(seconds: float):
    return lambda join_us: seconds


# ---------------------------------------------------------------------- pass selection
def test_a_pass_past_culmination_with_enough_left_is_joined_after_the_preparation_time():
    in_progress = window(-260, -40, 215)  # culminated 40 s ago, sets in 215 s
    later = window(5400, 5700, 6000)
    choice = choose_pass([in_progress, later], NOW, prepare_s=constant(25.0))
    assert choice.window is in_progress and choice.in_progress
    assert choice.join_us == NOW + 25 * S
    assert choice.remaining_s == pytest.approx(190.0)


def test_a_pass_in_progress_with_too_little_left_gives_way_to_the_next_one():
    nearly_set = window(-500, -200, 40)
    later = window(5400, 5700, 6000)
    choice = choose_pass([nearly_set, later], NOW, prepare_s=constant(25.0), min_track_s=30.0)
    assert choice.window is later and not choice.in_progress
    assert choice.join_us == later.rise_us  # the mount is ready long before the rise


def test_a_pass_risen_before_the_prediction_began_is_joined_too():
    choice = choose_pass([window(None, 300, 600)], NOW, prepare_s=constant(10.0))
    assert choice.in_progress and choice.join_us == NOW + 10 * S


def test_a_rise_sooner_than_the_mount_can_be_ready_joins_late_and_says_so():
    choice = choose_pass([window(5, 200, 400)], NOW, prepare_s=constant(30.0))
    assert choice.join_us == NOW + 30 * S and choice.in_progress


def test_the_preparation_time_is_refined_for_where_the_satellite_is_at_the_join():
    # the farther the join, the farther the satellite has moved: 20 s + 0.1 s per second
    def prepare(join_us: int) -> float:
        return 20.0 + 0.1 * (join_us - NOW) / S

    choice = choose_pass([window(-100, 50, 300)], NOW, prepare_s=prepare)
    # fixed point of j = 20 + 0.1 j: j = 22.2 s (three rounds come within 0.03 s)
    assert (choice.join_us - NOW) / S == pytest.approx(20 / 0.9, abs=0.05)


def test_no_pass_at_all_or_only_passes_without_a_set_give_none():
    assert choose_pass([], NOW, prepare_s=constant(1.0)) is None
    assert choose_pass([window(100, 400, None)], NOW, prepare_s=constant(1.0)) is None
    assert choose_pass([window(-600, -300, -10)], NOW, prepare_s=constant(1.0)) is None


# ---------------------------------------------------------------------- phases
def test_every_phase_has_a_row_and_terminal_phases_lead_nowhere():
    assert set(TRANSITIONS) == set(Phase)
    for phase in TERMINAL:
        assert TRANSITIONS[phase] == frozenset()
    for phase, targets in TRANSITIONS.items():
        if phase not in TERMINAL:
            assert {Phase.FAILED, Phase.ABORTED} <= targets, phase


def test_done_is_reached_only_after_a_verified_hold_a_measurement_or_coming_to_rest():
    before_done = {p for p, targets in TRANSITIONS.items() if Phase.DONE in targets}
    assert before_done == {Phase.SETTLING, Phase.MEASURING, Phase.ENDING}


def test_a_phase_change_outside_the_table_is_refused():
    op = Operation(1, "track", "Vega")
    op.advance(Phase.PREPARING)
    with pytest.raises(IllegalTransition, match="preparing -> tracking"):
        op.advance(Phase.TRACKING)
    op.advance(Phase.INTERRUPTED)
    op.advance(Phase.PREPARING)
    assert op.as_dict()["phase"] == "preparing"


# ---------------------------------------------------------------------- resuming
@pytest.mark.parametrize(("error", "resumable", "resumes", "expected"), [
    (MountUnavailable("line cut"), True, 0, Resume.WHEN_CONNECTED),
    (TrackingLost("buffer ran dry"), True, 0, Resume.NOW),
    (TrackingLost("buffer ran dry"), True, 10, Resume.NO),  # gives up after MAX_RESUMES
    (TrackingLost("buffer ran dry"), False, 0, Resume.NO),  # a slew or park is not resumed
    (MountFault("encoder"), True, 0, Resume.NO),
    (NotArrived("64° off", 230_000.0), True, 0, Resume.NO),
    (TargetUnreachable("set"), True, 0, Resume.NO),
])
def test_only_a_lost_mount_or_an_underrun_resumes_a_track(error, resumable, resumes, expected):
    assert resume_decision(error, resumable=resumable, resumes=resumes) is expected


# ---------------------------------------------------------------------- on-sky error
def test_the_on_sky_error_adds_rate_times_clock_offset_in_quadrature_and_linearly_at_the_peak():
    h = TrackingErrorHistory()
    t = NOW + np.arange(0, 10 * S, 1000, dtype=np.int64)  # 10 s at 1 kHz
    az_err = np.full(t.size, 0.3)  # arcsec, at el 0: on the sky as is
    h.add(t, az_err, np.zeros(t.size), np.zeros(t.size))
    h.note_rates(t[::50], np.full(t[::50].size, 15.0))  # a star: 15″/s
    h.note_clock_offset(int(t[0]), 2_000)  # the clock 2 ms off: 0.03″ on the sky
    s = h.stats(int(t[0]), int(t[-1]) + 1)
    clock = 15.0 * 2e-3
    assert s.rms_arcsec == pytest.approx(0.3)
    assert s.on_sky_rms_arcsec == pytest.approx(math.hypot(0.3, clock))
    assert s.on_sky_peak_arcsec == pytest.approx(0.3 + clock)
    assert s.clock_error_peak_arcsec == pytest.approx(clock)
    assert s.clock_offset_us == 2_000


def test_between_two_clock_measurements_the_larger_offset_bounds_the_drift():
    h = TrackingErrorHistory()
    t = NOW + np.arange(0, 20 * S, 1000, dtype=np.int64)
    h.add(t, np.zeros(t.size), np.zeros(t.size), np.zeros(t.size))
    h.note_rates(t[::100], np.full(t[::100].size, 1000.0))
    h.note_clock_offset(int(t[0]), 0)  # just synced
    h.note_clock_offset(int(t[0]) + 10 * S, 40)  # 40 µs of drift before the next sync
    h.note_clock_offset(int(t[0]) + 10 * S + 20_000, 0)  # synced again
    first = h.stats(int(t[0]), int(t[0]) + 10 * S)
    assert first.clock_error_peak_arcsec == pytest.approx(1000.0 * 40e-6)
