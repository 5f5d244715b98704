"""The current detector's scale statistics on a synthetic motor whose answer is known.

The synthetic azimuth axis is the emulator's law written out independently (torque =
inertia·a + viscous·v + Coulomb·clip(v/v_s), current = torque / kt), with a night that
the mean-residual statistic cannot see a small fault in: 10-s slews whose current changes
sign (a scale error averages out of their mean), and, after the reference, a sidereal
track at a speed the reference never held (not scored by the mean residual at all).
"""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_store import settled_track_scores, write_store

from virtualstar.anomalies import detect_anomalies

T0_US = 1_772_395_200_000_000
RATE_HZ = 1000.0
NIGHT_S = 1800.0
FAULT_S = 1100.0  # after the 15-minute reference
INERTIA_KG_M2, VISCOUS_NM_S, COULOMB_NM, SMOOTH_RAD_S, KT_NM_A = 36.0, 4.0, 3.0, 1e-4, 12.0
SLEW_S, SLEW_ACCEL_RAD_S2 = 10.0, 0.02  # a triangle: 0.1 rad/s at its middle, 0.5 rad
CYCLE_S = 150.0  # a slew, then a track
REFERENCE_TRACKS_RAD_S = (2e-5, 8e-5)  # alternated during the reference
LATER_TRACK_RAD_S = 4.5e-5  # afterwards: a speed the reference never held (±10 %)


