"""The detectors on a recording while it is made: each new anomaly is reported once.

`LiveAnomalies.feed(block)` takes the sample blocks a recorder writes and
`feed_events(events)` the events it stores (the mount's and the VSS's: they give the
motion phases). It reduces the samples to segments at once, labels a segment with its
phase once the stream is `lag_s` of mount time past it (so that the events of that time
are in), and holds the labelled segments until the automatic reference is complete
(anomalies.reference: the first 15 minutes of the mount working). Then it fits the
detectors, scores what it held, and from then on scores each chunk as it is labelled:
the work per chunk does not grow with the night, so the twelfth hour costs what the
first did. `on_anomaly` is called once per anomaly, when its first window is flagged;
the recorder logs it as an `anomaly` event (docs/events.md). The anomalies are those
`vs data anomalies` finds on the finished store (the same phases, reference, windows
and merging), reported as they open.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from virtualstar.recorder.samples import SampleBlock, concat_blocks

from .detectors import Anomaly, DetectorConfig
from .phases import PhaseLabeller
from .pipeline import Detection, segment_validity
from .reference import (
    Reference,
    ReferenceRefused,
    automatic_reference,
    check_reference,
    usable,
)
from .segments import SEGMENT_SAMPLES, Segments, axis_signals, reduce_blocks

__all__ = ["DEFAULT_LAG_S", "LiveAnomalies"]

DEFAULT_LAG_S = 60.0  # mount seconds between a segment and its labelling (events arrive late)


def _concat(parts: list[Segments]) -> Segments:
    if len(parts) == 1:
        return parts[0]
    return Segments(np.concatenate([p.t_first_us for p in parts]),
                    np.concatenate([p.t_last_us for p in parts]),
                    np.concatenate([p.spacing_us for p in parts]), parts[0].band_edges_hz,
                    {k: np.concatenate([p.features[k] for p in parts]) for k in parts[0].features})


class LiveAnomalies:
    """Detect anomalies on sample blocks as they arrive (see the module docstring)."""

    def __init__(self, names: list[str], rate_hz: float,
                 on_anomaly: Callable[[Anomaly], None], *,
                 config: DetectorConfig | None = None, lag_s: float = DEFAULT_LAG_S,
                 on_refused: Callable[[str], None] = lambda message: None) -> None:
        self.axes = axis_signals(names)
        self.rate_hz = float(rate_hz)
        self.on_anomaly = on_anomaly
        self.on_refused = on_refused
        self.config = config or DetectorConfig()
        self.lag_us = round(lag_s * 1e6)
        self.labeller = PhaseLabeller(self.axes, config=self.config.phases)
        self.detection = Detection(self.axes, self.rate_hz, self.config)
        self.reference: Reference | None = None
        self.refused = ""
        self.reported: list[Anomaly] = []
        self._names = sorted({n for roles in self.axes.values() for n in roles.values()})
        self._pending: list[SampleBlock] = []
        self._held_samples = 0
        self._unlabelled: list[Segments] = []
        self._labelled: list[tuple[Segments, np.ndarray]] = []
        self._usable_s = 0.0
        self._faults: list[int] = []
        self._faults_checked = 0

    @property
    def active(self) -> bool:
        """True when the recorded signals feed at least one detector."""
        return bool(self.axes)

    @property
    def held_segments(self) -> int:
        """Segments held for later: waiting for their label, for the reference, or in a
        window not yet closed. Once the reference is in it stays below a bound set by
        the lag and the longest window, however long the night: the work is incremental."""
        held = sum(len(s) for s in self._unlabelled) + sum(len(s) for s, _ in self._labelled)
        return held + sum(d.cutter.pending for d in self.detection.detectors)

    def feed_events(self, events) -> None:
        """Take events stored beside the samples (phases, mount states, faults)."""
        events = list(events)
        self.labeller.add_events(events)
        self._faults += [int(e.t_us) for e in events if e.kind == "fault" and e.level == "error"]

    def feed(self, block: SampleBlock) -> list[Anomaly]:
        """Take a block; return the anomalies newly reported (also passed to on_anomaly)."""
        if not self.active or len(block) == 0 or self.refused:
            return []
        self._pending.append(SampleBlock(block.t_us, {n: block.columns[n] for n in self._names}))
        self._held_samples += len(block)
        if self._held_samples < SEGMENT_SAMPLES:
            return []
        whole = concat_blocks(self._pending)
        m = len(whole) // SEGMENT_SAMPLES * SEGMENT_SAMPLES
        self._unlabelled.append(reduce_blocks(iter([whole.slice(0, m)]), self.axes,
                                              self.rate_hz))
        rest = whole.slice(m, len(whole))
        self._pending, self._held_samples = ([rest] if len(rest) else []), len(rest)
        return self._advance(int(whole.t_us[m - 1]) - self.lag_us)

    def finish(self) -> list[Anomaly]:
        """The recording ended: label and score everything held; return what it opened."""
        if not self.active or self.refused:
            return []
        found = self._advance(None)
        if self.reference is None and self._labelled:
            found += self._start(final=True)
        if self.detection.fitted:
            found += self._report(self.detection.feed(None, final=True))
        return found

    # ---------------------------------------------------------------------------------
    def _advance(self, until_us: int | None) -> list[Anomaly]:
        """Label the segments that end before `until_us` (all: None) and go on with them."""
        if not self._unlabelled:
            return []
        seg = _concat(self._unlabelled)
        k = len(seg) if until_us is None else int(np.searchsorted(seg.t_last_us, until_us,
                                                                   side="right"))
        if k == 0:
            self._unlabelled = [seg]
            return []
        ready = _slice(seg, 0, k)
        self._unlabelled = [_slice(seg, k, len(seg))] if k < len(seg) else []
        phase = self.labeller.label(ready)
        if self.reference is not None:
            return self._report(self.detection.feed(self.detection.chunk(ready, phase)))
        self._labelled.append((ready, phase))
        use = usable(phase, segment_validity(ready, self.rate_hz))
        self._usable_s += float(np.sum((ready.t_last_us - ready.t_first_us)[use])) * 1e-6
        if self._usable_s >= self.config.reference.length_s or \
                len(self._faults) > self._faults_checked:
            self._faults_checked = len(self._faults)
            return self._start(final=False)
        return []

    def _start(self, *, final: bool) -> list[Anomaly]:
        """Choose the reference over what is held; once complete, fit and score it all."""
        seg = _concat([s for s, _ in self._labelled])
        phase = np.concatenate([p for _, p in self._labelled])
        self._labelled = [(seg, phase)]
        valid = segment_validity(seg, self.rate_hz)
        faults = np.sort(np.asarray(self._faults, dtype=np.int64))
        ref, complete = automatic_reference(seg.t_first_us, seg.t_last_us, phase, valid,
                                            faults, self.config.reference)
        if not complete and not final:
            return []
        try:
            check_reference(ref, None, self.config.reference)
        except ReferenceRefused as exc:
            self.refused = str(exc)
            self.on_refused(self.refused)
            self._labelled = []
            return []
        self.reference = ref
        self._labelled = []
        chunk = self.detection.chunk(seg, phase)
        self.detection.fit(chunk, ref.mask(seg.t_first_us, seg.t_last_us) & usable(phase, valid))
        return self._report(self.detection.feed(chunk))

    def _report(self, opened: list[Anomaly]) -> list[Anomaly]:
        for a in opened:
            self.reported.append(a)
            self.on_anomaly(a)
        return opened


def _slice(seg: Segments, a: int, b: int) -> Segments:
    return Segments(seg.t_first_us[a:b], seg.t_last_us[a:b], seg.spacing_us[a:b],
                    seg.band_edges_hz, {k: v[a:b] for k, v in seg.features.items()})
