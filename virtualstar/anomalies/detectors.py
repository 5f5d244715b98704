"""The detectors: each turns segments into window scores against its reference.

Every detector compares a window statistic with the same statistic on the reference
(where the mount is taken to behave as itself), **per class** — the motion phase and,
per axis, the speed regime (anomalies.phases) — and never puts two classes in one
window. The limit is ``threshold`` robust sigmas of the reference windows of the class
(median absolute deviation), never less than an absolute floor that says what is too
small to matter; a score of 1 is the limit, so scores of different kinds read alike.

| kind | signals | statistic per window | classes |
|---|---|---|---|
| current | position, current | mean of current − model(position, velocity, acceleration) | rest, sidereal, satellite, slewing |
| vibration | error_arcsec | median log power of the tracking error per octave band | rest, sidereal, satellite, slewing |
| spike | error_arcsec, current | largest one-sample second difference per segment | rest, sidereal, satellite, slewing |
| temperature | temperature | slope of the winding temperature, K/h | powered |
| clock | t_us | sample spacing in mount µs (sync steps left out): the clock rate, ppm | all |

A class the reference holds too little of (fewer than `min_windows` windows or
`min_class_s` seconds) is scored against the next more dynamic class it holds — at rest
against sidereal tracking, sidereal against satellite rates, satellite rates against
slews: the louder class's limits are wider, so this can miss, never invent — or not at
all; every detector's `Check` says which classes it scored and why not the others.

Detectors are fitted once on the reference (`fit`), then score chunk after chunk
(`score`): a window is scored when it closes, so a night scored in one piece and one
scored minute by minute give the same windows and the same scores.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .current_model import CurrentModel, fit_current_model
from .phases import (
    AXIS_CLASSES,
    CLASS_NAMES,
    EXCLUDED,
    FAST,
    FASTER,
    REST,
    SLEW,
    MotionPhase,
    PhaseConfig,
)
from .reference import ReferenceConfig
from .robust import robust_center_scale
from .segments import SEGMENT_SAMPLES, Segments
from .windows import WindowCutter, class_window_starts, window_mean, window_median

__all__ = ["Anomaly", "Check", "Chunk", "DetectorConfig", "ScoreTrace", "Window",
           "build_detectors"]

POWERED = 0  # the one class of the temperature detector
ALL = 0  # the one class of the clock detector
CLOCK_STEP_US = 2.0  # a segment whose span is this far off its window's median holds a clock step
ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0


@dataclass(frozen=True)
class DetectorConfig:
    """Windows (s), thresholds (robust sigmas) and absolute floors of the detectors."""

    threshold: float = 8.0
    current_window_s: float = 10.0
    current_floor_a: float = 0.01
    current_ref_factor: float = 2.0  # × the largest deviation of a reference window
    # the current detector scores a segment only when its class held coverage_min_s of
    # reference within coverage_ratio of its speed; its limit widens by coverage_factor ×
    # the model's d(current)/d|v| × the distance to their median (CurrentDetector)
    coverage_ratio: float = 1.1
    coverage_min_s: float = 10.0
    coverage_factor: float = 2.0
    vibration_window_s: float = 30.0
    vibration_floor_ratio: float = 16.0  # power × this at least (amplitude × 4)
    spike_factor: float = 5.0  # × the largest spike of the class on the reference
    # At satellite rates and in slews the tracking error jumps where the trajectory's
    # pieces meet: up to 0.6″ in one sample on the emulator's fastest passes, more than a
    # reference pass of lower rates shows. An error jump smaller than this is no glitch
    # there (the current's jumps still count with their own limit).
    spike_fast_floor_arcsec: float = 1.0
    spike_merge_s: float = 10.0
    temperature_window_s: float = 120.0
    temperature_floor_k_h: float = 3.0
    clock_window_s: float = 60.0
    clock_floor_ppm: float = 0.5
    cogging_periods: int | None = None  # None: estimated; 0: no cogging term
    merge_s: float = 120.0  # flagged windows this close are one anomaly
    min_windows: int = 3  # reference windows a class needs to be scored against itself
    phases: PhaseConfig = field(default_factory=PhaseConfig)
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)


@dataclass(frozen=True)
class Anomaly:
    """A flagged stretch: mount time µs [start, end), the kind, its signals, its score."""

    start_us: int
    end_us: int
    kind: str
    signals: tuple[str, ...]
    score: float
    axis: str = ""
    detail: str = ""

    def as_dict(self) -> dict[str, object]:
        from virtualstar.recorder.parquet_store import utc_text

        return {"start_utc": utc_text(self.start_us), "end_utc": utc_text(self.end_us),
                "start_t_us": self.start_us, "end_t_us": self.end_us, "kind": self.kind,
                "signals": list(self.signals), "score": round(self.score, 3),
                "axis": self.axis, "detail": self.detail}


@dataclass
class ScoreTrace:
    """A detector's score over time (for plots): window starts (µs) and scores."""

    name: str
    t_us: np.ndarray
    score: np.ndarray
    info: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class Check:
    """What one detector did: on which signals, which classes it scored (and against
    what), which it could not and why; or why it did not run at all."""

    detector: str
    axis: str
    signals: tuple[str, ...]
    ran: bool
    reason: str = ""
    classes: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return {"detector": self.detector, "axis": self.axis, "signals": list(self.signals),
                "ran": self.ran, "reason": self.reason, "classes": dict(self.classes)}

    def line(self) -> str:
        """One line for the terminal."""
        where = f"{self.detector} {self.axis}".strip()
        if not self.ran:
            return f"{where}: did not run — {self.reason}"
        scored = [c for c, note in self.classes.items() if not note.startswith("not scored")]
        notes = "; ".join(f"{c}: {note}" for c, note in self.classes.items()
                          if note != "scored")
        return (f"{where} ({', '.join(self.signals)}): ran on "
                f"{', '.join(scored) or 'nothing'}" + (f"; {notes}" if notes else ""))


