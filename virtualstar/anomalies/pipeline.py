"""One night's detection, offline or live: fit on the reference, score chunk after chunk.

`Detection` holds the detectors a store's signals allow. `fit` learns the reference
(the current model, each class's usual statistics); `feed` scores a chunk of labelled
segments and merges flagged windows into anomalies — a flagged window within
`merge_s` (spikes: `spike_merge_s`) of an open anomaly of the same kind and axis extends
it, any other opens a new one. `feed` returns the anomalies it opened, which is what
live detection reports. The work per chunk depends only on the chunk's length, so an
hour late in a night costs what an hour early does.
"""

from __future__ import annotations

import numpy as np

from .current_detector import CurrentDetector
from .detectors import Anomaly, Check, Chunk, Detector, DetectorConfig, ScoreTrace, Window
from .phases import axis_classes
from .segments import SEGMENT_SAMPLES, Segments
from .spikes import SpikeDetector
from .trends import ClockDetector, TemperatureDetector
from .vibration import VibrationDetector

__all__ = ["Detection", "segment_validity"]

VALID_SPACING = 0.001  # a segment whose sample spacing is off by more spans a gap or a step


def segment_validity(seg: Segments, rate_hz: float) -> np.ndarray:
    """True for the segments without a recording gap or a clock step inside."""
    nominal_us = 1e6 / rate_hz
    return np.abs(seg.spacing_us - nominal_us) <= VALID_SPACING * nominal_us


def build_detectors(axes: dict[str, dict[str, str]], cfg: DetectorConfig, seg_s: float
                    ) -> tuple[list[Detector], list[Check]]:
    """Return the detectors the recorded signals allow (spikes first: the others leave
    out the segments a spike is in) and a Check for each that cannot run, with why."""
    dets: list[Detector] = []
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
            # with the current, the temperature's trend is compared with the heat it
            # explains (I²R); without, with the reference's usual trend
            dets.append(TemperatureDetector(axis, (names["temperature"],) + (
                (names["current"],) if "current" in names else ()), cfg, seg_s))
        else:
            missing.append(Check("temperature", axis, (), False,
                                 f"needs axis.{axis}.temperature; the store has none"))
    dets.append(ClockDetector("", ("t_us",), cfg, seg_s))
    return dets, missing


class _Open:
    """An anomaly still open: it may grow with the next flagged window."""

    def __init__(self, w: Window, kind: str, axis: str, signals: tuple[str, ...]) -> None:
        self.start, self.end, self.score, self.detail = w.start_us, w.end_us, w.score, w.detail
        self.kind, self.axis, self.signals = kind, axis, signals

    def extend(self, w: Window) -> None:
        self.end = max(self.end, w.end_us)
        if w.score > self.score:
            self.score, self.detail = w.score, w.detail

    def anomaly(self) -> Anomaly:
        return Anomaly(self.start, self.end, self.kind, self.signals, self.score, self.axis,
                       self.detail)


