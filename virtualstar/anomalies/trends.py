"""The slow detectors: the winding temperature's trend and the mount clock's rate.

Neither depends on the motion's class: one statistic per window over every usable segment
(the temperature's while the mount is powered, the clock's always), its median and robust
sigma on the reference, a limit of `threshold` sigmas never below a floor.
"""

from __future__ import annotations

import math

import numpy as np

from .detectors import Check, Detector
from .phases import EXCLUDED, MotionPhase
from .robust import robust_center_scale
from .segments import SEGMENT_SAMPLES
from .windows import window_mean, window_median

__all__ = ["ClockDetector", "TemperatureDetector"]

ONE = 0  # the one class of these detectors
CLOCK_STEP_US = 2.0  # a segment whose span is this far off its window's median holds a clock step


class _Trend(Detector):
    """One class; the statistic in its own unit (`unit`), deviation both ways."""

    need_share = 0.5
    unit = ""
    scope = ""  # what is scored, for the report
    stat = ""  # the key of the window statistic

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.center = math.nan
        self.limit = math.nan
        self.reason = ""

    def floor(self) -> float:
        raise NotImplementedError

    def to_unit(self, value: np.ndarray) -> np.ndarray:
        """The statistic as a deviation from the centre, in `unit`."""
        return value - self.center

    def fit_classes(self, stats, cls, seconds):
        s = stats[self.stat]
        ok = np.isfinite(s) & (cls == ONE)
        n = int(ok.sum())
        if n < self.cfg.min_windows:
            self.plan = {}
            self.reason = (f"the reference holds {n} windows of {self._window_s():.0f} s "
                           f"({self.scope}); {self.cfg.min_windows} needed")
            return
        med, sigma = robust_center_scale(s[ok])
        self.center = float(med)
        sigma_unit = abs(float(self.to_unit(np.array([med + sigma]))[0]))
        self.limit = max(self.cfg.threshold * sigma_unit, self.floor())
        self.plan = {ONE: (ONE, "scored")}

    def check(self) -> Check:
        if not self.plan:
            return Check(self.kind, self.axis, self.signals, False, self.reason)
        return Check(self.kind, self.axis, self.signals, True,
                     f"limit ±{self.limit:.2f} {self.unit}", {self.scope: "scored"})

    def window_scores(self, stats, cls):
        dev = self.to_unit(stats[self.stat])
        score = np.where(cls == ONE, np.abs(dev) / self.limit, np.nan)
        details = [self.detail(dev[k]) if np.isfinite(score[k]) and score[k] >= 1.0 else ""
                   for k in range(len(score))]
        return score, details

    def detail(self, dev: float) -> str:
        raise NotImplementedError