@dataclass(frozen=True)
class Window:
    """A scored window: mount µs [start, end), its score and (when flagged) why."""

    start_us: int
    end_us: int
    score: float
    detail: str = ""


@dataclass
class Chunk:
    """Consecutive segments with what the detectors need besides their features."""

    seg: Segments
    phase: np.ndarray  # MotionPhase codes
    valid: np.ndarray  # no recording gap or clock step inside the segment
    breaks: np.ndarray  # a window must begin here (a gap; the join of two stretches)
    classes: dict[str, np.ndarray]  # per axis: anomalies.phases classes
    calm: dict[str, np.ndarray] = field(default_factory=dict)  # per axis: no spike inside

    def __len__(self) -> int:
        return len(self.seg)


def _class_plan(held: dict[int, bool], why: dict[int, str]) -> dict[int, tuple[int | None, str]]:
    """For each class: the class whose reference it is scored against, and a note."""
    plan: dict[int, tuple[int | None, str]] = {}
    for c in AXIS_CLASSES:
        if held.get(c):
            plan[c] = (c, "scored")
            continue
        louder = [d for d in AXIS_CLASSES if d > c and held.get(d)]
        if louder:
            plan[c] = (louder[0], f"scored against {CLASS_NAMES[louder[0]]} ({why[c]})")
        else:
            plan[c] = (None, f"not scored: {why[c]}")
    return plan


