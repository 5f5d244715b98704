"""The current detector: the current minus its motion model, per class and speed.

Three statistics per window, each against the reference's windows:

* the **mean residual** (current − model), at speeds the reference held (or above its
  saturated friction): an offset of the current;
* the **gain**: the residual regressed on the modelled current, Σr·m / Σm². A winding
  fault (turns shorted, torque constant down by f) scales the whole current by 1/(1 − f),
  so its gain is f/(1 − f) in every phase — in a slew, where the current changes sign and
  a mean residual averages out, as much as in a track;
* the **friction scale**: the residual regressed on the model's dry-friction current. A
  bearing wearing or drying raises the Coulomb friction, which scales that term — by the
  same fraction at every speed, so a sidereal track at a speed the reference never held
  is compared with it through the model's friction law.

The scale statistics are scored at every speed the axis moves at, wherever the current
they regress on is large enough (`gain_min_a`, `friction_min_a`) to measure a scale; their
limit adds the model's uncertainty there, divided by that current — its reference RMS,
and, at speeds the reference did not hold, how far the model's current moves between the
nearest speed it held steadily and this one (the part of the prediction that is
extrapolated).
"""

from __future__ import annotations

import math

import numpy as np

from .current_model import CurrentModel, fit_current_model
from .detectors import POOLED, Check, Chunk, Detector, class_plan
from .phases import AXIS_CLASSES, CLASS_NAMES, REST
from .robust import robust_center_scale
from .segments import SEGMENT_SAMPLES
from .windows import window_mean

__all__ = ["CurrentDetector"]

# below this an axis's speed changes too slowly to cross the knee within a segment (the
# sidereal rates change by ~1e-8 rad/s²); it keeps noise at rest from counting as a start
EDGE_ACCEL_RAD_S2 = 1e-5
# The reference residual's slow wander outlasts a 10-s window: the coefficients' covariance
# also counts the correlation of windows up to this many apart (Newey–West weights). On a
# synthetic axis with a 30-s wander the model's error at 50× the reference's speeds then
# lies within 3 standard deviations on 19 nights of 20, within 3 of the estimate without
# the lags on 17 (tests/anomalies/test_model_uncertainty.py)
COVARIANCE_LAGS = 3

