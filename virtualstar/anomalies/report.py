"""Read a store, label its phases, choose the reference, run the detectors: `detect_anomalies`."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from virtualstar.recorder.exceptions import QueryError
from virtualstar.recorder.samples import SampleBlock

from .detectors import Anomaly, Check, DetectorConfig, ScoreTrace
from .phases import MotionPhase, PhaseLabeller
from .pipeline import Detection
from .reference import (
    MOVING,
    Reference,
    automatic_reference,
    check_reference,
    fault_times_us,
    given_reference,
    usable,
)
from .segments import Segments, axis_signals, reduce_blocks

__all__ = ["AnomalyReport", "detect_anomalies", "read_segments"]

CHUNK_US = 900_000_000  # read 15 minutes at a time: bounded memory over a whole night
RATE_PROBE_US = 10_000_000


@dataclass
class AnomalyReport:
    """What `detect_anomalies` found, over which window, against which reference, and what
    each detector checked."""

    from_t_us: int
    to_t_us: int
    reference: Reference
    rate_hz: float
    segments: int
    anomalies: list[Anomaly]
    checks: list[Check] = field(default_factory=list)
    phase_source: str = ""
    phase_s: dict[str, float] = field(default_factory=dict)
    traces: list[ScoreTrace] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def reference_t_us(self) -> tuple[int, int]:
        """The reference's first start and last end (mount µs)."""
        s = self.reference.stretches
        return (s[0][0], s[-1][1]) if s else (self.from_t_us, self.from_t_us)

    def as_list(self) -> list[dict[str, object]]:
        """The anomalies as dicts (start_utc, end_utc, signals, kind, score, …)."""
        return [a.as_dict() for a in self.anomalies]

    def as_dict(self) -> dict[str, object]:
        """The `--json` document: anomalies, the detectors' checks, phases, reference."""
        from virtualstar.recorder.parquet_store import utc_text

        return {"anomalies": self.as_list(),
                "checks": [c.as_dict() for c in self.checks],
                "not_run": [{"detector": c.detector, "axis": c.axis, "reason": c.reason}
                            for c in self.checks if not c.ran],
                "phases": {"source": self.phase_source,
                           "seconds": {k: round(v, 1) for k, v in self.phase_s.items()}},
                "reference": self.reference.as_dict(),
                "window": {"start_utc": utc_text(self.from_t_us),
                           "end_utc": utc_text(self.to_t_us), "start_t_us": self.from_t_us,
                           "end_t_us": self.to_t_us},
                "rate_hz": self.rate_hz, "segments": self.segments}


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


def _events(reader, a: int, b: int) -> list:
    read = getattr(reader, "events", None)
    if read is None:
        return []
    return [e for e in read() if a <= e.t_us < b]


def read_segments(reader, from_t_us: int, to_t_us: int
                  ) -> tuple[Segments, dict[str, dict[str, str]], float]:
    """Read [from, to) of a store and reduce it: (segments, {axis: {role: name}}, rate Hz).
    Raises QueryError when the store records no signal a detector reads."""
    names_all = [s.name for s in reader.signals()]
    axes = axis_signals(names_all)
    if not axes:
        raise QueryError("no signal to analyse: the detectors read axis.<az|el>.position, "
                         ".current, .error_arcsec, .temperature; the store holds "
                         + ", ".join(names_all))
    names = sorted({n for roles in axes.values() for n in roles.values()})
    rate = _rate_hz(reader, names, from_t_us, to_t_us)
    return reduce_blocks(_blocks(reader, names, from_t_us, to_t_us), axes, rate), axes, rate


def detect_anomalies(reader, from_t_us: int, to_t_us: int, *,
                     reference: list[tuple[int, int]] | tuple[int, int] | None = None,
                     config: DetectorConfig | None = None) -> AnomalyReport:
    """Flag the stretches of [from, to) where the mount behaves unlike it did on the reference.

    `reference`: stretches (mount µs, half-open) to learn from; None chooses them
    (anomalies.reference). Raises QueryError when the store records no signal a detector
    reads, and ReferenceRefused (a QueryError) when the reference cannot be used.
    """
    cfg = config or DetectorConfig()
    start = time.perf_counter()
    seg, axes, rate = read_segments(reader, from_t_us, to_t_us)
    events = _events(reader, from_t_us, to_t_us)
    read_s = time.perf_counter() - start

    labeller = PhaseLabeller(axes, events, config=cfg.phases)
    phase = labeller.label(seg)
    det = Detection(axes, rate, cfg)
    chunk = det.chunk(seg, phase)
    t0, t1 = seg.t_first_us, seg.t_last_us
    if reference is None:
        ref, _ = automatic_reference(t0, t1, phase, chunk.valid, fault_times_us(events),
                                     cfg.reference)
    else:
        stretches = [reference] if isinstance(reference, tuple) else list(reference)
        ref = given_reference(stretches, t0, t1, phase, chunk.valid)
    use = usable(phase, chunk.valid)
    window_phase_s = {p.label: float(np.sum((t1 - t0)[use & (phase == p)])) * 1e-6
                      for p in MOVING}
    check_reference(ref, window_phase_s, cfg.reference)
    det.fit(chunk, ref.mask(t0, t1) & use)
    det.feed(chunk, final=True)
    return AnomalyReport(from_t_us, to_t_us, ref, rate, len(seg), det.anomalies, det.checks,
                         labeller.source,
                         {p.label: round(labeller.seconds[p], 1) for p in MotionPhase},
                         det.traces(),
                         {"read_and_reduce": read_s,
                          "detect": time.perf_counter() - start - read_s})