class _Detector:
    """A detector over class windows of one axis (or of the mount)."""

    kind = ""
    window_s = 1.0
    need_share = 0.25  # a window needs this share of its segments usable

    def __init__(self, axis: str, signals: tuple[str, ...], cfg: DetectorConfig,
                 seg_s: float) -> None:
        self.axis = axis
        self.signals = signals
        self.cfg = cfg
        self.seg_s = seg_s
        self.per = max(1, round(self._window_s() / seg_s))
        self.need = max(1, math.ceil(self.per * self.need_share))
        self.cutter = WindowCutter(self.per)
        self.plan: dict[int, tuple[int | None, str]] = {}
        self.trace_t: list[np.ndarray] = []
        self.trace_score: list[np.ndarray] = []

    def _window_s(self) -> float:
        return self.window_s

    @property
    def name(self) -> str:
        return f"{self.axis} {self.kind}".strip()

    # -- per detector ------------------------------------------------------------------
    def classes(self, chunk: Chunk) -> np.ndarray:
        return chunk.classes[self.axis]

    def use(self, chunk: Chunk) -> np.ndarray:
        return chunk.calm[self.axis] & (self.classes(chunk) != EXCLUDED)

    def values(self, chunk: Chunk) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def stats(self, arrays: dict[str, np.ndarray], starts: np.ndarray) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def fit_classes(self, stats: dict[str, np.ndarray], cls: np.ndarray,
                    seconds: dict[int, float]) -> None:
        raise NotImplementedError

    def window_scores(self, stats: dict[str, np.ndarray], cls: np.ndarray
                      ) -> tuple[np.ndarray, list[str]]:
        raise NotImplementedError

    # -- shared ------------------------------------------------------------------------
    def _arrays(self, chunk: Chunk) -> dict[str, np.ndarray]:
        arrays = self.values(chunk)
        arrays.update(cls=self.classes(chunk), use=self.use(chunk), breaks=chunk.breaks,
                      t_first=chunk.seg.t_first_us, t_last=chunk.seg.t_last_us)
        return arrays

    def fit(self, chunk: Chunk, ref: np.ndarray) -> Check:
        """Learn the reference's statistics per class from the rows `ref` of `chunk`."""
        arrays = self._arrays(chunk)
        arrays["use"] = arrays["use"] & ref
        starts = class_window_starts(arrays["cls"], self.per, arrays["breaks"])
        stats = self.stats(arrays, starts)
        cls = arrays["cls"][starts]
        seconds = {c: float(np.sum(arrays["use"] & (arrays["cls"] == c))) * self.seg_s
                   for c in set(AXIS_CLASSES) | {POWERED}}
        self.fit_classes(stats, cls, seconds)
        return self.check()

    def check(self) -> Check:
        classes = {CLASS_NAMES[c]: note for c, (_, note) in self.plan.items()}
        if not any(b is not None for b, _ in self.plan.values()):
            return Check(self.kind, self.axis, self.signals, False,
                         "the reference holds too little of every phase", classes)
        return Check(self.kind, self.axis, self.signals, True, classes=classes)

    def _held(self, stat_ok: np.ndarray, cls: np.ndarray, seconds: dict[int, float],
              classes=AXIS_CLASSES) -> tuple[dict[int, bool], dict[int, str]]:
        held, why = {}, {}
        for c in classes:
            n = int(np.sum(stat_ok & (cls == c)))
            s = seconds.get(c, 0.0)
            held[c] = n >= self.cfg.min_windows and s >= self.cfg.reference.min_class_s
            why[c] = (f"the reference holds {s:.0f} s of it in {n} windows; "
                      f"{self.cfg.reference.min_class_s:.0f} s and {self.cfg.min_windows} "
                      "windows needed")
        return held, why

    def score(self, chunk: Chunk | None, *, final: bool = False) -> list[Window]:
        """Score the windows of `chunk` that close (all of them when `final`; `chunk` None:
        only what is pending); return the flagged ones (score >= 1; the scores of all go
        to the trace)."""
        arrays, starts, closed = self.cutter.push(
            None if chunk is None else self._arrays(chunk), final=final)
        if closed == 0:
            return []
        n_used = int(starts[closed]) if closed < len(starts) else len(arrays["cls"])
        part = {k: v[:n_used] for k, v in arrays.items()}
        starts = starts[:closed]
        stats = self.stats(part, starts)
        cls = part["cls"][starts]
        score, details = self.window_scores(stats, cls)
        ends = np.r_[starts[1:], n_used] - 1
        t0 = part["t_first"][starts]
        t1 = part["t_last"][ends] + 1
        self.trace_t.append(t0)
        self.trace_score.append(score)
        return [Window(int(t0[k]), int(t1[k]), float(score[k]), details[k])
                for k in np.flatnonzero(np.nan_to_num(score, nan=0.0) >= 1.0)]

    def trace(self) -> ScoreTrace:
        t = np.concatenate(self.trace_t) if self.trace_t else np.zeros(0, np.int64)
        s = np.concatenate(self.trace_score) if self.trace_score else np.zeros(0)
        return ScoreTrace(self.name, t, s)

    def _basis(self, cls: np.ndarray) -> np.ndarray:
        """Per window, the class whose reference it is scored against (-1: none)."""
        table = np.full(max(AXIS_CLASSES) + 2, -1, dtype=np.int64)
        for c, (b, _) in self.plan.items():
            table[c] = -1 if b is None else b
        return np.where(cls >= 0, table[np.maximum(cls, 0)], -1)

    def _lookup(self, per_class: dict[int, object], cls: np.ndarray, k: int | None = None
                ) -> np.ndarray:
        """Per window, the value of `per_class` for the class it is scored against (NaN
        where none): a table indexed at once, not a loop over windows."""
        shape = (max(AXIS_CLASSES) + 2,) + (() if k is None else (k,))
        table = np.full(shape, np.nan)
        for c, value in per_class.items():
            table[c] = value
        basis = self._basis(cls)
        return table[np.where(basis >= 0, basis, len(table) - 1)]


