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
motor's cogging repeats every revolution): the joint fit is scanned over every whole N
(a periodogram of the residual aliases when the reference held the axis at a few
clustered angles, and missed the true N on a fresh night), and the N that explains the
reference best wins. N is *certain* only when every other N explains the reference
clearly worse; a reference held at a few clustered angles lets several N fit, which part
between the clusters — then the detector widens its limits by what those rivals disagree
on and by the distance to the nearest angle the reference held
(`CurrentModel.cogging_uncertainty_a`). Everything is fitted on the reference only, so a fault after it cannot
hide in the fit, and live detection fits the same model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["CurrentModel", "Friction", "coefficient_covariance", "estimate_cogging_periods",
           "fit_current_model", "fit_friction", "friction_fits"]

FRICTION_SHAPES = ("clip", "tanh", "exp")
FRICTION_KNEES_RAD_S = tuple(float(x) for x in np.logspace(-6, -2, 41))
MIN_COGGING_PERIODS = 8  # below: a slow drift of the residual, not a motor property
MAX_COGGING_PERIODS = 1024
COGGING_CANDIDATES = 8  # the scan's best N whose neighbourhoods are fitted in full
MIN_COGGING_SHARE = 0.1  # the harmonic must explain this share of the residual variance
SCAN_POINTS = 2_000  # rows (evenly strided) the scan over every N fits
SCAN_BATCH = 64  # N fitted at once (a batch's columns: SCAN_BATCH × SCAN_POINTS × 4)
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
    cogging_certain: bool = False  # every other N explains the reference clearly worse
    # other N the reference fits almost as well (ALTERNATIVE_RMS_RATIO): (N, coefficients,
    # scales) each, with the same friction
    cogging_alternatives: tuple = ()
    # the reference's angles (rad, sorted) where the cogging shows (slow enough that a
    # segment does not average it out): where the fitted phase was seen
    held_angles_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # the coefficients' covariance (on the scaled columns), clustered by the reference's
    # windows (see `coefficient_covariance`): how far the reference pins each down
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def design(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The model's columns at each motion, scaled as fitted (rows × coefficients):
        `design @ coefficients` is `predict`, and a window's statistic that is linear in
        the residual is a linear form in them (its uncertainty: `form_sd`)."""
        x = _regressors(p, v, a, self.gravity, self.cogging_periods, self.friction,
                        self.segment_s)
        return x / self.scales

    def form_sd(self, forms: np.ndarray) -> np.ndarray:
        """The standard deviation of each row of `forms` (rows × coefficients) applied to
        the fitted coefficients: u·β has variance u Σ uᵀ (0 without a covariance)."""
        if self.covariance.size == 0 or len(forms) == 0:
            return np.zeros(len(forms))
        with np.errstate(invalid="ignore"):
            var = np.einsum("wk,kl,wl->w", forms, self.covariance, forms)
        return np.sqrt(np.maximum(var, 0.0))

    def prediction_sd_a(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """How far off the model's current may be at each motion from what the reference
        left open in its coefficients (A, one standard deviation): small where the
        reference held such motions, large where the model extrapolates."""
        return self.form_sd(self.design(p, v, a))

    def cogging_uncertainty_a(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """How far off the cogging term may be at each motion (A) when the reference did
        not pin N down (0 when it did): the largest difference between this model's
        current and a rival N's, and at least twice the cogging amplitude (the fitted wave
        and the true one in antiphase) once the angle is half a cogging period from every
        angle the reference held slowly, growing linearly up to there."""
        out = np.zeros(len(p))
        if not self.cogging_periods or self.cogging_certain:
            return out
        best = self.predict(p, v, a)
        for m, coef, scales in self.cogging_alternatives:
            x = _regressors(p, v, a, self.gravity, m, self.friction, self.segment_s)
            np.maximum(out, np.abs((x / scales) @ coef - best), out=out)
        held = self.held_angles_rad
        if len(held) == 0:
            return np.maximum(out, 2.0 * self.cogging_amplitude_a())
        k = np.searchsorted(held, p)
        d = np.minimum(np.abs(p - held[np.maximum(k - 1, 0)]),
                       np.abs(p - held[np.minimum(k, len(held) - 1)]))
        half_period = math.pi / self.cogging_periods
        return np.maximum(out, 2.0 * self.cogging_amplitude_a()
                          * np.minimum(1.0, np.nan_to_num(d, nan=np.inf) / half_period))

    def spread_a(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The largest difference between this model's current and an alternative's at
        each motion (A): what the reference leaves undetermined there (0 without
        alternatives)."""
        best = self.predict(p, v, a)
        out = np.zeros(len(best))
        if not self.alternatives:
            return out
        # only the friction column differs between the alternatives: the others (the
        # cogging's cosines, sines and fades among them) are computed once
        x = _regressors(p, v, a, self.gravity, self.cogging_periods, self.friction,
                        self.segment_s)
        for friction, coef, scales in self.alternatives:
            x[:, FRICTION_COLUMN] = friction(v)
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
        k = FRICTION_COLUMN
        return self.friction(v) * (self.coefficients[k] / self.scales[k])

    def slope_a_per_rad_s(self, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """d(current)/d|v| of the model at each motion (A per rad/s): how much the current
        changes with the speed there (the friction curve's steepness)."""
        dv = np.maximum(np.abs(v) * 0.05, 1e-7)
        up = self.predict(p, v + np.sign(v + 1e-30) * dv, a)
        down = self.predict(p, v - np.sign(v + 1e-30) * dv, a)
        return np.abs(up - down) / (2 * dv)


FRICTION_COLUMN = 3  # the column of g(v/v_k) in _regressors


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


def _held_angles(p: np.ndarray, v: np.ndarray, n: int, segment_s: float) -> np.ndarray:
    """The sorted angles of the rows whose segment shows the cogging at N (its fade, the
    segment mean of the wave, at least half the amplitude)."""
    if not n:
        return np.zeros(0)
    fade = np.abs(np.sinc(n * v * segment_s / (2 * math.pi)))
    keep = (fade >= 0.5) & np.isfinite(p)
    return np.sort(p[keep])


def _lstsq(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (coefficients, column scales) of a ridge-stabilised least-squares fit."""
    scales = np.sqrt(np.mean(x * x, axis=0)) if len(x) else np.ones(x.shape[1])
    scales[scales == 0] = 1.0
    xs = x / scales
    gram = xs.T @ xs
    gram += RIDGE * max(np.trace(gram), 1e-30) / len(gram) * np.eye(len(gram))
    return np.linalg.solve(gram, xs.T @ y), scales


def coefficient_covariance(xs: np.ndarray, residual: np.ndarray, clusters: np.ndarray, *,
                           lags: int = 0) -> np.ndarray:
    """The covariance of least-squares coefficients on the scaled columns `xs`, robust to
    residuals correlated within a cluster and between clusters up to `lags` apart (labels
    are integers in time order: clusters l apart in label are l apart in time).

    The sandwich G⁻¹ M G⁻¹ with g_c = Σ_{rows of c} x·r and M = Σ_c g_c g_cᵀ + Σ_{l ≤ lags}
    (1 − l/(lags + 1)) Σ_c (g_c g_{c+l}ᵀ + g_{c+l} g_cᵀ) (Newey–West's Bartlett weights
    over the clusters), times C/(C − 1).

    Clustered because the residual of a motion model is no white noise: it wanders slowly
    (a friction that warms, a cogging phase slightly off), so rows next to each other err
    together. The textbook σ²(XᵀX)⁻¹ counts each 0.256-s segment as news and, on a fresh
    night's elevation whose reference held no fast slew, put the current of a 0.1-rad/s
    slew within 0.0009 A — it was 0.019 A off; clustered by 10-s windows, 0.010 A."""
    k = xs.shape[1]
    gram = xs.T @ xs
    gram += RIDGE * max(np.trace(gram), 1e-30) / k * np.eye(k)
    inv = np.linalg.pinv(gram)
    labels, index = np.unique(clusters, return_inverse=True)
    if len(labels) < 2:
        return np.zeros((k, k))
    scores = np.zeros((len(labels), k))
    np.add.at(scores, index, xs * residual[:, None])
    meat = scores.T @ scores
    for lag in range(1, lags + 1):
        j = np.searchsorted(labels, labels + lag)
        pair = j < len(labels)
        pair[pair] = labels[j[pair]] == labels[pair] + lag
        cross = scores[pair].T @ scores[j[pair]]
        meat += (1.0 - lag / (lags + 1.0)) * (cross + cross.T)
    meat *= len(labels) / (len(labels) - 1)
    return inv @ meat @ inv


def _rms(x: np.ndarray, y: np.ndarray) -> float:
    coef, scales = _lstsq(x, y)
    r = y - (x / scales) @ coef
    return float(np.sqrt(np.mean(r * r)))


def scan_cogging_periods(p: np.ndarray, v: np.ndarray, x0: np.ndarray, i: np.ndarray,
                         segment_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(N, residual RMS) of the joint fit of the base columns `x0` and the cogging at every
    whole N from the lowest with a period inside the travel to MAX_COGGING_PERIODS.

    Every N is fitted, not only a periodogram's peaks: over a reference whose slow
    segments sit in a few clusters of angle the periodogram of the residual aliases (on a
    fresh night's elevation its eight highest peaks missed the emulator's N = 96, and the
    best of them, 247, left ten times its residual). The scan uses the normal equations of
    at most SCAN_POINTS evenly strided rows: the base block is shared by every N."""
    step_n = max(1, len(p) // SCAN_POINTS)
    p, v, x0, i = p[::step_n], v[::step_n], x0[::step_n], i[::step_n]
    span = float(np.ptp(p))
    lo = max(MIN_COGGING_PERIODS, math.ceil(2 * math.pi / span)) if span > 0 else \
        MAX_COGGING_PERIODS + 1
    ns = np.arange(lo, MAX_COGGING_PERIODS + 1)
    rms = np.full(len(ns), np.inf)
    s0 = np.sqrt(np.mean(x0 * x0, axis=0))
    s0[s0 == 0] = 1.0
    x0 = x0 / s0
    g00, b0, yy = x0.T @ x0, x0.T @ i, float(i @ i)
    k0 = x0.shape[1]
    eye = np.eye(k0 + 4)
    # e^(iNp) and e^(iNh), h = v·T/2, for each N by recurrence (a product per N, not
    # cosines and sines): the cogging's phase and the fade's, sinc(k·N·v·T/2π) =
    # sin(kNh)/(kNh), of both harmonics (sin(2x)/2x = sin(x)/x · cos(x))
    half_vt = v * (segment_s / 2)
    step = np.exp(1j * np.stack([p, half_vt]))
    at_n = np.exp(1j * (ns[0] - 1) * np.stack([p, half_vt]))
    moving = half_vt != 0
    inv_h = np.zeros(len(p))
    inv_h[moving] = 1.0 / half_vt[moving]
    for first in range(0, len(ns), SCAN_BATCH):
        nb = ns[first:first + SCAN_BATCH].astype(np.float64)
        zw = np.empty((len(nb), 2, len(p)), dtype=np.complex128)
        for j in range(len(nb)):
            at_n = at_n * step
            zw[j] = at_n
        z, w = zw[:, 0], zw[:, 1]
        fade1 = w.imag * (inv_h[None, :] / nb[:, None])
        fade1[:, ~moving] = 1.0
        fade2 = fade1 * w.real
        # the same columns as _regressors, one row per column (each contiguous over the
        # points): cos(kNp)·fade and sin(kNp)·fade
        c = np.empty((len(nb), 4, len(p)))
        z2 = z * z
        np.multiply(z.real, fade1, out=c[:, 0])
        np.multiply(z.imag, fade1, out=c[:, 1])
        np.multiply(z2.real, fade2, out=c[:, 2])
        np.multiply(z2.imag, fade2, out=c[:, 3])
        # scale the products rather than the columns: a column's mean square is its
        # product with itself over the points
        g_cc = c @ np.transpose(c, (0, 2, 1))
        sc = np.sqrt(np.diagonal(g_cc, axis1=1, axis2=2) / len(p))
        sc[sc == 0] = 1.0
        gram = np.empty((len(nb), k0 + 4, k0 + 4))
        gram[:, :k0, :k0] = g00
        gram[:, k0:, k0:] = g_cc / (sc[:, :, None] * sc[:, None, :])
        gram[:, k0:, :k0] = (c @ x0) / sc[:, :, None]
        gram[:, :k0, k0:] = np.transpose(gram[:, k0:, :k0], (0, 2, 1))
        b = np.concatenate([np.broadcast_to(b0, (len(nb), k0)), (c @ i) / sc], axis=1)
        ridge = RIDGE * np.maximum(np.trace(gram, axis1=1, axis2=2), 1e-30) / (k0 + 4)
        coef = np.linalg.solve(gram + ridge[:, None, None] * eye, b[:, :, None])[:, :, 0]
        sse = yy - 2 * np.sum(coef * b, axis=1) + np.sum(
            coef * (gram @ coef[:, :, None])[:, :, 0], axis=1)
        rms[first:first + SCAN_BATCH] = np.sqrt(np.maximum(sse, 0.0) / len(p))
    return ns, rms


def _equivalent(n: int, m: int) -> bool:
    """N and 2N (either way) fit the same cogging: the second harmonic of one is the
    fundamental of the other."""
    return n == m or n == 2 * m or m == 2 * n


def friction_fits(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray, *,
                  gravity: bool, cogging_periods: int = 0,
                  segment_s: float = 0.0) -> list[tuple[Friction, np.ndarray, np.ndarray, float]]:
    """(friction, coefficients, column scales, residual RMS) of the fit with each friction
    shape and knee (FRICTION_SHAPES × FRICTION_KNEES_RAD_S, in that order): what `_lstsq`
    gives for each, solved together.

    Only the friction column differs between the candidates, so the other columns' normal
    equations are formed once and each candidate adds its column's products with them
    (one matrix product per shape); the residual RMS comes from the normal equations, as
    in `scan_cogging_periods`. A fit is then a (k × k) solve, not a pass over the rows."""
    base = _regressors(p, v, a, gravity, cogging_periods, Friction(), segment_s)
    k = base.shape[1]
    others = [c for c in range(k) if c != FRICTION_COLUMN]
    b_scales = np.sqrt(np.mean(base[:, others] ** 2, axis=0)) if len(p) else np.ones(k - 1)
    b_scales[b_scales == 0] = 1.0
    bs = base[:, others] / b_scales
    g_bb, y_b, yy = bs.T @ bs, bs.T @ i, float(i @ i)
    n_rows = max(len(p), 1)
    out = []
    for shape in FRICTION_SHAPES:
        frictions = [Friction(shape, knee) for knee in FRICTION_KNEES_RAD_S]
        f = np.stack([fr(v) for fr in frictions], axis=1) if len(p) else \
            np.zeros((0, len(frictions)))
        f_scales = np.sqrt(np.mean(f * f, axis=0)) if len(p) else np.ones(len(frictions))
        f_scales[f_scales == 0] = 1.0
        fs = f / f_scales
        m = len(frictions)
        gram = np.empty((m, k, k))
        sub = np.ix_(others, others)
        gram[:, sub[0], sub[1]] = g_bb
        cross = (bs.T @ fs).T  # (m, k - 1)
        gram[:, FRICTION_COLUMN, others] = cross
        gram[:, others, FRICTION_COLUMN] = cross
        gram[:, FRICTION_COLUMN, FRICTION_COLUMN] = np.einsum("nm,nm->m", fs, fs)
        rhs = np.empty((m, k))
        rhs[:, others] = y_b
        rhs[:, FRICTION_COLUMN] = fs.T @ i
        ridge = RIDGE * np.maximum(np.trace(gram, axis1=1, axis2=2), 1e-30) / k
        coef = np.linalg.solve(gram + ridge[:, None, None] * np.eye(k), rhs[:, :, None])[:, :, 0]
        sse = yy - 2 * np.sum(coef * rhs, axis=1) + np.einsum("mk,mkl,ml->m", coef, gram, coef)
        rms = np.sqrt(np.maximum(sse, 0.0) / n_rows)
        for j, fr in enumerate(frictions):
            scales = np.empty(k)
            scales[others] = b_scales
            scales[FRICTION_COLUMN] = f_scales[j]
            out.append((fr, coef[j], scales, float(rms[j])))
    return out


def _best_friction(fits) -> Friction:
    """The friction of `fits` (as `friction_fits` returns) with the least residual RMS, the
    first on a tie; Friction() when none is finite."""
    best, best_rms = Friction(), math.inf
    for friction, _, _, rms in fits:
        if rms < best_rms:
            best, best_rms = friction, rms
    return best


def fit_friction(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray, *,
                 gravity: bool, cogging_periods: int = 0, segment_s: float = 0.0) -> Friction:
    """Return the friction shape and knee that explain `i` best (see the module docstring)."""
    return _best_friction(friction_fits(p, v, a, i, gravity=gravity,
                                        cogging_periods=cogging_periods, segment_s=segment_s))


def _cogging_choice(p, v, a, i, *, gravity: bool, friction: Friction,
                    segment_s: float) -> tuple[int, list[int]]:
    """(N, the other N the reference cannot tell from it): N is 0 when no cogging explains
    MIN_COGGING_SHARE of what the base model leaves (or the travel is too short to tell).

    Every N is scanned (`scan_cogging_periods`); the COGGING_CANDIDATES best and their
    neighbours are fitted on every row. Where N and 2N both fit, 2N is taken (one harmonic
    explains it). The others are the candidates whose fit leaves at most
    ALTERNATIVE_RMS_RATIO × the best's residual RMS, 2N and N/2 aside: a reference whose
    slow segments sit in a few clusters of angle lets several N fit it, and they part
    between the clusters."""
    ok = np.isfinite(p) & np.isfinite(v) & np.isfinite(a) & np.isfinite(i)
    p, v, a, i = p[ok], v[ok], a[ok], i[ok]
    if len(p) < 100 or float(np.ptp(p)) <= 0:
        return 0, []
    x0 = _regressors(p, v, a, gravity, 0, friction)
    coef, scales = _lstsq(x0, i)
    base = i - (x0 / scales) @ coef
    base_var = float(np.mean(base * base))
    ns, scan = scan_cogging_periods(p, v, x0, i, segment_s)
    if len(ns) == 0 or base_var <= 0:
        return 0, []
    top = ns[np.argsort(scan)[:COGGING_CANDIDATES]]
    cands = sorted({int(n) + d for n in top for d in (-1, 0, 1)
                    if ns[0] <= int(n) + d <= MAX_COGGING_PERIODS})
    cands = sorted(set(cands) | {2 * n for n in cands if 2 * n <= MAX_COGGING_PERIODS})
    full = {n: _rms(_regressors(p, v, a, gravity, n, friction, segment_s), i) for n in cands}
    best = min(full, key=full.__getitem__)
    if 2 * best in full and full[2 * best] <= ALTERNATIVE_RMS_RATIO * full[best]:
        best = 2 * best
    if 1.0 - min(full.values()) ** 2 / base_var < MIN_COGGING_SHARE:
        return 0, []
    bound = ALTERNATIVE_RMS_RATIO * min(full.values())
    others = [n for n, r in sorted(full.items(), key=lambda kv: kv[1])
              if r <= bound and not _equivalent(n, best)]
    return best, others


def estimate_cogging_periods(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray, *,
                             gravity: bool, friction: Friction = Friction(),
                             segment_s: float = 0.0) -> int:
    """Return the cogging periods per revolution that best explain `i` (see the module
    docstring and `_cogging_choice`), or 0 when none explains MIN_COGGING_SHARE of what
    the base model leaves (or the travel is too short to tell)."""
    return _cogging_choice(p, v, a, i, gravity=gravity, friction=friction,
                           segment_s=segment_s)[0]


def fit_current_model(p: np.ndarray, v: np.ndarray, a: np.ndarray, i: np.ndarray,
                      rows: np.ndarray, *, gravity: bool, cogging_periods: int | None = None,
                      segment_s: float = 0.0, clusters: np.ndarray | None = None,
                      cluster_lags: int = 0) -> CurrentModel:
    """Fit the current model on `rows`; `cogging_periods` None estimates N from them.
    `segment_s`: the span of a segment (s), over which the cogging averages. `clusters`:
    a label per row (the same length as `p`) of the stretches whose residuals may err
    together (the detector's windows), for the coefficients' covariance; None: every row
    its own."""
    labels = (np.arange(len(p)) if clusters is None else np.asarray(clusters))[rows]
    p, v, a, i = p[rows], v[rows], a[rows], i[rows]
    if len(p) < 10:
        raise ValueError(f"the current model needs rows to learn from; got {len(p)}")
    fits = friction_fits(p, v, a, i, gravity=gravity)
    friction = _best_friction(fits)
    rivals: list[int] = []
    if cogging_periods is None:
        cogging_periods, rivals = _cogging_choice(p, v, a, i, gravity=gravity,
                                                  friction=friction, segment_s=segment_s)
    n = int(round(cogging_periods))
    if n:
        fits = friction_fits(p, v, a, i, gravity=gravity, cogging_periods=n,
                             segment_s=segment_s)
        friction = _best_friction(fits)
    x = _regressors(p, v, a, gravity, n, friction, segment_s)
    coef, scales = _lstsq(x, i)
    res = i - (x / scales) @ coef
    rms = float(np.sqrt(np.mean(res * res)))
    alternatives = [(f, cf, sf) for f, cf, sf, r in fits
                    if f != friction and r <= ALTERNATIVE_RMS_RATIO * rms]
    # N is certain when the reference rules out every other N it was scanned against (an
    # N given by the caller has no rivals) and N ± 1 explain it clearly worse
    cogging_alternatives = []
    for m in rivals[:COGGING_CANDIDATES]:
        xm = _regressors(p, v, a, gravity, m, friction, segment_s)
        cm, sm = _lstsq(xm, i)
        cogging_alternatives.append((m, cm, sm))
    certain = bool(n) and not rivals and all(
        _rms(_regressors(p, v, a, gravity, m, friction, segment_s), i)
        > ALTERNATIVE_RMS_RATIO * rms for m in (n - 1, n + 1) if m > 0)
    held = _held_angles(p, v, n, segment_s)
    covariance = coefficient_covariance(x / scales, res, labels, lags=cluster_lags)
    return CurrentModel(coef, scales, gravity, n, rms, friction, segment_s,
                        tuple(alternatives), certain, tuple(cogging_alternatives), held,
                        covariance)
