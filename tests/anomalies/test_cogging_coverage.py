"""The cogging's N on a reference that held the axis at a few clustered angles.

A fresh night (pattern 32's elevation) held its reference at four clusters of elevation
plus slews; the model took N = 247 (the emulator's is 96) from a periodogram that aliased,
judged it certain because N ± 1 fitted worse, and flagged a clean culmination between the
clusters on every night of that pattern. The synthetic elevation here is the emulator's
law written out independently — torque = J·a + c·v + Fc·clip(v/v_s) + G·cos(el) − C·sin(N·el),
current = torque / kt, with the segment mean of the cogging wave (sinc of the travel within
a segment) — so the right answer is known.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic_store import settled_track_scores, write_store

from virtualstar.anomalies import detect_anomalies
from virtualstar.anomalies.current_model import fit_current_model
from virtualstar.anomalies.detectors import DetectorConfig

J_KG_M2, VISCOUS_NM_S, COULOMB_NM, SMOOTH_RAD_S, KT_NM_A = 36.0, 4.0, 2.0, 1e-4, 12.0
GRAVITY_NM, COGGING_NM, COGGING_N = 6.0, 0.4, 96
SEGMENT_S = 0.256
SIDEREAL_RAD_S = 5e-5
UNHELD_DEG = np.linspace(15.0, 85.0, 2000)


def _current_a(p, v, a, segment_s: float = SEGMENT_S) -> np.ndarray:
    cogging = COGGING_NM * np.sin(COGGING_N * p) * np.sinc(
        COGGING_N * v * segment_s / (2 * math.pi))
    return (J_KG_M2 * a + VISCOUS_NM_S * v + COULOMB_NM * np.clip(v / SMOOTH_RAD_S, -1, 1)
            + GRAVITY_NM * np.cos(p) - cogging) / KT_NM_A


def _tracks(rng, centres_deg, width_deg: float, n: int = 3500):
    """Segments of sidereal tracks (either way) at the given clusters of elevation."""
    centres = np.radians(centres_deg)
    p = centres[np.arange(n) % len(centres)] + np.radians(width_deg) * rng.uniform(
        -0.5, 0.5, n)
    v = SIDEREAL_RAD_S * rng.choice([-1.0, 1.0], n) * rng.uniform(0.8, 1.2, n)
    return p, v, np.zeros(n)


def _fit(p, v, a, seed: int):
    i = _current_a(p, v, a) + np.random.default_rng(seed).normal(0.0, 3e-4, len(p))
    return fit_current_model(p, v, a, i, np.ones(len(p), bool), gravity=True,
                             segment_s=SEGMENT_S)


def _unheld_error_and_uncertainty(model):
    q = np.radians(UNHELD_DEG)
    v, a = np.full(len(q), SIDEREAL_RAD_S), np.zeros(len(q))
    return (np.abs(model.predict(q, v, a) - _current_a(q, v, a)),
            model.cogging_uncertainty_a(q, v, a))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_reference_held_at_a_few_clustered_angles_leaves_the_cogging_n_uncertain(seed):
    rng = np.random.default_rng(seed)
    p, v, a = _tracks(rng, [20.0, 40.0, 60.0, 80.0], 0.1)  # 0.03 cogging periods each
    model = _fit(p, v, a, seed)
    assert not model.cogging_certain
    assert model.cogging_alternatives  # the rival N it could not rule out
    err, unc = _unheld_error_and_uncertainty(model)
    # whatever N won, the model is wrong between the clusters (by up to 2 × the cogging
    # amplitude, 0.067 A, and the gravity fitted with it) ...
    assert err.max() > 0.005
    # ... and the uncertainty covers it with the detector's coverage factor (2), ...
    assert np.all(err <= DetectorConfig().coverage_factor * unc + 1e-3)
    # ... while at the angles the reference held the cogging adds no allowance
    assert model.cogging_uncertainty_a(p[:200], v[:200], a[:200]).max() < 0.1 * unc.max()


def test_a_reference_spread_over_many_angles_pins_the_right_n_and_is_certain():
    rng = np.random.default_rng(4)
    n = 3500
    p = np.radians(rng.uniform(15.0, 85.0, n))
    v = SIDEREAL_RAD_S * rng.choice([-1.0, 1.0], n)
    model = _fit(p, v, np.zeros(n), 4)
    assert model.cogging_periods == COGGING_N and model.cogging_certain
    err, unc = _unheld_error_and_uncertainty(model)
    assert np.all(unc == 0.0) and err.max() < 1e-3


def test_slews_that_show_the_cogging_pin_n_between_clustered_tracks():
    # pattern 32's case: tracks at four clusters, slews everywhere between them slow
    # enough that a segment keeps most of the cogging wave (0.01-0.1 rad/s: sinc ≥ 0.77)
    rng = np.random.default_rng(5)
    p, v, a = _tracks(rng, [17.0, 41.0, 50.0, 86.0], 1.0)
    m = 400
    p = np.r_[p, np.radians(rng.uniform(15.0, 88.0, m))]
    v = np.r_[v, rng.choice([-1.0, 1.0], m) * rng.uniform(0.01, 0.1, m)]
    a = np.r_[a, rng.uniform(-0.02, 0.02, m)]
    model = _fit(p, v, a, 5)
    assert model.cogging_periods == COGGING_N and model.cogging_certain
    err, _ = _unheld_error_and_uncertainty(model)
    assert err.max() < 2e-3


# -- a whole night through the detector ---------------------------------------------------

T0_US = 1_772_395_200_000_000
RATE_HZ = 1000.0
NIGHT_S = 1800.0
FAULT_S = 1100.0
SLEW_S = 10.0
CYCLE_S = 150.0
# the reference (first 900 s) tracks at three clustered elevations; afterwards the axis
# tracks between them (58-62°), where the reference never held it slowly
REFERENCE_DEG = (20.0, 45.0, 80.0)
LATER_DEG = 58.0


def _el_night(path, *, winding_loss: float = 0.0):
    ts = np.arange(round(NIGHT_S * RATE_HZ)) / RATE_HZ
    k = np.floor(ts / CYCLE_S).astype(int)
    targets = np.where(k * CYCLE_S < 900.0,
                       np.radians(np.array(REFERENCE_DEG))[k % len(REFERENCE_DEG)],
                       np.radians(LATER_DEG + 2.0 * (k % 2)))
    track = np.where(k % 2 == 0, SIDEREAL_RAD_S, -0.8 * SIDEREAL_RAD_S)
    u = ts - k * CYCLE_S
    # each cycle: a slew from where the last track ended to the target (a triangle of
    # speed over SLEW_S), then a sidereal track; positions by integrating the rate
    v = np.empty_like(ts)
    a = np.empty_like(ts)
    p = np.empty_like(ts)
    start = math.radians(REFERENCE_DEG[-1])
    half = SLEW_S / 2
    for c in range(int(k.max()) + 1):
        rows = k == c
        uu = u[rows]
        dist = targets[rows][0] - start
        acc = 4.0 * dist / SLEW_S ** 2
        slewing = uu < SLEW_S
        v[rows] = np.where(slewing, acc * np.where(uu < half, uu, SLEW_S - uu), track[rows])
        a[rows] = np.where(slewing, np.where(uu < half, acc, -acc), 0.0)
        p[rows] = np.where(slewing, start + np.where(
            uu < half, 0.5 * acc * uu ** 2, dist - 0.5 * acc * (SLEW_S - uu) ** 2),
            targets[rows][0] + track[rows] * (uu - SLEW_S))
        start = p[rows][-1]
    kt = np.where(ts >= FAULT_S, KT_NM_A * (1.0 - winding_loss), KT_NM_A)
    current = _current_a(p, v, a, 0.0) * KT_NM_A / kt + \
        np.random.default_rng(6).normal(0.0, 2e-4, len(ts))
    reader = write_store(path, T0_US, ts, {"axis.el.position": p, "axis.el.current": current},
                         RATE_HZ)
    first, last = reader.time_range()
    return detect_anomalies(reader, first, last + 1)


def _later_track_scores(report, from_s: float) -> np.ndarray:
    return settled_track_scores(report, "el current", T0_US, from_s, CYCLE_S, SLEW_S)


@pytest.fixture(scope="module")
def clean_el_report(tmp_path_factory):
    return _el_night(tmp_path_factory.mktemp("clean_el") / "s")


def test_a_clean_night_whose_reference_held_clustered_elevations_raises_no_flag(
        clean_el_report):
    assert clean_el_report.anomalies == []
    scores = _later_track_scores(clean_el_report, 900.0)
    # the tracks between the clusters are scored, and well inside the limit
    assert np.mean(np.isfinite(scores)) > 0.9 and np.nanmax(scores) < 0.5


def test_a_winding_fault_is_still_found_after_a_clustered_reference(tmp_path):
    report = _el_night(tmp_path / "s", winding_loss=0.06)
    flags = [x for x in report.anomalies if x.kind == "current" and x.axis == "el"]
    assert flags, report.anomalies
    assert not any(x.end_us <= T0_US + FAULT_S * 1e6 for x in report.anomalies)
    first = min(x.start_us for x in flags)
    assert first <= T0_US + (FAULT_S + 60.0) * 1e6
