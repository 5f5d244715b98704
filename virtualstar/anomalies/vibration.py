"""The vibration detector: the tracking error's octave-band spectrum per class, aware of the
encoder's quantisation tones."""

from __future__ import annotations

import math

import numpy as np

from .detectors import Check, Chunk, Detector, class_plan
from .phases import AXIS_CLASSES, CLASS_NAMES
from .robust import robust_center_scale
from .segments import SEGMENT_SAMPLES
from .windows import window_median

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0

__all__ = ["VibrationDetector"]

class VibrationDetector(Detector):
    """Flag windows whose tracking error is louder than usual in some octave band."""

    kind = "vibration"

    def _window_s(self) -> float:
        return self.cfg.vibration_window_s

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.bands = np.zeros(0, np.int64)
        self.edges = np.zeros(0)
        self.count_arcsec = 0.0
        self.quantisation_log = -math.inf
        self.center: dict[int, np.ndarray] = {}
        self.limit: dict[int, np.ndarray] = {}

    def values(self, chunk):
        bp = chunk.seg.features[f"{self.axis}.error_band_power"]
        self.edges = chunk.seg.band_edges_hz
        return {"logp": np.log10(bp + 1e-30),
                "spiky": (chunk.valid & ~chunk.calm[self.axis]).astype(np.float64)}

    def stats(self, arrays, starts):
        logp = arrays["logp"][:, self.bands] if len(self.bands) else arrays["logp"]
        med = window_median(logp, starts, arrays["use"], need=self.need)
        # a one-sample jump kicks the loops and the error rings for a second or more: a
        # window holding one is the spike detector's, not a sample of the spectrum
        spiky = np.add.reduceat(arrays["spiky"], starts) > 0 if len(starts) else \
            np.zeros(0, bool)
        med[spiky] = np.nan
        return {"median": med}

    def fit(self, chunk: Chunk, ref: np.ndarray) -> Check:
        bp = chunk.seg.features[f"{self.axis}.error_band_power"]
        rows = self.use(chunk) & ref
        # The encoder's count quantises the error: its sawtooth puts up to n/12·q² (one
        # count q, n samples a segment) into whichever band the count rate's harmonics
        # alias to, and the count rate follows the speed — a tone that comes and goes
        # with the target, a hundredfold between two stars. A band is flagged only when
        # louder than that bound, and the reference's spread (which such tones inflate)
        # widens the limit at most up to it. (Twice the bound, as before, hid resonance
        # growth that the bound alone lets through without a false flag on the
        # benchmark's tuning nights.)
        step = chunk.seg.features.get(f"{self.axis}.position_step_rad")
        # one count: the smallest step of segments that move by less than a count a
        # sample (a low percentile: faster segments step by several counts)
        q_rad = float(np.nanpercentile(step[rows], 10)) if step is not None and \
            np.isfinite(step[rows]).any() else 0.0
        self.count_arcsec = q_rad * ARCSEC_PER_RAD
        bound = SEGMENT_SAMPLES / 12.0 * self.count_arcsec ** 2
        self.quantisation_log = math.log10(bound) if bound > 0 else -math.inf
        # a band silent on the reference has no usual level to compare with
        self.bands = np.flatnonzero(np.median(bp[rows], axis=0) > 0) if rows.any() \
            else np.zeros(0, np.int64)
        if len(self.bands) == 0:
            self.plan = {}
            return Check(self.kind, self.axis, self.signals, False,
                         "the tracking error is silent in every band on the reference")
        return super().fit(chunk, ref)

    def fit_classes(self, stats, cls, seconds):
        med_w = stats["median"]
        ok = np.all(np.isfinite(med_w), axis=1)
        held, why = self._held(ok, cls, seconds)
        self.plan = class_plan(held, why)
        floor = math.log10(self.cfg.vibration_floor_ratio)
        for c in AXIS_CLASSES:
            if held[c]:
                rows = med_w[ok & (cls == c)]
                center, _ = robust_center_scale(rows)
                # below the quantisation bound a band's level says nothing about the
                # mount: the spread is taken with such levels raised to the bound
                lifted, sigma = robust_center_scale(np.maximum(rows, self.quantisation_log))
                level = np.maximum.reduce([center + floor, lifted + self.cfg.threshold * sigma,
                                           np.full_like(center, self.quantisation_log)])
                self.center[c] = center
                self.limit[c] = level - center

    def window_scores(self, stats, cls):
        wm = stats["median"]
        k = wm.shape[1]
        center = self._lookup(self.center, cls, k)
        limit = self._lookup(self.limit, cls, k)
        z = (wm - center) / limit  # louder only: a quieter mount is no fault
        finite = np.where(np.isfinite(z), z, -np.inf)
        score = finite.max(axis=1) if k else np.full(len(cls), np.nan)
        score = np.where(np.isfinite(score), score, np.nan)
        band = finite.argmax(axis=1) if k else np.zeros(len(cls), np.int64)
        details = []
        for w in range(len(score)):
            if not (np.isfinite(score[w]) and score[w] >= 1.0):
                details.append("")
                continue
            b = self.bands[band[w]]
            ratio = 10 ** (wm[w, band[w]] - center[w, band[w]])
            details.append(f"tracking-error power ×{ratio:.1f} in {self.edges[b]:g}–"
                           f"{self.edges[b + 1]:g} Hz while {CLASS_NAMES.get(int(cls[w]), '?')}")
        return score, details
