"""A model of the motor current from the motion, fitted on a reference stretch.

On a driven axis the commanded motion dominates the raw current, so the detectors look
at what is left once the motion is explained:

    i ≈ c0 + c1·v + c2·a + Σ_s c_s·tanh(v/s)          inertia, viscous and Coulomb friction
          [+ c·cos(p) + c'·sin(p)]                       gravity imbalance (elevation)
          [+ Σ_k (c_k·cos(kNp) + c'_k·sin(kNp)), k=1,2]  cogging, N periods per revolution

p, v, a: axis angle (rad), rate (rad/s), acceleration (rad/s²) of each segment. The
friction terms use a few smoothing rates on a log scale because the real stiction
curve is not known. The cogging's N is not known either: it is found as the peak of a
Lomb–Scargle periodogram (scipy) of the base model's residual against position, over
the whole recording — a position periodicity is a property of the motor, and the
longer the travel the sharper the peak — while the coefficients are fitted on the
reference stretch only, so a fault after it cannot hide in the fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lombscargle

__all__ = ["CurrentModel", "estimate_cogging_periods", "fit_current_model"]

FRICTION_SMOOTHING_RAD_S = (3e-5, 1e-4, 3e-4)
MIN_COGGING_PERIODS = 8.0  # below: a slow drift of the residual, not a motor property
MAX_COGGING_PERIODS = 1024.0
MIN_COGGING_SHARE = 0.1  # the harmonic must explain this share of the residual variance
MAX_PERIODOGRAM_POINTS = 20_000
# Relative ridge on the scaled columns: the friction terms are nearly collinear over
# tracking rates, and so are the offset and gravity terms over a few degrees of
# elevation; unbounded, the fit cancels large coefficients against each other and
# extrapolates poorly beyond the reference stretch. 3e-4 was chosen on clean recordings
# (a 12-h azimuth night, 20 min of azimuth, 30 min of elevation) and faulty ones: 1e-8
# let a 20-minute elevation run drift by 14 A; 1e-2 blunts a 20 % winding fault to the
# flagging limit.
RIDGE = 3e-4


@dataclass(frozen=True)
class CurrentModel:
    """Fitted coefficients; `predict` gives the current (A) of a motion."""

    coefficients: np.ndarray
    scales: np.ndarray
    gravity: bool
    cogging_periods: float  # 0: no cogging term
    reference_rms_a: float  # residual RMS on the reference stretch

    def predict(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        x = _regressors(p, v, a, self.gravity, self.cogging_periods) / self.scales
        return x @ self.coefficients


def _regressors(p, v, a, gravity: bool, cogging_periods: float) -> np.ndarray:
    cols = [np.ones_like(p), v, a] + [np.tanh(v / s) for s in FRICTION_SMOOTHING_RAD_S]
    if gravity:
        cols += [np.cos(p), np.sin(p)]
    if cogging_periods > 0:
        for k in (1, 2):
            cols += [np.cos(k * cogging_periods * p), np.sin(k * cogging_periods * p)]
    return np.stack(cols, axis=1)


def _lstsq(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (coefficients, column scales) of a ridge-stabilised least-squares fit."""
    scales = np.sqrt(np.mean(x * x, axis=0))
    scales[scales == 0] = 1.0
    xs = x / scales
    gram = xs.T @ xs
    gram += RIDGE * np.trace(gram) / len(gram) * np.eye(len(gram))
    return np.linalg.solve(gram, xs.T @ y), scales


def estimate_cogging_periods(p: np.ndarray, residual: np.ndarray) -> float:
    """Return the cogging periods per revolution seen in `residual` against position `p`,
    or 0 when no periodicity explains enough of it (or the travel is too short to tell)."""
    ok = np.isfinite(p) & np.isfinite(residual)
    p, r = p[ok], residual[ok]
    span = float(np.ptp(p)) if len(p) else 0.0
    if len(p) < 100 or span <= 0:
        return 0.0
    r = r - r.mean()
    step_n = max(1, len(p) // MAX_PERIODOGRAM_POINTS)
    p, r = p[::step_n], r[::step_n]
    lo = max(MIN_COGGING_PERIODS, 2 * math.pi / span)  # at least one period in the travel
    resolution = 2 * math.pi / span / 4
    freqs = np.arange(lo, MAX_COGGING_PERIODS, resolution)[:20_000]
    if len(freqs) == 0:
        return 0.0
    power = lombscargle(p, r, freqs)
    best = float(freqs[int(np.argmax(power))])
    # share of variance the best harmonic explains (a one-frequency least-squares fit)
    x = np.stack([np.cos(best * p), np.sin(best * p)], axis=1)
    coef, *_ = np.linalg.lstsq(x, r, rcond=None)
    share = 1.0 - np.var(r - x @ coef) / max(np.var(r), 1e-300)
    return best if share >= MIN_COGGING_SHARE else 0.0


def fit_current_model(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray,
                      ref: np.ndarray, *, gravity: bool,
                      cogging_periods: float | None = None) -> CurrentModel:
    """Fit the current model on the rows `ref`; `cogging_periods` None estimates it."""
    x = _regressors(p, v, a, gravity, 0.0)
    coef, scales = _lstsq(x[ref], i[ref])
    if cogging_periods is None:
        base = i - (x / scales) @ coef
        first = estimate_cogging_periods(p, base)
        # A fault after the reference (a current step, a ramp) leaks into the periodogram
        # and can move its peak: estimate again on the rows that the model with the first
        # estimate explains as well as it explains the reference.
        x1 = _regressors(p, v, a, gravity, first)
        c1, s1 = _lstsq(x1[ref], i[ref])
        dev = np.abs(i - (x1 / s1) @ c1)
        usual = dev <= 2.0 * float(np.max(dev[ref])) if ref.any() else np.ones_like(ref)
        cogging_periods = estimate_cogging_periods(p[usual], base[usual])
    if cogging_periods > 0:
        x = _regressors(p, v, a, gravity, cogging_periods)
        coef, scales = _lstsq(x[ref], i[ref])
    res = i[ref] - (x[ref] / scales) @ coef
    return CurrentModel(coef, scales, gravity, float(cogging_periods),
                        float(np.sqrt(np.mean(res * res))) if len(res) else math.nan)