def _rate_rad_s(ts: np.ndarray, one_way: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(velocity, acceleration) of the night: each cycle a slew (alternating direction)
    then a track; `one_way`: during the reference (900 s) every slew and track goes the
    negative way."""
    k = np.floor(ts / CYCLE_S).astype(int)
    u = ts - k * CYCLE_S
    direction = np.where(k % 2 == 0, 1.0, -1.0)
    track = np.where(ts < 900.0, np.where(k % 2 == 0, *REFERENCE_TRACKS_RAD_S),
                     LATER_TRACK_RAD_S)
    if one_way:
        direction = np.where(ts < 900.0, -1.0, direction)
        track = np.where(ts < 900.0, -track, track)
    half = SLEW_S / 2
    slewing = u < SLEW_S
    accel = np.where(slewing, np.where(u < half, 1.0, -1.0) * SLEW_ACCEL_RAD_S2 * direction,
                     0.0)
    v_slew = direction * SLEW_ACCEL_RAD_S2 * np.where(u < half, u, SLEW_S - u)
    return np.where(slewing, v_slew + track, track), accel


def _night(path, *, winding_loss: float = 0.0, friction_growth_nm_h: float = 0.0,
           one_way: bool = False, detect: bool = True):
    ts = np.arange(round(NIGHT_S * RATE_HZ)) / RATE_HZ
    v, a = _rate_rad_s(ts, one_way)
    p = 0.3 + np.cumsum(v) / RATE_HZ
    after = np.clip(ts - FAULT_S, 0.0, None)
    coulomb = COULOMB_NM + friction_growth_nm_h * after / 3600.0
    torque = INERTIA_KG_M2 * a + VISCOUS_NM_S * v + coulomb * np.clip(v / SMOOTH_RAD_S, -1, 1)
    kt = np.where(ts >= FAULT_S, KT_NM_A * (1.0 - winding_loss), KT_NM_A)
    current = torque / kt + np.random.default_rng(5).normal(0.0, 2e-4, len(ts))
    reader = write_store(path, T0_US, ts, {"axis.az.position": p, "axis.az.current": current},
                         RATE_HZ)
    first, last = reader.time_range()
    return detect_anomalies(reader, first, last + 1) if detect else reader


def _current_flags(report):
    return [x for x in report.anomalies if x.kind == "current" and x.axis == "az"]


def _later_track_scores(report, from_s: float) -> np.ndarray:
    """The current detector's scores of the windows wholly inside the tracks at the speed
    the reference never held, from `from_s` on (20 s after each slew: settled): windows
    the mean residual cannot score, so a score there is the scale statistics'."""
    return settled_track_scores(report, "az current", T0_US, from_s, CYCLE_S, SLEW_S)


@pytest.fixture(scope="module")
def clean_report(tmp_path_factory):
    return _night(tmp_path_factory.mktemp("clean") / "s")


def test_a_clean_synthetic_night_with_an_unheld_sidereal_speed_raises_no_flag(clean_report):
    assert clean_report.anomalies == []
    # the unheld speed is scored (finite scores), not skipped, and well inside the limit
    scores = _later_track_scores(clean_report, 900.0)
    assert np.all(np.isfinite(scores)) and scores.max() < 0.5


def test_a_known_gain_loss_is_found_in_slews_and_at_an_unheld_speed(tmp_path):
    # 6 % of kt lost: the current is 1/0.94 = +6.4 % everywhere after FAULT_S
    report = _night(tmp_path / "s", winding_loss=0.06)
    flags = _current_flags(report)
    assert flags, report.anomalies
    assert not any(x.end_us <= T0_US + FAULT_S * 1e6 for x in report.anomalies)
    first = min(x.start_us for x in flags)
    assert T0_US + (FAULT_S - 10.0) * 1e6 <= first <= T0_US + (FAULT_S + 30.0) * 1e6
    assert np.all(_later_track_scores(report, FAULT_S) >= 1.0)


def test_the_gain_statistic_is_the_scale_of_the_current_over_its_model():
    from virtualstar.anomalies.current_detector import CurrentDetector
    from virtualstar.anomalies.detectors import DetectorConfig

    det = CurrentDetector("az", ("p", "i"), DetectorConfig(), 0.256)
    rng = np.random.default_rng(2)
    model = rng.normal(0.0, 0.3, 200)  # a current changing sign, as in a slew
    friction = 0.25 * np.sign(model)
    resid = (1 / 0.94 - 1) * model  # 6 % of kt lost
    arrays = {"resid": resid, "allowance": np.zeros(200), "uncertainty": np.zeros(200),
              "model": model, "friction": friction, "use": np.ones(200, bool),
              "use_any": np.ones(200, bool)}
    stats = det.stats(arrays, np.arange(0, 200, 40))
    assert stats["gain"] == pytest.approx(np.full(5, 1 / 0.94 - 1), rel=1e-9)
    assert np.all(np.abs(stats["mean"]) < 0.5 * np.abs(stats["gain"]) * 0.3)


def test_a_known_friction_growth_at_an_unheld_sidereal_speed_is_found(tmp_path):
    # 2.5 N·m/h on 3 N·m Coulomb friction; after the fault the axis tracks only at
    # 4.5e-5 rad/s, a speed the reference never held, between slews
    report = _night(tmp_path / "s", friction_growth_nm_h=2.5)
    flags = _current_flags(report)
    assert flags, report.anomalies
    assert min(x.start_us for x in flags) >= T0_US + (FAULT_S - 10.0) * 1e6
    # from 400 s on (+0.28 N·m, 9 % of the dry friction) every such window is flagged
    assert np.all(_later_track_scores(report, FAULT_S + 400.0) >= 1.0)


def test_a_reference_that_moved_one_way_only_covers_no_speed_the_other_way(tmp_path):
    # every slew and track of the reference goes the negative way: the dry friction's sign
    # flips the other way, so the split between the offset and the friction is the
    # model's guess there, and the mean residual must not score it as covered
    from virtualstar.anomalies.current_detector import CurrentDetector
    from virtualstar.anomalies.detectors import DetectorConfig
    from virtualstar.anomalies.phases import PhaseLabeller
    from virtualstar.anomalies.pipeline import Detection
    from virtualstar.anomalies.reference import automatic_reference, fault_times_us, usable
    from virtualstar.anomalies.report import _events, read_segments

    reader = _night(tmp_path / "s", one_way=True, detect=False)
    first, last = reader.time_range()
    cfg = DetectorConfig()
    seg, axes, rate = read_segments(reader, first, last + 1)
    events = _events(reader, first, last + 1)
    phase = PhaseLabeller(axes, events, config=cfg.phases).label(seg)
    det = Detection(axes, rate, cfg)
    chunk = det.chunk(seg, phase)
    ref, _ = automatic_reference(seg.t_first_us, seg.t_last_us, phase, chunk.valid,
                                 fault_times_us(events), cfg.reference)
    det.fit(chunk, ref.mask(seg.t_first_us, seg.t_last_us) & usable(phase, chunk.valid))
    cd = next(d for d in det.detectors if isinstance(d, CurrentDetector))
    assert np.isfinite(cd.saturated_rad_s[-1]) and cd.saturated_rad_s[1] == np.inf
    _, v, _, _ = cd._motion(chunk)
    covered = cd.values(chunk)["covered"]
    fast = np.abs(v) > 2 * cd.saturated_rad_s[-1]
    assert covered[fast & (v < 0)].all() and not covered[fast & (v > 0)].any()
    assert detect_anomalies(reader, first, last + 1).anomalies == []
