"""Read a store, reduce it to segments, run the detectors: `detect_anomalies`."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from virtualstar.recorder.exceptions import QueryError
from virtualstar.recorder.samples import SampleBlock

from .detectors import Anomaly, DetectorConfig, ScoreTrace, run_detectors
from .segments import Segments, axis_signals, reduce_blocks

__all__ = ["DEFAULT_REFERENCE_S", "AnomalyReport", "detect_anomalies"]

DEFAULT_REFERENCE_S = 900.0  # the first 15 minutes are taken as the mount's usual self
CHUNK_US = 900_000_000  # read 15 minutes at a time: bounded memory over a whole night
RATE_PROBE_US = 10_000_000
MIN_REFERENCE_S = 300.0  # a few of the longest detector windows (temperature: 120 s)


@dataclass
class AnomalyReport:
    """What `detect_anomalies` found, over which window, against which reference."""

    from_t_us: int
    to_t_us: int
    reference_t_us: tuple[int, int]
    rate_hz: float
    segments: int
    anomalies: list[Anomaly]
    traces: list[ScoreTrace] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)

    def as_list(self) -> list[dict[str, object]]:
        """Return the anomalies as the `--json` list (start_utc, end_utc, signals, kind, score, …)."""
        return [a.as_dict() for a in self.anomalies]


def _blocks(reader, names: list[str], a: int, b: int) -> Iterator[SampleBlock]:
    t = a
    while t < b:
        yield reader.window(t, min(t + CHUNK_US, b), names)
        t += CHUNK_US


def _rate_hz(reader, names: list[str], a: int, b: int) -> float:
    probe = reader.window(a, min(b, a + RATE_PROBE_US), names[:1])
    if len(probe) < 3:
        raise QueryError("too few samples in the window to find the sample rate")
    return 1e6 / float(np.median(np.diff(probe.t_us)))


def detect_anomalies(reader, from_t_us: int, to_t_us: int, *,
                     reference: tuple[int, int] | None = None,
                     config: DetectorConfig | None = None) -> AnomalyReport:
    """Flag the stretches of [from, to) where the mount behaves unlike it did in `reference`.

    `reference` (mount µs, half-open) defaults to the first 15 minutes of the window, at
    most its first half. Raises QueryError when the store records no signal a detector
    reads, or the reference holds too little.
    """
    cfg = config or DetectorConfig()
    start = time.perf_counter()
    names_all = [s.name for s in reader.signals()]
    axes = axis_signals(names_all)
    if not axes:
        raise QueryError("no signal to analyse: the detectors read axis.<az|el>.position, "
                         ".current, .error_arcsec, .temperature; the store holds "
                         + ", ".join(names_all))
    if reference is None:
        span = to_t_us - from_t_us
        reference = (from_t_us, from_t_us + min(round(DEFAULT_REFERENCE_S * 1e6), span // 2))
    names = sorted({n for roles in axes.values() for n in roles.values()})
    rate = _rate_hz(reader, names, from_t_us, to_t_us)
    seg: Segments = reduce_blocks(_blocks(reader, names, from_t_us, to_t_us), axes, rate)
    read_s = time.perf_counter() - start
    ref = (seg.t_first_us >= reference[0]) & (seg.t_last_us < reference[1])
    held_s = float(np.sum(seg.t_last_us[ref] - seg.t_first_us[ref])) * 1e-6
    if held_s < MIN_REFERENCE_S:
        raise QueryError(f"the reference stretch {reference[0]}..{reference[1]} µs holds "
                         f"{held_s:.0f} s of the window's samples; it needs "
                         f"{MIN_REFERENCE_S:.0f} s or more (give --reference-from/--reference-to "
                         "inside the window)")
    anomalies, traces = run_detectors(seg, ref, axes, cfg)
    return AnomalyReport(from_t_us, to_t_us, reference, rate, len(seg), anomalies, traces,
                         {"read_and_reduce": read_s,
                          "detect": time.perf_counter() - start - read_s})
