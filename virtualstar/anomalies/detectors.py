"""The detectors: each turns segment features into a score series and flagged windows.

Every detector compares a window statistic with the same statistic on the reference
stretch (where the mount is taken to behave as itself): ``deviation / limit`` where
the limit is ``threshold`` robust sigmas of the reference (median absolute deviation),
never less than an absolute floor that says what is too small to matter. A score of 1
is the flagging limit, so scores of different kinds read alike.

| kind | signals | statistic (per window) |
|---|---|---|
| current | position, current | mean of current − model(position, velocity, acceleration) |
| vibration | error_arcsec | power of the tracking error per octave band, log ratio |
| spike | error_arcsec, current | largest one-sample second difference per segment |
| temperature | temperature | slope of the winding temperature, K/h |
| clock | t_us | sample spacing in mount µs: the clock rate, ppm |
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .current_model import CurrentModel, fit_current_model
from .robust import robust_center_scale, runs, window_median, window_reduce, window_starts
from .segments import Segments

__all__ = ["Anomaly", "DetectorConfig", "ScoreTrace", "run_detectors"]


@dataclass(frozen=True)
class DetectorConfig:
    """Windows (s), thresholds (robust sigmas) and absolute floors of the detectors."""

    threshold: float = 8.0
    current_window_s: float = 10.0
    current_floor_a: float = 0.01
    current_ref_factor: float = 2.0  # × the largest deviation of a reference window
    vibration_window_s: float = 60.0  # a median over it: brief stick-slip bursts are usual
    # band power × this at least (amplitude × 4): a clean 12-h night reaches × 8.5 in 16–32 Hz
    # for a minute whenever the sine slows to a stop (stick-slip exciting the structure)
    vibration_floor_ratio: float = 16.0
    spike_factor: float = 3.0  # × the largest spike of the reference stretch
    spike_merge_s: float = 10.0
    temperature_window_s: float = 120.0
    temperature_floor_k_h: float = 3.0
    clock_window_s: float = 60.0
    clock_floor_ppm: float = 0.5
    cogging_periods: float | None = None  # None: estimated; 0: no cogging term
    merge_s: float = 120.0  # flagged windows this close are one anomaly


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


def _seg_s(seg: Segments) -> float:
    return float(np.median(np.diff(seg.t_first_us))) * 1e-6 if len(seg) > 1 else 1.0


def _per_window(seg: Segments, seconds: float) -> tuple[np.ndarray, int]:
    """Return the window starts and the fewest valid segments a window needs (half of it)."""
    per = max(1, round(seconds / max(_seg_s(seg), 1e-9)))
    return window_starts(len(seg), per), max(1, per // 2)


def _bridge(seg: Segments, starts: np.ndarray, cfg: DetectorConfig) -> int:
    width_s = (len(seg) / max(len(starts), 1)) * _seg_s(seg)
    return max(1, round(cfg.merge_s / max(width_s, 1e-9)))


def _window_span(seg: Segments, starts: np.ndarray, i0: int, i1: int) -> tuple[int, int]:
    a = int(seg.t_first_us[starts[i0]])
    last = starts[i1 + 1] - 1 if i1 + 1 < len(starts) else len(seg) - 1
    return a, int(seg.t_last_us[last]) + 1


def _flag(seg: Segments, starts: np.ndarray, score: np.ndarray, kind: str,
          signals: tuple[str, ...], axis: str, detail, bridge: int) -> list[Anomaly]:
    """Return one Anomaly per run of windows whose score is >= 1 (NaN never flags)."""
    out = []
    for i0, i1 in runs(np.nan_to_num(score, nan=0.0) >= 1.0, bridge=bridge):
        a, b = _window_span(seg, starts, i0, i1)
        peak = i0 + int(np.nanargmax(score[i0:i1 + 1]))
        out.append(Anomaly(a, b, kind, signals, float(score[peak]), axis, detail(peak)))
    return out


def _ref_windows(seg: Segments, starts: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """A window belongs to the reference when all of its segments do."""
    counts = np.add.reduceat(ref.astype(np.int64), starts)
    sizes = np.diff(np.r_[starts, len(seg)])
    return counts == sizes


def detect_current(seg: Segments, ref: np.ndarray, valid: np.ndarray, axis: str,
                   names: dict[str, str], cfg: DetectorConfig
                   ) -> tuple[list[Anomaly], ScoreTrace, CurrentModel]:
    """Flag windows whose current departs from the motion model (friction, winding)."""
    f = seg.features
    p, v, i = f[f"{axis}.position_rad"], f[f"{axis}.velocity_rad_s"], f[f"{axis}.current_a"]
    t_s = (seg.t_mid_us - seg.t_mid_us[0]) * 1e-6
    a = np.gradient(v, t_s) if len(v) > 1 else np.zeros_like(v)
    fit_rows = ref & valid
    model = fit_current_model(p, v, a, i, fit_rows, gravity=axis == "el",
                              cogging_periods=cfg.cogging_periods)
    resid = i - model.predict(p, v, a)
    starts, need = _per_window(seg, cfg.current_window_s)
    wm = window_reduce(resid, starts, valid, min_count=need)
    ref_w = _ref_windows(seg, starts, ref)
    med, sigma = robust_center_scale(wm, ref_w)
    dev = wm - np.nan_to_num(med)
    # the model's own error is not normal: never flag what the reference itself reached
    widest = float(np.nanmax(np.abs(dev[ref_w]))) if np.isfinite(dev[ref_w]).any() else 0.0
    limit = max(cfg.threshold * float(np.nan_to_num(sigma)), cfg.current_ref_factor * widest,
                cfg.current_floor_a)
    score = np.abs(dev) / limit
    signals = (names["position"], names["current"])
    anomalies = _flag(seg, starts, score, "current", signals, axis,
                      lambda k: f"current {dev[k]:+.3f} A off its motion model "
                                f"(limit {limit:.3f} A)", _bridge(seg, starts, cfg))
    trace = ScoreTrace(f"{axis} current", seg.t_first_us[starts], score,
                       {"cogging_periods": round(model.cogging_periods, 2),
                        "reference_rms_a": model.reference_rms_a, "limit_a": limit})
    return anomalies, trace, model


def detect_vibration(seg: Segments, ref: np.ndarray, valid: np.ndarray, axis: str,
                     names: dict[str, str], cfg: DetectorConfig) -> tuple[list[Anomaly], ScoreTrace]:
    """Flag windows whose tracking error has more power than usual in some octave band."""
    bp = seg.features[f"{axis}.error_band_power"]
    edges = seg.band_edges_hz
    # a band silent on the reference has no usual level to compare with
    usable = np.flatnonzero(np.median(bp[ref & valid], axis=0) > 0) if (ref & valid).any() \
        else np.zeros(0, np.int64)
    if len(usable) == 0:
        return [], ScoreTrace(f"{axis} vibration", seg.t_first_us[:1], np.zeros(1))
    logp = np.log10(bp[:, usable] + 1e-30)
    starts, need = _per_window(seg, cfg.vibration_window_s)
    wm = window_median(logp, starts, valid, min_count=need)
    med, sigma = robust_center_scale(wm, _ref_windows(seg, starts, ref))
    floor = np.log10(cfg.vibration_floor_ratio)
    limit = np.maximum(cfg.threshold * np.nan_to_num(sigma), floor)
    z = (wm - np.nan_to_num(med)) / limit  # louder only: a quieter mount is no fault
    finite = np.where(np.isfinite(z), z, -np.inf)
    score = finite.max(axis=1)
    score = np.where(np.isfinite(score), score, np.nan)
    band = finite.argmax(axis=1)

    def detail(k: int) -> str:
        b = usable[band[k]]
        ratio = 10 ** (wm[k, band[k]] - med[band[k]])
        return f"tracking-error power ×{ratio:.1f} in {edges[b]:g}–{edges[b + 1]:g} Hz"

    anomalies = _flag(seg, starts, score, "vibration", (names["error_arcsec"],), axis, detail,
                      _bridge(seg, starts, cfg))
    return anomalies, ScoreTrace(f"{axis} vibration", seg.t_first_us[starts], score)


def detect_spikes(seg: Segments, ref: np.ndarray, valid: np.ndarray, axis: str,
                  names: dict[str, str], cfg: DetectorConfig) -> tuple[list[Anomaly], ScoreTrace]:
    """Flag segments holding a one-sample jump far beyond any in the reference stretch."""
    f = seg.features
    parts = []
    for feat, role in (("error_spike_arcsec", "error_arcsec"), ("current_spike_a", "current")):
        key = f"{axis}.{feat}"
        if key in f and (ref & valid).any():
            usual = float(np.max(f[key][ref & valid]))
            parts.append((f[key] / max(cfg.spike_factor * usual, 1e-12), names[role]))
    if not parts:
        return [], ScoreTrace(f"{axis} spike", seg.t_first_us, np.zeros(len(seg)))
    stacked = np.stack([s for s, _ in parts], axis=1)
    score = np.where(valid, stacked.max(axis=1), np.nan)
    bridge = max(1, round(cfg.spike_merge_s / max(_seg_s(seg), 1e-9)))
    out = []
    starts = np.arange(len(seg))
    for i0, i1 in runs(np.nan_to_num(score) >= 1.0, bridge=bridge):
        a, b = _window_span(seg, starts, i0, i1)
        block = np.nan_to_num(score[i0:i1 + 1])
        count = int(np.count_nonzero(block >= 1.0))
        sigs = tuple(name for k, (_, name) in enumerate(parts)
                     if np.nanmax(stacked[i0:i1 + 1, k]) >= 1.0)
        out.append(Anomaly(a, b, "spike", sigs, float(block.max()), axis,
                           f"{count} segment(s) with a one-sample jump (×{block.max():.1f} "
                           "the limit)"))
    return out, ScoreTrace(f"{axis} spike", seg.t_first_us, score)


def _window_slope(t_s: np.ndarray, y: np.ndarray, starts: np.ndarray, valid: np.ndarray,
                  need: int) -> np.ndarray:
    """Least-squares slope of y against t in each window (per second)."""
    n = np.add.reduceat(valid.astype(np.float64), starts)
    mt = window_reduce(t_s, starts, valid)
    my = window_reduce(y, starts, valid)
    mtt = window_reduce(t_s * t_s, starts, valid)
    mty = window_reduce(t_s * y, starts, valid)
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = (mty - mt * my) / (mtt - mt * mt)
    return np.where(n >= max(3, need), slope, np.nan)


def detect_temperature(seg: Segments, ref: np.ndarray, valid: np.ndarray, axis: str,
                       names: dict[str, str], cfg: DetectorConfig
                       ) -> tuple[list[Anomaly], ScoreTrace]:
    """Flag windows whose winding temperature climbs unlike its trend on the reference."""
    temp = seg.features[f"{axis}.temperature_c"]
    t_s = (seg.t_mid_us - seg.t_mid_us[0]) * 1e-6
    starts, need = _per_window(seg, cfg.temperature_window_s)
    slope = _window_slope(t_s - t_s.mean(), temp, starts, valid, need) * 3600.0  # K/h
    med, sigma = robust_center_scale(slope, _ref_windows(seg, starts, ref))
    limit = max(cfg.threshold * float(np.nan_to_num(sigma)), cfg.temperature_floor_k_h)
    dev = slope - np.nan_to_num(med)
    score = np.abs(dev) / limit
    anomalies = _flag(seg, starts, score, "temperature", (names["temperature"],), axis,
                      lambda k: f"temperature changing {dev[k]:+.1f} K/h off its usual trend "
                                f"(limit {limit:.1f} K/h)", _bridge(seg, starts, cfg))
    return anomalies, ScoreTrace(f"{axis} temperature", seg.t_first_us[starts], score)


def detect_clock(seg: Segments, ref: np.ndarray, valid: np.ndarray,
                 cfg: DetectorConfig) -> tuple[list[Anomaly], ScoreTrace]:
    """Flag windows whose sample spacing (mount µs) says the clock runs at another rate."""
    starts, need = _per_window(seg, cfg.clock_window_s)
    span = (seg.t_last_us - seg.t_first_us).astype(np.float64)
    spacing = window_reduce(span, starts, valid, min_count=need)
    med, sigma = robust_center_scale(spacing, _ref_windows(seg, starts, ref))
    med = float(np.nan_to_num(med, nan=np.nanmedian(spacing) if len(spacing) else 1.0))
    ppm = (spacing / med - 1.0) * 1e6
    sigma_ppm = float(np.nan_to_num(sigma)) / med * 1e6
    limit = max(cfg.threshold * sigma_ppm, cfg.clock_floor_ppm)
    score = np.abs(ppm) / limit
    anomalies = _flag(seg, starts, score, "clock", ("t_us",), "",
                      lambda k: f"mount clock rate {ppm[k]:+.2f} ppm off its usual "
                                f"(limit {limit:.2f} ppm)", _bridge(seg, starts, cfg))
    return anomalies, ScoreTrace("clock", seg.t_first_us[starts], score)


def run_detectors(seg: Segments, ref: np.ndarray, axes: dict[str, dict[str, str]],
                  cfg: DetectorConfig) -> tuple[list[Anomaly], list[ScoreTrace]]:
    """Run every detector the recorded signals allow; return anomalies by start and traces."""
    anomalies: list[Anomaly] = []
    traces: list[ScoreTrace] = []
    if len(seg) == 0:
        return anomalies, traces
    # a segment across a recording gap or a clock step is no sample of the mount's behaviour
    usual = float(np.median(seg.spacing_us))
    valid = np.abs(seg.spacing_us - usual) <= 0.001 * usual
    for axis, names in axes.items():
        calm = valid
        if "error_arcsec" in names or "current" in names:
            found, spikes = detect_spikes(seg, ref, valid, axis, names, cfg)
            anomalies += found
            # a segment with a one-sample jump is the spike detector's: it would bend the
            # current's window mean and the error's spectrum
            calm = valid & ~(np.nan_to_num(spikes.score) >= 1.0)
        if {"position", "current"} <= names.keys():
            found, trace, _ = detect_current(seg, ref, calm, axis, names, cfg)
            anomalies += found
            traces.append(trace)
        if "error_arcsec" in names:
            found, trace = detect_vibration(seg, ref, calm, axis, names, cfg)
            anomalies += found
            traces.append(trace)
        if "error_arcsec" in names or "current" in names:
            traces.append(spikes)
        if "temperature" in names:
            found, trace = detect_temperature(seg, ref, valid, axis, names, cfg)
            anomalies += found
            traces.append(trace)
    found, trace = detect_clock(seg, ref, valid, cfg)
    anomalies += found
    traces.append(trace)
    anomalies.sort(key=lambda x: (x.start_us, x.kind))
    return anomalies, traces
