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

from .phases import AXIS_CLASSES, CLASS_NAMES, EXCLUDED, PhaseConfig
from .reference import ReferenceConfig
from .segments import Segments
from .windows import WindowCutter, class_window_starts

__all__ = ["POOLED", "Anomaly", "Check", "Chunk", "Detector", "DetectorConfig", "ScoreTrace",
           "Window", "class_plan"]

# the reference's windows of every class together: what a detector may score a class
# against that the reference holds too little of, when it has no louder class to use
POOLED = max(AXIS_CLASSES) + 1


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
    # Scale statistics (CurrentDetector): per window, the residual regressed on the
    # modelled current (its gain: a winding fault scales the whole current) and on the
    # model's dry-friction current (a bearing's friction growth scales that term), scored
    # at every speed and in slews where that current is at least *_min_a RMS. The limit
    # is the larger of the floor and `threshold` robust sigmas of the reference windows,
    # plus the model's uncertainty there (scale_uncertainty_factor × (its reference RMS +
    # the speed allowance) ÷ the window's RMS current).
    gain_floor: float = 0.035
    gain_min_a: float = 0.05
    friction_scale_floor: float = 0.08
    friction_min_a: float = 0.03
    scale_uncertainty_factor: float = 3.0
    # Every current statistic's limit also widens by this many standard deviations of
    # the statistic's model error: the coefficients' covariance on the reference
    # (clustered by window) propagated to the window scored (CurrentDetector.stats)
    model_sd_factor: float = 3.0
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


def class_plan(held: dict[int, bool], why: dict[int, str]) -> dict[int, tuple[int | None, str]]:
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


class Detector:
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
        for key in [k for k in arrays if k.startswith("use")]:  # "use" and its variants
            arrays[key] = arrays[key] & ref
        starts = class_window_starts(arrays["cls"], self.per, arrays["breaks"])
        stats = self.stats(arrays, starts)
        cls = arrays["cls"][starts]
        seconds = {c: float(np.sum(arrays["use"] & (arrays["cls"] == c))) * self.seg_s
                   for c in set(AXIS_CLASSES) | {0}}
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
        table = np.full(POOLED + 2, -1, dtype=np.int64)
        for c, (b, _) in self.plan.items():
            table[c] = -1 if b is None else b
        return np.where(cls >= 0, table[np.maximum(cls, 0)], -1)

    def _lookup(self, per_class: dict[int, object], cls: np.ndarray, k: int | None = None
                ) -> np.ndarray:
        """Per window, the value of `per_class` for the class it is scored against (NaN
        where none): a table indexed at once, not a loop over windows."""
        shape = (POOLED + 2,) + (() if k is None else (k,))
        table = np.full(shape, np.nan)
        for c, value in per_class.items():
            table[c] = value
        basis = self._basis(cls)
        return table[np.where(basis >= 0, basis, len(table) - 1)]
