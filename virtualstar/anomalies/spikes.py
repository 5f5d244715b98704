"""The spike detector: one-sample jumps of the error and the current, per class."""

from __future__ import annotations

import numpy as np

from .detectors import Chunk, Detector, class_plan
from .phases import AXIS_CLASSES, CLASS_NAMES, EXCLUDED, FAST, FASTER, SLEW
from .windows import WindowCutter

__all__ = ["SpikeDetector"]

class SpikeDetector(Detector):
    """Flag segments holding a one-sample jump far beyond any of their class on the
    reference (each segment is a window)."""

    kind = "spike"

    def _window_s(self) -> float:
        return self.seg_s  # one segment

    def __init__(self, axis, signals, cfg, seg_s, roles: tuple[str, ...]) -> None:
        super().__init__(axis, signals, cfg, seg_s)
        self.roles = roles  # ("error_spike_arcsec", "current_spike_a") present
        self.per = 1
        self.need = 1
        self.cutter = WindowCutter(1)
        self.usual: dict[int, np.ndarray] = {}

    def use(self, chunk):
        return chunk.valid & (self.classes(chunk) != EXCLUDED)

    def values(self, chunk):
        f = chunk.seg.features
        return {"spikes": np.stack([f[f"{self.axis}.{r}"] for r in self.roles], axis=1)}

    def stats(self, arrays, starts):
        x = arrays["spikes"][starts]
        return {"spikes": np.where(arrays["use"][starts][:, None], x, np.nan)}

    def flags(self, chunk: Chunk) -> np.ndarray:
        """True for the segments of `chunk` holding a spike (no state is changed)."""
        arrays = self._arrays(chunk)
        starts = np.arange(len(chunk), dtype=np.int64)
        score, _ = self.window_scores(self.stats(arrays, starts), arrays["cls"])
        return np.nan_to_num(score, nan=0.0) >= 1.0

    def fit_classes(self, stats, cls, seconds):
        x = stats["spikes"]
        ok = np.all(np.isfinite(x), axis=1)
        held, why = self._held(ok, cls, seconds)
        self.plan = class_plan(held, why)
        error = self.roles.index("error_spike_arcsec") if "error_spike_arcsec" in self.roles \
            else None
        for c in AXIS_CLASSES:
            if held[c]:
                usual = np.max(x[ok & (cls == c)], axis=0)
                if error is not None and c in (FAST, FASTER, SLEW):
                    usual[error] = max(usual[error],
                                       self.cfg.spike_fast_floor_arcsec / self.cfg.spike_factor)
                self.usual[c] = usual

    def window_scores(self, stats, cls):
        x = stats["spikes"]
        usual = self._lookup(self.usual, cls, x.shape[1])
        with np.errstate(invalid="ignore"):
            ratio = x / np.maximum(self.cfg.spike_factor * usual, 1e-12)
        finite = np.where(np.isfinite(ratio), ratio, -np.inf)
        score = finite.max(axis=1) if len(cls) else np.zeros(0)
        score = np.where(np.isfinite(score), score, np.nan)
        details = [""] * len(score)
        for w in np.flatnonzero(np.nan_to_num(score, nan=0.0) >= 1.0):
            details[w] = (f"one-sample jump ×{score[w]:.1f} the limit in "
                          f"{self.signals[int(np.argmax(finite[w]))]} while "
                          f"{CLASS_NAMES.get(int(cls[w]), '?')}")
        return score, details