class CurrentDetector(Detector):
    """Flag windows whose current departs from the motion model (friction, winding)."""

    kind = "current"

    def _window_s(self) -> float:
        return self.cfg.current_window_s

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.model: CurrentModel | None = None
        self.rest_rad_s = math.radians(self.cfg.phases.rest_rate_arcsec_s / 3600.0)
        # (class, direction ±1): the sorted speeds the reference held steadily that way
        self.ref_speeds: dict[tuple[int, int], np.ndarray] = {}
        self.window_sigma_a = math.nan  # robust sigma of the reference's window residuals
        self.scale_ref: dict[str, tuple[float, float]] = {}  # statistic: (centre, limit)
        self.saturated_rad_s = {1: math.inf, -1: math.inf}  # per direction
        self.ref_angles = (-math.inf, math.inf)
        self.cogging_a = 0.0
        self.center: dict[int, float] = {}
        self.limit: dict[int, float] = {}

    def _motion(self, chunk: Chunk):
        f = chunk.seg.features
        ax = self.axis
        return (f[f"{ax}.position_rad"], f[f"{ax}.velocity_rad_s"],
                f[f"{ax}.acceleration_rad_s2"], f[f"{ax}.current_a"])

    def _arrays(self, chunk: Chunk) -> dict[str, np.ndarray]:
        arrays = super()._arrays(chunk)
        arrays["use_any"] = arrays["use"].copy()  # the scale statistics: any speed
        arrays["use"] = arrays["use"] & arrays["covered"]
        return arrays

    def use(self, chunk: Chunk) -> np.ndarray:
        _, v, a, _ = self._motion(chunk)
        at_rest = self.classes(chunk) == REST
        # a segment in which the axis starts, stops or turns crosses the friction's knee:
        # its mean current is no function of its mean speed. Whatever its class: the
        # events that say a slew began are stamped up to a block late
        edge = (np.abs(a) > EDGE_ACCEL_RAD_S2) & (np.abs(v) < np.abs(a) * self.seg_s)
        return super().use(chunk) & ~edge & ~at_rest

    def values(self, chunk: Chunk) -> dict[str, np.ndarray]:
        p, v, a, i = self._motion(chunk)
        assert self.model is not None, "fit before scoring"
        resid = i - self.model.predict(p, v, a)
        # Speeds the reference did not hold: below a few hundred arcseconds per second the
        # dry friction changes steeply with speed, and the model there is an extrapolation
        # from the speeds it saw. A segment is scored when its class held
        # `coverage_min_s` of reference at speeds within `coverage_ratio` of its own (its
        # limit widens by coverage_factor × the model's slope × its distance to their
        # median speed), or when it is as fast as the saturated friction the reference
        # showed (`saturated_rad_s`): there the friction is flat and only the viscous
        # term grows, linearly. Both per direction: the dry friction changes sign with
        # the motion, and a reference that moved one way at speed only (a night's first
        # quarter-hour slewing and tracking westwards, a few slow steps eastwards) leaves
        # the split between the offset and the friction open — the other way at speed
        # the model is an extrapolation (0.10 A off on a fresh night's azimuth).
        allowance = np.zeros(len(p))
        direction = np.where(v >= 0, 1, -1)
        covered = np.abs(v) >= np.where(direction > 0, self.saturated_rad_s[1],
                                        self.saturated_rad_s[-1])
        cls = self.classes(chunk)
        need = max(1, round(self.cfg.coverage_min_s / self.seg_s))
        for (c, sign), speeds in self.ref_speeds.items():
            rows = np.flatnonzero((cls == c) & (direction == sign))
            if len(rows) == 0 or len(speeds) < need:
                continue
            s = np.abs(v[rows])
            lo = np.searchsorted(speeds, s / self.cfg.coverage_ratio)
            hi = np.searchsorted(speeds, s * self.cfg.coverage_ratio, side="right")
            near = hi - lo >= need
            middle = speeds[np.clip((lo + hi) // 2, 0, len(speeds) - 1)]
            allowance[rows] = np.where(near, np.abs(s - middle) * self.model.slope_a_per_rad_s(
                p[rows], v[rows], a[rows]), 0.0)
            covered[rows] |= near
        # Beyond the angles the reference travelled, a cogging period off by one (over a
        # short travel the fit cannot always tell N from N ± 1) puts the cogging term out
        # of phase: up to its amplitude, growing with the distance (rad) from that travel.
        beyond = np.maximum(self.ref_angles[0] - p, p - self.ref_angles[1]).clip(min=0.0)
        cogging = self.cogging_a * np.minimum(1.0, beyond)
        # Where the reference did not pin N down (held at a few clustered angles, several
        # N fit it), the cogging may be off between the angles it held too: by what the
        # rival N predict there, and up to twice its amplitude half a period away from
        # every angle held slowly
        if not self.model.cogging_certain:
            cogging = np.maximum(cogging, self.model.cogging_uncertainty_a(p, v, a))
        allowance += cogging
        # the scale statistics' uncertainty: what the reference leaves open at this motion
        # (friction shapes and knees it cannot tell apart), and the cogging's phase where N
        # is not certain
        uncertainty = self.model.spread_a(p, v, a)
        if not self.model.cogging_certain:
            uncertainty += cogging
        return {"resid": resid, "allowance": allowance, "covered": covered,
                "model": i - resid, "friction": self.model.friction_a(v),
                "uncertainty": uncertainty, "design": self.model.design(p, v, a)}

    def _form_sd(self, forms: np.ndarray) -> np.ndarray:
        """The model error's standard deviation of each window's linear form (0 before a
        model is fitted)."""
        return np.zeros(len(forms)) if self.model is None else self.model.form_sd(forms)

    def stats(self, arrays, starts):
        design = arrays.get("design")
        if design is None:  # statistics of given arrays, no model: no model error
            design = np.zeros((len(arrays["resid"]), 0))
        out = {"mean": window_mean(arrays["resid"], starts, arrays["use"], need=self.need),
               "allowance": window_mean(arrays["allowance"], starts, arrays["use"],
                                        need=self.need)}
        # Each statistic is linear in the residual, so an error δβ of the model's
        # coefficients moves it by a linear form u·δβ: the window mean of the design rows
        # for the mean residual, Σ x·m / Σ m² for a scale regressed on m. Its standard
        # deviation, from the coefficients' covariance on the reference, is how far the
        # statistic may be off at this motion because the reference left the model open
        # there (a slew ten times faster than any the reference held, say).
        out["mean_sd_a"] = self._form_sd(window_mean(design, starts, arrays["use"],
                                                     need=self.need))
        use, r = arrays["use_any"], arrays["resid"]
        unc = window_mean(arrays["uncertainty"], starts, use, need=self.need)
        for name, x in (("gain", arrays["model"]), ("friction", arrays["friction"])):
            power = window_mean(x * x, starts, use, need=self.need)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[name] = window_mean(r * x, starts, use, need=self.need) / power
                out[f"{name}_rms_a"] = np.sqrt(power)
                out[f"{name}_sd"] = self._form_sd(window_mean(
                    design * x[:, None], starts, use, need=self.need) / power[:, None])
        out["uncertainty"] = unc
        return out

    def fit(self, chunk: Chunk, ref: np.ndarray) -> Check:
        p, v, a, i = self._motion(chunk)
        rows = self.use(chunk) & ref
        # the residuals of neighbouring segments err together: the coefficients'
        # covariance is clustered by the detector's windows (10 s of mount time), with
        # the neighbouring windows' correlation up to COVARIANCE_LAGS windows apart
        t = chunk.seg.t_first_us
        clusters = (t - (t[0] if len(t) else 0)) // round(self._window_s() * 1e6)
        try:
            self.model = fit_current_model(p, v, a, i, rows, gravity=self.axis == "el",
                                           cogging_periods=self.cfg.cogging_periods,
                                           segment_s=self.seg_s * (SEGMENT_SAMPLES - 1)
                                           / SEGMENT_SAMPLES, clusters=clusters,
                                           cluster_lags=COVARIANCE_LAGS)
        except ValueError as exc:
            self.plan = {}
            return Check(self.kind, self.axis, self.signals, False, str(exc))
        cls = self.classes(chunk)
        self.ref_angles = (float(np.min(p[rows])), float(np.max(p[rows])))
        self.cogging_a = self.model.cogging_amplitude_a()
        # speeds held steadily (changing by under 10 % within a segment): a run-up
        # sweeping through a speed says little about the friction there
        steady = np.abs(a) * self.seg_s <= 0.1 * np.abs(v)
        self.ref_speeds = {(c, sign): np.sort(np.abs(v[rows & steady & (cls == c)
                                                       & (np.sign(v) == sign)]))
                           for c in AXIS_CLASSES for sign in (1, -1)}
        # Where the friction is saturated: three knees above its knee, and no lower than
        # the lowest speed the reference held steadily for coverage_min_s (a knee fitted
        # on speeds all above it is a guess); trusted when the reference held that long
        # at such speeds in that direction.
        held = np.sort(np.abs(v[rows & steady]))
        need = max(1, round(self.cfg.coverage_min_s / self.seg_s))
        self.saturated_rad_s = {1: math.inf, -1: math.inf}
        if len(held) >= need:
            start = max(3.0 * self.model.friction.knee_rad_s, float(held[need - 1]))
            for sign in (1, -1):
                way = np.abs(v[rows & steady & (np.sign(v) == sign)])
                if np.sum(way >= start) >= need:
                    self.saturated_rad_s[sign] = start
        return super().fit(chunk, ref)

    def fit_classes(self, stats, cls, seconds):
        mean = stats["mean"]
        held, why = self._held(np.isfinite(mean), cls, seconds)
        self.plan = class_plan(held, why)
        self.plan[REST] = (None, "not scored: dry friction holds an axis at rest anywhere "
                                 "within its breakaway torque, so the holding current says "
                                 "nothing")
        # The model is one for every motion: a class the reference holds too little of
        # (often the slews of an axis that moved little between targets) is scored against
        # all the reference's windows together, with twice the floor.
        pooled = mean[np.isfinite(mean) & (cls != REST) & (cls >= 0)]
        if len(pooled) >= self.cfg.min_windows:
            med, sigma = robust_center_scale(pooled)
            self.window_sigma_a = float(sigma)
            self.center[POOLED] = float(med)
            self.limit[POOLED] = max(self.cfg.threshold * float(sigma),
                                     self.cfg.current_ref_factor * float(
                                         np.max(np.abs(pooled - med))),
                                     2.0 * self.cfg.current_floor_a)
            for c, (basis, note) in list(self.plan.items()):
                if basis is None and c != REST:
                    self.plan[c] = (POOLED, "scored against all the reference's windows with "
                                    "twice the floor (" + note.removeprefix("not scored: ")
                                    + ")")
        # The scale statistics: the reference's moving windows together (a scale is one
        # number for the motor whatever the motion), where the current was large enough
        self.scale_ref = {}
        for name, least, floor in (("gain", self.cfg.gain_min_a, self.cfg.gain_floor),
                                   ("friction", self.cfg.friction_min_a,
                                    self.cfg.friction_scale_floor)):
            x = stats[name][(stats[f"{name}_rms_a"] >= least) & (cls != REST) & (cls >= 0)]
            x = x[np.isfinite(x)]
            if len(x) < self.cfg.min_windows:
                continue
            med, sigma = robust_center_scale(x)
            self.scale_ref[name] = (float(med), max(
                floor, self.cfg.threshold * float(sigma),
                self.cfg.current_ref_factor * float(np.max(np.abs(x - med)))))
        for c in AXIS_CLASSES:
            m = mean[(cls == c) & np.isfinite(mean)]
            if not held[c] or len(m) == 0:
                continue
            med, sigma = robust_center_scale(m)
            widest = float(np.max(np.abs(m - med)))
            self.center[c] = float(med)
            self.limit[c] = max(self.cfg.threshold * float(sigma),
                                self.cfg.current_ref_factor * widest, self.cfg.current_floor_a)

    def _scale_limits(self, stats, name: str, cls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(deviation, limit) per window of the scale statistic `name` (NaN where it is not
        scored: no reference for it, at rest, or too little current to measure a scale)."""
        n = len(cls)
        if name not in self.scale_ref:
            return np.full(n, np.nan), np.full(n, np.nan)
        center, base = self.scale_ref[name]
        rms = stats[f"{name}_rms_a"]
        least = self.cfg.gain_min_a if name == "gain" else self.cfg.friction_min_a
        assert self.model is not None
        with np.errstate(invalid="ignore", divide="ignore"):
            # a scale measured on a smaller current is noisier: the reference's window
            # noise (A) over this window's current, in the same robust sigmas; and the
            # model's own error — its residual RMS on the reference (slow wanders of the
            # current do not average out in a window) and what the reference leaves open
            # at this motion — over the same current
            noise = self.cfg.threshold * self.window_sigma_a / rms
            limit = np.maximum(base, noise) + self.cfg.scale_uncertainty_factor * (
                self.model.reference_rms_a + stats["uncertainty"]) / rms \
                + self.cfg.model_sd_factor * stats[f"{name}_sd"]
        ok = (rms >= least) & (cls != REST) & (cls >= 0)
        return np.where(ok, stats[name] - center, np.nan), np.where(ok, limit, np.nan)

    def window_scores(self, stats, cls):
        center = self._lookup(self.center, cls)
        limit = self._lookup(self.limit, cls) + self.cfg.coverage_factor * stats["allowance"] \
            + self.cfg.model_sd_factor * stats["mean_sd_a"]
        dev = stats["mean"] - center
        with np.errstate(invalid="ignore"):
            score = np.abs(dev) / limit
            gain_dev, gain_lim = self._scale_limits(stats, "gain", cls)
            fric_dev, fric_lim = self._scale_limits(stats, "friction", cls)
            gain_score = np.abs(gain_dev) / gain_lim
            fric_score = np.abs(fric_dev) / fric_lim
        scores = np.stack([score, gain_score, fric_score])
        best = np.argmax(np.nan_to_num(scores, nan=-1.0), axis=0)
        total = np.where(np.all(np.isnan(scores), axis=0), np.nan,
                         np.nanmax(np.where(np.isnan(scores), -np.inf, scores), axis=0))
        details = []
        for k in range(len(total)):
            if not (np.isfinite(total[k]) and total[k] >= 1.0):
                details.append("")
                continue
            while_ = CLASS_NAMES.get(int(cls[k]), "?")
            if best[k] == 0:
                details.append(f"current {dev[k]:+.3f} A off its motion model while "
                               f"{while_} (limit {limit[k]:.3f} A)")
            elif best[k] == 1:
                details.append(f"current {gain_dev[k]:+.1%} of its modelled value off its "
                               f"model while {while_} (limit {gain_lim[k]:.1%}): a "
                               "torque-constant change scales the current")
            else:
                details.append(f"dry friction {fric_dev[k]:+.1%} off its model while "
                               f"{while_} (limit {fric_lim[k]:.1%})")
        return total, details

    def check(self) -> Check:
        c = super().check()
        if not c.ran:
            return c
        m = self.model
        assert m is not None
        return Check(c.detector, c.axis, c.signals, c.ran,
                     f"model fitted on the reference: dry friction {m.friction.shape} with its "
                     f"knee at {math.degrees(m.friction.knee_rad_s) * 3600:.3g}″/s, cogging "
                     f"{m.cogging_periods} periods/rev"
                     + ("" if m.cogging_certain or not m.cogging_periods else
                        " (not certain: the reference fits "
                        + (", ".join(str(x[0]) for x in m.cogging_alternatives) or "N ± 1")
                        + " almost as well; limits widened between the angles it held)")
                     + f", residual {m.reference_rms_a:.4f} A RMS",
                     c.classes)
