"""A model of the motor current from the motion, fitted on the reference stretch.

On a driven axis the commanded motion dominates the raw current, so the detectors look
at what is left once the motion is explained:

    i ≈ c0 + c1·v + c2·a + Σ_s c_s·clip(v/s, −1, 1)      inertia, viscous and dry friction
          [+ c·cos(p) + c'·sin(p)]                        gravity imbalance (elevation)
          [+ Σ_k (c_k·cos(kNp) + c'_k·sin(kNp)), k=1,2]   cogging, N periods per revolution

p, v, a: the axis angle (rad), rate (rad/s) and acceleration (rad/s²) of each segment
(a least-squares parabola through its samples). The friction curve of a real bearing is
not known, so it is a linear spline in v with knots on a log scale from 10 µrad/s (a
fraction of the sidereal rate) to 3 mrad/s: any monotone friction curve, Stribeck's
included, is a sum of such ramps. The cogging's N is an integer (a motor's cogging
repeats every revolution): the candidates are the highest peaks of a Lomb–Scargle
periodogram (scipy) of the base model's residual against position at whole N, and the
one whose full fit explains the reference best wins — the periodogram alone cannot tell
N from N ± 1 over the short travel of an elevation axis in 15 minutes, the joint fit
can. Everything is fitted on the reference only, so a fault after it cannot hide in the
fit, and live detection fits the same model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lombscargle

__all__ = ["CurrentModel", "estimate_cogging_periods", "fit_current_model"]

FRICTION_KNOTS_RAD_S = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3)
MIN_COGGING_PERIODS = 8  # below: a slow drift of the residual, not a motor property
MAX_COGGING_PERIODS = 1024
COGGING_CANDIDATES = 8  # periodogram peaks whose neighbourhoods are fitted in full
MIN_COGGING_SHARE = 0.1  # the harmonic must explain this share of the residual variance
MAX_PERIODOGRAM_POINTS = 20_000
# Relative ridge on the scaled columns: the friction ramps are nearly collinear where
# the reference holds few speeds, and so are the offset and gravity terms over a few
# degrees of elevation; unbounded, the fit cancels large coefficients against each
# other. 1e-5 was chosen on clean VSS nights of the tuning set (docs/anomalies.md): 3e-4
# (the value of the sine-experiment days) biased the gravity term by 0.015 A on
# elevation blocks outside the reference's elevations, 1e-7 let the ramps swing by
# 0.05 A between the speeds the reference held.
RIDGE = 1e-5


@dataclass(frozen=True)
class CurrentModel:
    """Fitted coefficients; `predict` gives the current (A) of a motion."""

    coefficients: np.ndarray
    scales: np.ndarray
    gravity: bool
    cogging_periods: int  # 0: no cogging term
    reference_rms_a: float  # residual RMS on the rows it was fitted on

    def predict(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        x = _regressors(p, v, a, self.gravity, self.cogging_periods) / self.scales
        return x @ self.coefficients

    def slope_a_per_rad_s(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """d(current)/d|v| of the model at each motion (A per rad/s): how much the current
        changes with the speed there (the friction curve's steepness)."""
        dv = np.maximum(np.abs(v) * 0.05, 1e-7)
        up = self.predict(p, v + np.sign(v + 1e-30) * dv, a)
        down = self.predict(p, v - np.sign(v + 1e-30) * dv, a)
        return np.abs(up - down) / (2 * dv)


def _regressors(p, v, a, gravity: bool, cogging_periods: int) -> np.ndarray:
    cols = [np.ones_like(p), v, a] + [np.clip(v / s, -1.0, 1.0) for s in FRICTION_KNOTS_RAD_S]
    if gravity:
        cols += [np.cos(p), np.sin(p)]
    if cogging_periods > 0:
        for k in (1, 2):
            cols += [np.cos(k * cogging_periods * p), np.sin(k * cogging_periods * p)]
    return np.stack(cols, axis=1)


def _lstsq(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (coefficients, column scales) of a ridge-stabilised least-squares fit."""
    scales = np.sqrt(np.mean(x * x, axis=0)) if len(x) else np.ones(x.shape[1])
    scales[scales == 0] = 1.0
    xs = x / scales
    gram = xs.T @ xs
    gram += RIDGE * max(np.trace(gram), 1e-30) / len(gram) * np.eye(len(gram))
    return np.linalg.solve(gram, xs.T @ y), scales


def _rms(x: np.ndarray, y: np.ndarray) -> float:
    coef, scales = _lstsq(x, y)
    r = y - (x / scales) @ coef
    return float(np.sqrt(np.mean(r * r)))


def _candidates(p: np.ndarray, r: np.ndarray) -> list[int]:
    """Whole N near the highest peaks of the periodogram of `r` against position `p`."""
    step_n = max(1, len(p) // MAX_PERIODOGRAM_POINTS)
    p, r = p[::step_n], r[::step_n] - r[::step_n].mean()
    span = float(np.ptp(p))
    lo = max(MIN_COGGING_PERIODS, math.ceil(2 * math.pi / span))  # a period in the travel
    freqs = np.arange(lo, MAX_COGGING_PERIODS + 1, dtype=np.float64)
    if len(freqs) == 0 or not np.any(r):
        return []
    power = lombscargle(p, r, freqs)
    best = np.argsort(power)[-COGGING_CANDIDATES:]
    return sorted({int(freqs[k]) + d for k in best for d in (-1, 0, 1)
                   if lo <= int(freqs[k]) + d <= MAX_COGGING_PERIODS})


def estimate_cogging_periods(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray, *,
                             gravity: bool) -> int:
    """Return the cogging periods per revolution that best explain `i` (see the module
    docstring), or 0 when none explains MIN_COGGING_SHARE of what the base model leaves
    (or the travel is too short to tell)."""
    ok = np.isfinite(p) & np.isfinite(v) & np.isfinite(a) & np.isfinite(i)
    p, v, a, i = p[ok], v[ok], a[ok], i[ok]
    if len(p) < 100 or float(np.ptp(p)) <= 0:
        return 0
    x0 = _regressors(p, v, a, gravity, 0)
    coef, scales = _lstsq(x0, i)
    base = i - (x0 / scales) @ coef
    base_var = float(np.mean(base * base))
    best, best_rms = 0, math.inf
    for n in _candidates(p, base):
        rms = _rms(_regressors(p, v, a, gravity, n), i)
        if rms < best_rms:
            best, best_rms = n, rms
    if best == 0 or base_var <= 0 or 1.0 - best_rms ** 2 / base_var < MIN_COGGING_SHARE:
        return 0
    return best


def fit_current_model(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray,
                      rows: np.ndarray, *, gravity: bool,
                      cogging_periods: int | None = None) -> CurrentModel:
    """Fit the current model on `rows`; `cogging_periods` None estimates N from them."""
    if cogging_periods is None:
        cogging_periods = estimate_cogging_periods(p[rows], v[rows], a[rows], i[rows],
                                                   gravity=gravity)
    n = int(round(cogging_periods))
    x = _regressors(p[rows], v[rows], a[rows], gravity, n)
    coef, scales = _lstsq(x, i[rows])
    res = i[rows] - (x / scales) @ coef
    return CurrentModel(coef, scales, gravity, n,
                        float(np.sqrt(np.mean(res * res))) if len(res) else math.nan)
