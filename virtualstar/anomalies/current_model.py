"""A model of the motor current from the motion, fitted on the reference stretch.

On a driven axis the commanded motion dominates the raw current, so the detectors look
at what is left once the motion is explained:

    i ≈ c0 + c1·v + c2·a + c3·g(v/v_k)                   inertia, viscous and dry friction
          [+ c·cos(p) + c'·sin(p)]                        gravity imbalance (elevation)
          [+ Σ_k (c_k·cos(kNp) + c'_k·sin(kNp)), k=1,2]   cogging, N periods per revolution

p, v, a: the axis angle (rad), rate (rad/s) and acceleration (rad/s²) of each segment
(a least-squares parabola through its samples). Dry friction saturates with speed: g is
one of three common shapes — a ramp clipped at ±1, tanh, or 1 − e^(−|x|) — and v_k the
knee speed; the shape and the knee (41 on a log scale, 1 µrad/s to 10 mrad/s) that
explain the reference best are kept. Sidereal rates sit on that knee, so its shape
decides the current of a star the reference never tracked; a fixed family with one
knee extrapolates where a flexible curve (tried: a linear spline with six knots) swung
by 0.07 A between the speeds the reference held. The cogging's N is an integer (a
motor's cogging repeats every revolution): the candidates are the highest peaks of a
Lomb–Scargle periodogram (scipy) of the base model's residual against position at whole
N, and the one whose full fit explains the reference best wins — the periodogram alone
cannot tell N from N ± 1 over the short travel of an elevation axis in 15 minutes, the
joint fit can. Everything is fitted on the reference only, so a fault after it cannot
hide in the fit, and live detection fits the same model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lombscargle

__all__ = ["CurrentModel", "Friction", "estimate_cogging_periods", "fit_current_model",
           "fit_friction"]

FRICTION_SHAPES = ("clip", "tanh", "exp")
FRICTION_KNEES_RAD_S = tuple(float(x) for x in np.logspace(-6, -2, 41))
MIN_COGGING_PERIODS = 8  # below: a slow drift of the residual, not a motor property
MAX_COGGING_PERIODS = 1024
COGGING_CANDIDATES = 8  # periodogram peaks whose neighbourhoods are fitted in full
MIN_COGGING_SHARE = 0.1  # the harmonic must explain this share of the residual variance
MAX_PERIODOGRAM_POINTS = 20_000
# Relative ridge on the scaled columns: the offset and gravity terms are nearly collinear
# over a few degrees of elevation; unbounded, the fit cancels large coefficients against
# each other. Small: with one friction shape there is little else to tame (3e-4, the
# value of the sine-experiment days, biased the gravity term by 0.015 A on elevation
# blocks outside the reference's elevations).
RIDGE = 1e-7
# Alternatives the reference cannot tell from the best fit: a friction shape and knee, or
# a cogging N ± 1, whose fit leaves at most this much more residual RMS. The spread of
# their predictions is the model's uncertainty at a motion (CurrentModel.spread_a).
ALTERNATIVE_RMS_RATIO = 1.05


@dataclass(frozen=True)
class Friction:
    """The dry-friction shape and its knee speed (rad/s)."""

    shape: str = "clip"
    knee_rad_s: float = 1e-4

    def __call__(self, v: np.ndarray) -> np.ndarray:
        x = v / self.knee_rad_s
        if self.shape == "clip":
            return np.clip(x, -1.0, 1.0)
        if self.shape == "tanh":
            return np.tanh(x)
        return np.sign(x) * -np.expm1(-np.abs(x))


@dataclass(frozen=True)
class CurrentModel:
    """Fitted coefficients; `predict` gives the current (A) of a motion."""

    coefficients: np.ndarray
    scales: np.ndarray
    gravity: bool
    cogging_periods: int  # 0: no cogging term
    reference_rms_a: float  # residual RMS on the rows it was fitted on
    friction: Friction = Friction()
    segment_s: float = 0.0  # the segments' span (s): the cogging averages over it
    # fits the reference explains almost as well (ALTERNATIVE_RMS_RATIO): (friction,
    # coefficients, scales) each, with the same cogging N
    alternatives: tuple = ()
    cogging_certain: bool = False  # N ± 1 explains the reference clearly worse

    def spread_a(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The largest difference between this model's current and an alternative's at
        each motion (A): what the reference leaves undetermined there (0 without
        alternatives)."""
        best = self.predict(p, v, a)
        out = np.zeros(len(best))
        for friction, coef, scales in self.alternatives:
            x = _regressors(p, v, a, self.gravity, self.cogging_periods, friction,
                            self.segment_s)
            np.maximum(out, np.abs((x / scales) @ coef - best), out=out)
        return out

    def predict(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        x = _regressors(p, v, a, self.gravity, self.cogging_periods, self.friction,
                        self.segment_s)
        return (x / self.scales) @ self.coefficients

    def cogging_amplitude_a(self) -> float:
        """The largest current the cogging terms can add (A): the sum of both harmonics'
        amplitudes (0 without a cogging term)."""
        if not self.cogging_periods:
            return 0.0
        c = self.coefficients[-4:] / self.scales[-4:]
        return float(math.hypot(c[0], c[1]) + math.hypot(c[2], c[3]))

    def friction_a(self, v: np.ndarray) -> np.ndarray:
        """The dry-friction part of the model's current at each rate (A): the term a
        bearing's friction growth scales."""
        k = 3  # the column of g(v/v_k) in _regressors
        return self.friction(v) * (self.coefficients[k] / self.scales[k])

    def slope_a_per_rad_s(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """d(current)/d|v| of the model at each motion (A per rad/s): how much the current
        changes with the speed there (the friction curve's steepness)."""
        dv = np.maximum(np.abs(v) * 0.05, 1e-7)
        up = self.predict(p, v + np.sign(v + 1e-30) * dv, a)
        down = self.predict(p, v - np.sign(v + 1e-30) * dv, a)
        return np.abs(up - down) / (2 * dv)


def _regressors(p, v, a, gravity: bool, cogging_periods: int,
                friction: Friction = Friction(), segment_s: float = 0.0) -> np.ndarray:
    cols = [np.ones_like(p), v, a, friction(v)]
    if gravity:
        cols += [np.cos(p), np.sin(p)]
    if cogging_periods > 0:
        for k in (1, 2):
            w = k * cogging_periods
            # a segment's mean of cos(w·p) while p moves by v·T: cos(w·p̄)·sinc(w·v·T/2π) —
            # in a slew the cogging averages out, and a high N cannot fit it there
            fade = np.sinc(w * v * segment_s / (2 * math.pi))
            cols += [np.cos(w * p) * fade, np.sin(w * p) * fade]
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


def fit_friction(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray, *,
                 gravity: bool, cogging_periods: int = 0, segment_s: float = 0.0) -> Friction:
    """Return the friction shape and knee that explain `i` best (see the module docstring)."""
    best, best_rms = Friction(), math.inf
    for shape in FRICTION_SHAPES:
        for knee in FRICTION_KNEES_RAD_S:
            f = Friction(shape, knee)
            rms = _rms(_regressors(p, v, a, gravity, cogging_periods, f, segment_s), i)
            if rms < best_rms:
                best, best_rms = f, rms
    return best


def estimate_cogging_periods(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray, *,
                             gravity: bool, friction: Friction = Friction(),
                             segment_s: float = 0.0) -> int:
    """Return the cogging periods per revolution that best explain `i` (see the module
    docstring), or 0 when none explains MIN_COGGING_SHARE of what the base model leaves
    (or the travel is too short to tell)."""
    ok = np.isfinite(p) & np.isfinite(v) & np.isfinite(a) & np.isfinite(i)
    p, v, a, i = p[ok], v[ok], a[ok], i[ok]
    if len(p) < 100 or float(np.ptp(p)) <= 0:
        return 0
    x0 = _regressors(p, v, a, gravity, 0, friction)
    coef, scales = _lstsq(x0, i)
    base = i - (x0 / scales) @ coef
    base_var = float(np.mean(base * base))
    best, best_rms = 0, math.inf
    for n in _candidates(p, base):
        rms = _rms(_regressors(p, v, a, gravity, n, friction, segment_s), i)
        if rms < best_rms:
            best, best_rms = n, rms
    if best == 0 or base_var <= 0 or 1.0 - best_rms ** 2 / base_var < MIN_COGGING_SHARE:
        return 0
    return best


def fit_current_model(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray,
                      rows: np.ndarray, *, gravity: bool, cogging_periods: int | None = None,
                      segment_s: float = 0.0) -> CurrentModel:
    """Fit the current model on `rows`; `cogging_periods` None estimates N from them.
    `segment_s`: the span of a segment (s), over which the cogging averages."""
    p, v, a, i = p[rows], v[rows], a[rows], i[rows]
    if len(p) < 10:
        raise ValueError(f"the current model needs rows to learn from; got {len(p)}")
    friction = fit_friction(p, v, a, i, gravity=gravity)
    if cogging_periods is None:
        cogging_periods = estimate_cogging_periods(p, v, a, i, gravity=gravity,
                                                   friction=friction, segment_s=segment_s)
    n = int(round(cogging_periods))
    if n:
        friction = fit_friction(p, v, a, i, gravity=gravity, cogging_periods=n,
                                segment_s=segment_s)
    x = _regressors(p, v, a, gravity, n, friction, segment_s)
    coef, scales = _lstsq(x, i)
    res = i - (x / scales) @ coef
    rms = float(np.sqrt(np.mean(res * res)))
    alternatives = []
    for shape in FRICTION_SHAPES:
        for knee in FRICTION_KNEES_RAD_S:
            f = Friction(shape, knee)
            if f == friction:
                continue
            xf = _regressors(p, v, a, gravity, n, f, segment_s)
            cf, sf = _lstsq(xf, i)
            r = i - (xf / sf) @ cf
            if np.sqrt(np.mean(r * r)) <= ALTERNATIVE_RMS_RATIO * rms:
                alternatives.append((f, cf, sf))
    certain = bool(n) and all(
        _rms(_regressors(p, v, a, gravity, m, friction, segment_s), i)
        > ALTERNATIVE_RMS_RATIO * rms for m in (n - 1, n + 1) if m > 0)
    return CurrentModel(coef, scales, gravity, n, rms, friction, segment_s,
                        tuple(alternatives), certain)