class Detection:
    """The detectors of one recording (see the module docstring)."""

    def __init__(self, axes: dict[str, dict[str, str]], rate_hz: float,
                 config: DetectorConfig | None = None) -> None:
        self.axes = axes
        self.config = config or DetectorConfig()
        self.rate_hz = float(rate_hz)
        self.seg_s = SEGMENT_SAMPLES / self.rate_hz
        self.detectors, self.missing = build_detectors(axes, self.config, self.seg_s)
        self.checks: list[Check] = []
        self._open: dict[tuple[str, str], _Open] = {}
        self._closed: list[Anomaly] = []
        self._last_t_us: int | None = None
        self._last_spike: dict[str, bool] = {}
        self.fitted = False

    # -- chunks ------------------------------------------------------------------------
    def chunk(self, seg: Segments, phase: np.ndarray) -> Chunk:
        """Return the chunk of `seg` (labelled with `phase`) the detectors read; chunks must
        come in time order (a gap between two is a window break)."""
        nominal_us = 1e6 / self.rate_hz
        valid = segment_validity(seg, self.rate_hz)
        previous = np.r_[self._last_t_us if self._last_t_us is not None else -1,
                         seg.t_last_us[:-1]]
        breaks = (seg.t_first_us - previous > 2 * nominal_us) | ~valid
        if self._last_t_us is None and len(seg):
            breaks[0] = True
        if len(seg):
            self._last_t_us = int(seg.t_last_us[-1])
        classes = {ax: axis_classes(phase, seg.features.get(f"{ax}.velocity_rad_s"),
                                    self.config.phases,
                                    seg.features.get(f"{ax}.acceleration_rad_s2"))
                   for ax in self.axes}
        return Chunk(seg, phase, valid, breaks, classes)

    def _calm(self, chunk: Chunk, *, carry: bool = True) -> None:
        """Mark per axis the segments free of spikes: a segment with a one-sample jump is
        the spike detector's — it would bend the current's window mean and the error's
        spectrum — and so is the next one, where the loops answer the jump. `carry`: the
        previous chunk's last segment counts (scoring); fitting looks at its chunk only."""
        chunk.calm = {ax: chunk.valid.copy() for ax in self.axes}
        for det in self.detectors:
            if isinstance(det, SpikeDetector) and det.plan:
                flags = det.flags(chunk)
                before = self._last_spike.get(det.axis, False) if carry else False
                after = np.r_[before, flags[:-1]] if len(flags) else flags
                chunk.calm[det.axis] &= ~(flags | after)
                if carry and len(flags):
                    self._last_spike[det.axis] = bool(flags[-1])

    # -- fit and score -----------------------------------------------------------------
    def fit(self, chunk: Chunk, ref: np.ndarray) -> list[Check]:
        """Learn the rows `ref` of `chunk` (the reference); return what each detector will
        check and what it cannot."""
        chunk.calm = {ax: chunk.valid.copy() for ax in self.axes}
        checks: dict[int, Check] = {}
        for det in self.detectors:  # spikes first: the others leave their segments out
            if isinstance(det, SpikeDetector):
                checks[id(det)] = det.fit(chunk, ref)
        self._calm(chunk, carry=False)
        for det in self.detectors:
            if not isinstance(det, SpikeDetector):
                checks[id(det)] = det.fit(chunk, ref)
        self.detectors = [d for d in self.detectors if checks[id(d)].ran]
        self.checks = [checks[id(d)] for d in self.detectors] + \
            [c for c in checks.values() if not c.ran] + self.missing
        self.fitted = True
        return self.checks

    def feed(self, chunk: Chunk | None, *, final: bool = False) -> list[Anomaly]:
        """Score `chunk` (None: nothing new; with `final`, what is pending); return the
        anomalies it opened."""
        if chunk is not None:
            self._calm(chunk)
        opened: list[Anomaly] = []
        for det in self.detectors:
            bridge_us = round(1e6 * (self.config.spike_merge_s if det.kind == "spike"
                                     else self.config.merge_s))
            for w in det.score(chunk, final=final):
                key = (det.kind, det.axis)
                cur = self._open.get(key)
                if cur is not None and w.start_us <= cur.end + bridge_us:
                    cur.extend(w)
                    continue
                if cur is not None:
                    self._closed.append(cur.anomaly())
                self._open[key] = _Open(w, det.kind, det.axis, det.signals)
                opened.append(self._open[key].anomaly())
        if final:
            self._closed += [o.anomaly() for o in self._open.values()]
            self._open = {}
        return opened

    @property
    def anomalies(self) -> list[Anomaly]:
        """Every anomaly so far (the open ones as far as they reach), by start time."""
        found = self._closed + [o.anomaly() for o in self._open.values()]
        return sorted(found, key=lambda a: (a.start_us, a.kind, a.axis))

    def traces(self) -> list[ScoreTrace]:
        return [det.trace() for det in self.detectors]