class CurrentDetector(_Detector):
    """Flag windows whose current departs from the motion model (friction, winding)."""

    kind = "current"

    def _window_s(self) -> float:
        return self.cfg.current_window_s

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.model: CurrentModel | None = None
        self._edge_accel = 0.5 * math.radians(self.cfg.phases.slew_accel_deg_s2)
        self.rest_rad_s = math.radians(self.cfg.phases.rest_rate_arcsec_s / 3600.0)
        self.ref_speeds: dict[int, np.ndarray] = {}
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
        # a segment in which a slew starts or stops crosses the friction's knee: its mean
        # current is no function of its mean speed
        edge = (self.classes(chunk) == SLEW) & (np.abs(a) > self._edge_accel) & \
            (np.abs(v) < np.abs(a) * self.seg_s)
        return super().use(chunk) & ~edge & ~at_rest

    def values(self, chunk: Chunk) -> dict[str, np.ndarray]:
        p, v, a, i = self._motion(chunk)
        assert self.model is not None, "fit before scoring"
        resid = i - self.model.predict(p, v, a)
        # Speeds the reference did not hold: below a few hundred arcseconds per second the
        # dry friction changes steeply with speed, and the model there is an extrapolation
        # from the speeds it saw. A segment is scored only when its class held
        # `coverage_min_s` of reference at speeds within `coverage_ratio` of its own; its
        # limit widens by coverage_factor × the model's slope × its distance to their
        # median speed.
        allowance = np.zeros(len(p))
        covered = np.zeros(len(p), bool)
        cls = self.classes(chunk)
        need = max(1, round(self.cfg.coverage_min_s / self.seg_s))
        for c, speeds in self.ref_speeds.items():
            rows = np.flatnonzero(cls == c)
            if len(rows) == 0 or len(speeds) < need:
                continue
            s = np.abs(v[rows])
            lo = np.searchsorted(speeds, s / self.cfg.coverage_ratio)
            hi = np.searchsorted(speeds, s * self.cfg.coverage_ratio, side="right")
            covered[rows] = hi - lo >= need
            middle = speeds[np.clip((lo + hi) // 2, 0, len(speeds) - 1)]
            allowance[rows] = np.abs(s - middle) * \
                self.model.slope_a_per_rad_s(p[rows], v[rows], a[rows])
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
        # speeds held steadily (changing by under 10 % within a segment): a run-up
        # sweeping through a speed says little about the friction there
        steady = np.abs(a) * self.seg_s <= 0.1 * np.abs(v)
        self.ref_speeds = {c: np.sort(np.abs(v[rows & steady & (cls == c)]))
                           for c in AXIS_CLASSES}
        return super().fit(chunk, ref)

    def fit_classes(self, stats, cls, seconds):
        mean = stats["mean"]
        held, why = self._held(np.isfinite(mean), cls, seconds)
        self.plan = _class_plan(held, why)
        self.plan[REST] = (None, "not scored: dry friction holds an axis at rest anywhere "
                                 "within its breakaway torque, so the holding current says "
                                 "nothing")
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


class VibrationDetector(_Detector):
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
        # louder than twice that bound, and the reference's spread (which such tones
        # inflate) widens the limit at most up to it.
        step = chunk.seg.features.get(f"{self.axis}.position_step_rad")
        # one count: the smallest step of segments that move by less than a count a
        # sample (a low percentile: faster segments step by several counts)
        q_rad = float(np.nanpercentile(step[rows], 10)) if step is not None and \
            np.isfinite(step[rows]).any() else 0.0
        self.count_arcsec = q_rad * ARCSEC_PER_RAD
        bound = 2.0 * SEGMENT_SAMPLES / 12.0 * self.count_arcsec ** 2
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
        self.plan = _class_plan(held, why)
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


class SpikeDetector(_Detector):
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
        self.plan = _class_plan(held, why)
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


class TemperatureDetector(_Detector):
    """Flag windows whose winding temperature climbs unlike its trend on the reference."""

    kind = "temperature"
    need_share = 0.5

    def _window_s(self) -> float:
        return self.cfg.temperature_window_s

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.center = math.nan
        self.limit = math.nan
        self.reason = ""

    def classes(self, chunk):
        return np.where(chunk.phase == MotionPhase.OFF, EXCLUDED, POWERED)

    def use(self, chunk):
        return chunk.valid & (self.classes(chunk) != EXCLUDED)

    def values(self, chunk):
        return {"temp": chunk.seg.features[f"{self.axis}.temperature_c"],
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
        return {"slope": np.where(n >= max(3, self.need), slope * 3600.0, np.nan)}

    def fit_classes(self, stats, cls, seconds):
        s = stats["slope"]
        ok = np.isfinite(s) & (cls == POWERED)
        n = int(ok.sum())
        if n < self.cfg.min_windows:
            self.plan = {}
            self.reason = (f"the reference holds {n} windows of {self.window_s:.0f} s with "
                           f"the mount powered; {self.cfg.min_windows} needed")
            return
        med, sigma = robust_center_scale(s[ok])
        self.center = float(med)
        self.limit = max(self.cfg.threshold * float(sigma), self.cfg.temperature_floor_k_h)
        self.plan = {POWERED: (POWERED, "scored")}

    def check(self):
        if not self.plan:
            return Check(self.kind, self.axis, self.signals, False, self.reason)
        return Check(self.kind, self.axis, self.signals, True,
                     f"usual trend {self.center:+.2f} K/h, limit ±{self.limit:.2f} K/h",
                     {"powered (any motion)": "scored"})

    def window_scores(self, stats, cls):
        dev = stats["slope"] - self.center
        score = np.where(cls == POWERED, np.abs(dev) / self.limit, np.nan)
        details = [f"temperature changing {dev[k]:+.1f} K/h off its usual trend (limit "
                   f"{self.limit:.1f} K/h)" if np.isfinite(score[k]) and score[k] >= 1.0
                   else "" for k in range(len(score))]
        return score, details


class ClockDetector(_Detector):
    """Flag windows whose sample spacing (mount µs) says the clock runs at another rate.

    A mount whose clock is set to UTC now and then (the VSS's TimeS, every ~11 s) steps
    back by what it drifted: the few segments holding a step are left out of each window
    (span off the window's median by more than CLOCK_STEP_US), so the statistic is the
    rate between the steps — what the crystal does."""

    kind = "clock"
    need_share = 0.5

    def _window_s(self) -> float:
        return self.cfg.clock_window_s

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.center = math.nan
        self.limit = math.nan
        self.reason = ""

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
        per_seg = np.repeat(med, lengths)
        keep = use & (np.abs(span - per_seg) <= CLOCK_STEP_US)
        mean = window_mean(span, starts, keep, need=self.need)
        return {"spacing": mean / (SEGMENT_SAMPLES - 1)}

    def fit_classes(self, stats, cls, seconds):
        s = stats["spacing"]
        ok = np.isfinite(s)
        if int(ok.sum()) < self.cfg.min_windows:
            self.plan = {}
            self.reason = (f"the reference holds {int(ok.sum())} windows of "
                           f"{self.window_s:.0f} s without gaps; {self.cfg.min_windows} needed")
            return
        med, sigma = robust_center_scale(s[ok])
        self.center = float(med)
        sigma_ppm = float(sigma) / self.center * 1e6
        self.limit = max(self.cfg.threshold * sigma_ppm, self.cfg.clock_floor_ppm)
        self.plan = {ALL: (ALL, "scored")}

    def check(self):
        if not self.plan:
            return Check(self.kind, self.axis, self.signals, False, self.reason)
        return Check(self.kind, self.axis, self.signals, True,
                     f"limit ±{self.limit:.2f} ppm", {"all (any motion, powered or not)":
                                                      "scored"})

    def window_scores(self, stats, cls):
        ppm = (stats["spacing"] / self.center - 1.0) * 1e6
        score = np.abs(ppm) / self.limit
        details = [f"mount clock rate {ppm[k]:+.2f} ppm off its usual (limit "
                   f"{self.limit:.2f} ppm)" if np.isfinite(score[k]) and score[k] >= 1.0
                   else "" for k in range(len(score))]
        return score, details


def build_detectors(axes: dict[str, dict[str, str]], cfg: DetectorConfig, seg_s: float
                    ) -> tuple[list[_Detector], list[Check]]:
    """Return the detectors the recorded signals allow (spikes first: the others leave
    out the segments a spike is in) and a Check for each that cannot run, with why."""
    dets: list[_Detector] = []
    missing: list[Check] = []
    for axis, names in axes.items():
        roles = tuple(r for r, role in (("error_spike_arcsec", "error_arcsec"),
                                        ("current_spike_a", "current")) if role in names)
        sigs = tuple(names[role] for role in ("error_arcsec", "current") if role in names)
        if roles:
            dets.append(SpikeDetector(axis, sigs, cfg, seg_s, roles))
        else:
            missing.append(Check("spike", axis, (), False,
                                 f"needs axis.{axis}.error_arcsec or axis.{axis}.current; "
                                 "the store records neither"))
        if {"position", "current"} <= names.keys():
            dets.append(CurrentDetector(axis, (names["position"], names["current"]), cfg,
                                        seg_s))
        else:
            lack = [f"axis.{axis}.{r}" for r in ("position", "current") if r not in names]
            missing.append(Check("current", axis, (), False,
                                 f"needs axis.{axis}.position and axis.{axis}.current; the "
                                 f"store has no {' and no '.join(lack)}"))
        if "error_arcsec" in names:
            dets.append(VibrationDetector(axis, (names["error_arcsec"],), cfg, seg_s))
        else:
            missing.append(Check("vibration", axis, (), False,
                                 f"needs axis.{axis}.error_arcsec; the store has none"))
        if "temperature" in names:
            dets.append(TemperatureDetector(axis, (names["temperature"],), cfg, seg_s))
        else:
            missing.append(Check("temperature", axis, (), False,
                                 f"needs axis.{axis}.temperature; the store has none"))
    dets.append(ClockDetector("", ("t_us",), cfg, seg_s))
    return dets, missing
