"""The current detector: the current minus its motion model, per class and speed."""

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

class CurrentDetector(Detector):
    """Flag windows whose current departs from the motion model (friction, winding)."""

    kind = "current"

    def _window_s(self) -> float:
        return self.cfg.current_window_s

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.model: CurrentModel | None = None
        self.rest_rad_s = math.radians(self.cfg.phases.rest_rate_arcsec_s / 3600.0)
        self.ref_speeds: dict[int, np.ndarray] = {}
        self.saturated_rad_s = math.inf
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
        # term grows, linearly.
        allowance = np.zeros(len(p))
        covered = np.abs(v) >= self.saturated_rad_s
        cls = self.classes(chunk)
        need = max(1, round(self.cfg.coverage_min_s / self.seg_s))
        for c, speeds in self.ref_speeds.items():
            rows = np.flatnonzero(cls == c)
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
        allowance += self.cogging_a * np.minimum(1.0, beyond)
        return {"resid": resid, "allowance": allowance, "covered": covered}

    def stats(self, arrays, starts):
        return {"mean": window_mean(arrays["resid"], starts, arrays["use"], need=self.need),
                "allowance": window_mean(arrays["allowance"], starts, arrays["use"],
                                         need=self.need)}

    def fit(self, chunk: Chunk, ref: np.ndarray) -> Check:
        p, v, a, i = self._motion(chunk)
        rows = self.use(chunk) & ref
        try:
            self.model = fit_current_model(p, v, a, i, rows, gravity=self.axis == "el",
                                           cogging_periods=self.cfg.cogging_periods,
                                           segment_s=self.seg_s * (SEGMENT_SAMPLES - 1)
                                           / SEGMENT_SAMPLES)
        except ValueError as exc:
            self.plan = {}
            return Check(self.kind, self.axis, self.signals, False, str(exc))
        cls = self.classes(chunk)
        self.ref_angles = (float(np.min(p[rows])), float(np.max(p[rows])))
        self.cogging_a = self.model.cogging_amplitude_a()
        # speeds held steadily (changing by under 10 % within a segment): a run-up
        # sweeping through a speed says little about the friction there
        steady = np.abs(a) * self.seg_s <= 0.1 * np.abs(v)
        self.ref_speeds = {c: np.sort(np.abs(v[rows & steady & (cls == c)]))
                           for c in AXIS_CLASSES}
        # Where the friction is saturated: three knees above its knee, and no lower than
        # the lowest speed the reference held steadily for coverage_min_s (a knee fitted
        # on speeds all above it is a guess); trusted when the reference held that long
        # at such speeds.
        held = np.sort(np.abs(v[rows & steady]))
        need = max(1, round(self.cfg.coverage_min_s / self.seg_s))
        self.saturated_rad_s = math.inf
        if len(held) >= need:
            start = max(3.0 * self.model.friction.knee_rad_s, float(held[need - 1]))
            if np.sum(held >= start) >= need:
                self.saturated_rad_s = start
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
        for c in AXIS_CLASSES:
            m = mean[(cls == c) & np.isfinite(mean)]
            if not held[c] or len(m) == 0:
                continue
            med, sigma = robust_center_scale(m)
            widest = float(np.max(np.abs(m - med)))
            self.center[c] = float(med)
            self.limit[c] = max(self.cfg.threshold * float(sigma),
                                self.cfg.current_ref_factor * widest, self.cfg.current_floor_a)

    def window_scores(self, stats, cls):
        center = self._lookup(self.center, cls)
        limit = self._lookup(self.limit, cls) + self.cfg.coverage_factor * stats["allowance"]
        dev = stats["mean"] - center
        score = np.abs(dev) / limit
        details = [f"current {dev[k]:+.3f} A off its motion model while "
                   f"{CLASS_NAMES.get(int(cls[k]), '?')} (limit {limit[k]:.3f} A)"
                   if np.isfinite(score[k]) and score[k] >= 1.0 else ""
                   for k in range(len(score))]
        return score, details

    def check(self) -> Check:
        c = super().check()
        if not c.ran:
            return c
        m = self.model
        assert m is not None
        return Check(c.detector, c.axis, c.signals, c.ran,
                     f"model fitted on the reference: dry friction {m.friction.shape} with its "
                     f"knee at {math.degrees(m.friction.knee_rad_s) * 3600:.3g}″/s, cogging "
                     f"{m.cogging_periods} periods/rev, residual {m.reference_rms_a:.4f} A RMS",
                     c.classes)
