"""The detectors on a recording while it is made: each new anomaly is reported once.

`LiveAnomalies.feed(block)` takes the sample blocks a recorder writes. Once the
reference stretch (the first `reference_s` of mount time) is in, it runs the same
detectors as `vs data anomalies` every `every_s` of mount time over what it holds
(segments only: a 12-hour night is 170 k rows), and calls `on_anomaly` for each anomaly
that does not continue one it already reported of the same kind and axis (within
`quiet_s` of its end). The recorder logs them as `anomaly` events (docs/events.md).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from virtualstar.recorder.samples import SampleBlock, concat_blocks

from .detectors import Anomaly, DetectorConfig, run_detectors
from .report import DEFAULT_REFERENCE_S
from .segments import SEGMENT_SAMPLES, Segments, axis_signals, reduce_blocks

__all__ = ["LiveAnomalies"]

DEFAULT_EVERY_S = 60.0
# A flag of the same kind and axis within this long after one already reported is the same
# episode (a fault's residual dips below the limit at slow speeds and comes back): it is
# not reported again, so the log gets one event per episode, not one per flicker.
DEFAULT_QUIET_S = 600.0


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
                 reference_s: float = DEFAULT_REFERENCE_S, every_s: float = DEFAULT_EVERY_S,
                 quiet_s: float = DEFAULT_QUIET_S, config: DetectorConfig | None = None) -> None:
        self.axes = axis_signals(names)
        self.rate_hz = float(rate_hz)
        self.on_anomaly = on_anomaly
        self.reference_us = round(reference_s * 1e6)
        self.every_us = round(every_s * 1e6)
        self.quiet_us = round(quiet_s * 1e6)
        self.config = config or DetectorConfig()
        self.reported: list[Anomaly] = []
        self._pending: list[SampleBlock] = []
        self._held = 0
        self._parts: list[Segments] = []
        self._next_run_us: int | None = None
        self._names = sorted({n for roles in self.axes.values() for n in roles.values()})

    @property
    def active(self) -> bool:
        """True when the recorded signals feed at least one detector."""
        return bool(self.axes)

    def feed(self, block: SampleBlock) -> list[Anomaly]:
        """Take a block; return the anomalies newly reported (also passed to on_anomaly)."""
        if not self.active or len(block) == 0:
            return []
        self._pending.append(SampleBlock(block.t_us, {n: block.columns[n] for n in self._names}))
        self._held += len(block)
        if self._held < SEGMENT_SAMPLES:
            return []
        whole = concat_blocks(self._pending)
        m = len(whole) // SEGMENT_SAMPLES * SEGMENT_SAMPLES
        self._parts.append(reduce_blocks(iter([whole.slice(0, m)]), self.axes, self.rate_hz))
        rest = whole.slice(m, len(whole))
        self._pending, self._held = ([rest] if len(rest) else []), len(rest)
        if len(self._parts) > 64:  # keep concatenation cheap
            self._parts = [_concat(self._parts)]
        return self._maybe_run()

    def _maybe_run(self) -> list[Anomaly]:
        seg = _concat(self._parts)
        if len(seg) == 0:
            return []
        start = int(seg.t_first_us[0])
        now = int(seg.t_last_us[-1])
        if self._next_run_us is None:
            self._next_run_us = start + self.reference_us + self.every_us
        if now < self._next_run_us:
            return []
        self._next_run_us = now + self.every_us
        self._parts = [seg]
        ref = seg.t_last_us < start + self.reference_us
        found, _ = run_detectors(seg, ref, self.axes, self.config)
        new = []
        for a in found:
            same = [k for k, r in enumerate(self.reported) if r.kind == a.kind
                    and r.axis == a.axis and a.start_us < r.end_us + self.quiet_us]
            if same:  # the episode goes on: remember how far, report nothing
                k = same[-1]
                r = self.reported[k]
                self.reported[k] = Anomaly(r.start_us, max(r.end_us, a.end_us), r.kind,
                                           r.signals, max(r.score, a.score), r.axis, r.detail)
                continue
            self.reported.append(a)
            new.append(a)
            self.on_anomaly(a)
        return new
