"""The current model's two searches solve many least-squares fits together from shared
normal equations (`friction_fits` over every friction shape and knee, `scan_cogging_periods`
over every cogging N). Each candidate's residual must be the one numpy's own least
squares (an SVD of the candidate's whole design, no shared pieces) leaves."""

from __future__ import annotations

import numpy as np
import pytest

from virtualstar.anomalies.current_model import (
    FRICTION_KNEES_RAD_S,
    FRICTION_SHAPES,
    Friction,
    _regressors,
    fit_friction,
    friction_fits,
    scan_cogging_periods,
)

SEGMENT_S = 0.255
# The ridge (current_model.RIDGE, 1e-7 of the scaled trace) moves a residual RMS by far
# less than this; the searches' sums in another order by far less still.
RMS_REL = 1e-6


def _axis(seed: int, n: int = 3000):
    """A synthetic elevation axis: tracks through the friction knee, a few slews, a
    96-period cogging, gravity; noise 0.2 mA."""
    rng = np.random.default_rng(seed)
    v = rng.uniform(-2e-3, 2e-3, n)
    v[::40] = 0.05  # slews: the cogging fades out of their segments
    v[::97] = 0.0
    a = rng.normal(0.0, 1e-3, n)
    p = 0.3 + np.cumsum(np.abs(v)) * SEGMENT_S
    i = (0.02 + 3.0 * v + 0.4 * a + 0.2 * np.tanh(v / 3e-4) + 0.5 * np.cos(p)
         + 0.003 * np.cos(96 * p) * np.sinc(96 * v * SEGMENT_S / (2 * np.pi))
         + rng.normal(0.0, 2e-4, n))
    return p, v, a, i


def _lstsq_rms(x: np.ndarray, y: np.ndarray) -> float:
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ coef
    return float(np.sqrt(np.mean(r * r)))


@pytest.mark.parametrize("cogging_periods", [0, 96])
def test_the_friction_search_leaves_each_candidate_the_residual_of_its_own_fit(
        cogging_periods):
    p, v, a, i = _axis(1)
    fits = friction_fits(p, v, a, i, gravity=True, cogging_periods=cogging_periods,
                         segment_s=SEGMENT_S)
    assert [f for f, *_ in fits] == [Friction(s, k) for s in FRICTION_SHAPES
                                     for k in FRICTION_KNEES_RAD_S]
    for friction, coef, scales, rms in fits:
        x = _regressors(p, v, a, True, cogging_periods, friction, SEGMENT_S)
        truth = _lstsq_rms(x, i)
        assert rms == pytest.approx(truth, rel=RMS_REL), friction
        # the coefficients and scales predict as the fit they stand for
        r = i - (x / scales) @ coef
        assert float(np.sqrt(np.mean(r * r))) == pytest.approx(truth, rel=RMS_REL)
    # the truth's shape wins, at the knee of the grid nearest the truth's 3e-4 rad/s
    best = fit_friction(p, v, a, i, gravity=True, cogging_periods=cogging_periods,
                        segment_s=SEGMENT_S)
    assert best.shape == "tanh"
    assert best.knee_rad_s == pytest.approx(3e-4, rel=0.12)


def test_the_cogging_scan_leaves_each_n_the_residual_of_its_own_fit():
    p, v, a, i = _axis(2, n=1800)  # under SCAN_POINTS: the scan fits every row
    friction = Friction("tanh", 3e-4)
    x0 = _regressors(p, v, a, True, 0, friction)
    ns, rms = scan_cogging_periods(p, v, x0, i, SEGMENT_S)
    assert ns[-1] == 1024 and len(ns) == len(rms)
    for k in range(0, len(ns), 37):  # a spread of N over the whole scan, and the truth's
        n = int(ns[k])
        truth = _lstsq_rms(_regressors(p, v, a, True, n, friction, SEGMENT_S), i)
        assert rms[k] == pytest.approx(truth, rel=RMS_REL), n
    assert int(ns[np.argmin(rms)]) == 96