class TemperatureDetector(_Trend):
    """Flag windows whose winding temperature climbs unlike the heat its current explains.

    A winding warms at C·dT/dt = I²R − (T − T_ambient)/R_th: its trend follows the square
    of the current. On an elevation axis the current holding the tube against gravity
    changes with the elevation, and slews add more, so the trend of a 120-s window moves
    by several K/h with the motion (on a fresh night's reference: 8 robust σ = 6.6 K/h,
    the window slopes correlated 0.90 with the windows' mean I²), more than an injected
    heat of 12 W/h adds in the nine minutes the night had left (≈ 4 K/h). So, when the
    axis records its current, the reference's window slopes are fitted as
    slope ≈ c + h·⟨I²⟩ (h ≥ 0: K/h per A², the winding's R·R_th/τ) and each window is
    scored by its slope minus that; the cooling towards ambient, (T − T_amb)/τ, stays in
    the residual (a winding within 0.5 K of its reference temperature moves it by
    ≲ 2 K/h at τ = 15 min, inside the floor). Without a current h is 0: the reference's
    usual trend, as before."""

    kind = "temperature"
    unit = "K/h"
    scope = "powered (any motion)"
    stat = "slope"

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.heat_k_h_per_a2 = 0.0

    def _window_s(self) -> float:
        return self.cfg.temperature_window_s

    def floor(self) -> float:
        return self.cfg.temperature_floor_k_h

    def classes(self, chunk):
        return np.where(chunk.phase == MotionPhase.OFF, EXCLUDED, ONE)

    def use(self, chunk):
        return chunk.valid & (self.classes(chunk) != EXCLUDED)

    def values(self, chunk):
        f = chunk.seg.features
        heat = f.get(f"{self.axis}.current_sq_a2")
        return {"temp": f[f"{self.axis}.temperature_c"],
                "heat": np.zeros(len(chunk)) if heat is None else heat,
                "t_us": chunk.seg.t_mid_us.astype(np.float64)}

    def stats(self, arrays, starts):
        use = arrays["use"]
        t = (arrays["t_us"] - (arrays["t_us"][0] if len(use) else 0.0)) * 1e-6
        y = arrays["temp"]
        n = np.add.reduceat(use.astype(np.float64), starts) if len(starts) else np.zeros(0)
        mt = window_mean(t, starts, use)
        my = window_mean(y, starts, use)
        mtt = window_mean(t * t, starts, use)
        mty = window_mean(t * y, starts, use)
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = (mty - mt * my) / (mtt - mt * mt)
        return {"slope": np.where(n >= max(3, self.need), slope * 3600.0, np.nan),
                "heat": window_mean(arrays["heat"], starts, use)}

    def fit_classes(self, stats, cls, seconds):
        s, heat = stats["slope"], stats["heat"]
        ok = np.isfinite(s) & np.isfinite(heat) & (cls == ONE)
        self.heat_k_h_per_a2 = 0.0
        if ok.sum() >= self.cfg.min_windows and np.ptp(heat[ok]) > 0:
            x = np.stack([np.ones(int(ok.sum())), heat[ok]], axis=1)
            coef = np.linalg.lstsq(x, s[ok], rcond=None)[0]
            self.heat_k_h_per_a2 = max(0.0, float(coef[1]))  # a current cannot cool
        super().fit_classes({"slope": self._unheated(stats)}, cls, seconds)

    def _unheated(self, stats) -> np.ndarray:
        """The window slopes less what the current's heat explains (K/h)."""
        return stats["slope"] - self.heat_k_h_per_a2 * np.nan_to_num(stats["heat"])

    def window_scores(self, stats, cls):
        return super().window_scores({"slope": self._unheated(stats)}, cls)

    def check(self) -> Check:
        c = super().check()
        if not c.ran or len(self.signals) < 2:
            return c
        return Check(c.detector, c.axis, c.signals, c.ran,
                     f"{c.reason}; heating {self.heat_k_h_per_a2:.2f} K/h per A² of current "
                     "fitted on the reference and taken out of the trend", c.classes)

    def detail(self, dev: float) -> str:
        return (f"temperature changing {dev:+.1f} K/h off its usual trend and the heat of "
                f"its current (limit {self.limit:.1f} K/h)")


class ClockDetector(_Trend):
    """Flag windows whose sample spacing (mount µs) says the clock runs at another rate.

    A mount whose clock is set to UTC now and then (the VSS's TimeS, every ~11 s) steps
    back by what it drifted: the few segments holding a step are left out of each window
    (span off the window's median by more than CLOCK_STEP_US), so the statistic is the
    rate between the steps — what the crystal does."""

    kind = "clock"
    unit = "ppm"
    scope = "all (any motion, powered or not)"
    stat = "spacing"

    def _window_s(self) -> float:
        return self.cfg.clock_window_s

    def floor(self) -> float:
        return self.cfg.clock_floor_ppm

    def to_unit(self, value):
        return (value / self.center - 1.0) * 1e6

    def classes(self, chunk):
        return np.zeros(len(chunk), dtype=np.int64)

    def use(self, chunk):
        return chunk.valid.copy()

    def values(self, chunk):
        return {"span": (chunk.seg.t_last_us - chunk.seg.t_first_us).astype(np.float64)}

    def stats(self, arrays, starts):
        span, use = arrays["span"], arrays["use"]
        med = window_median(span[:, None], starts, use)[:, 0]
        lengths = np.diff(np.r_[starts, len(span)])
        keep = use & (np.abs(span - np.repeat(med, lengths)) <= CLOCK_STEP_US)
        mean = window_mean(span, starts, keep, need=self.need)
        return {"spacing": mean / (SEGMENT_SAMPLES - 1)}

    def detail(self, dev: float) -> str:
        return f"mount clock rate {dev:+.2f} ppm off its usual (limit {self.limit:.2f} ppm)"
