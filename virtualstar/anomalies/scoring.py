"""Score detections against faults injected at known times: precision and recall.

A flag is **true** only when it overlaps the window of an injected fault of its own kind
and axis — a rattling part that also moves the current makes a `current` flag, and that
flag counts as false. A fault is **found** when a true flag for it exists. A flag that
began more than `early_us` before the injection cannot be counting it (it was up
before), so it does not overlap in this sense.
"""

from __future__ import annotations

from dataclasses import dataclass

from .detectors import Anomaly

__all__ = ["InjectedFault", "Scores", "score_detections"]


@dataclass(frozen=True)
class InjectedFault:
    """A fault put in a recording: the kind a detector should report, on which axis
    ("" for the clock), and its window in mount µs (from the injection to when it ended,
    or the end of the recording when it lasts)."""

    kind: str
    axis: str
    start_us: int
    end_us: int


@dataclass(frozen=True)
class Scores:
    """Faults found, anomalies that were true, and the ratios."""

    faults: int
    found: int
    anomalies: int
    true_anomalies: int

    @property
    def recall(self) -> float:
        return self.found / self.faults if self.faults else 1.0

    @property
    def precision(self) -> float:
        return self.true_anomalies / self.anomalies if self.anomalies else 1.0

    def __add__(self, other: Scores) -> Scores:
        return Scores(self.faults + other.faults, self.found + other.found,
                      self.anomalies + other.anomalies,
                      self.true_anomalies + other.true_anomalies)


def matches(a: Anomaly, f: InjectedFault, early_us: int = 0) -> bool:
    """The anomaly is of the fault's kind and axis and overlaps its window (beginning at
    most `early_us` before the injection: a window's start is rounded down)."""
    return (a.kind == f.kind and a.axis == f.axis and a.end_us > f.start_us
            and f.start_us - early_us <= a.start_us < f.end_us)


def score_detections(anomalies: list[Anomaly], faults: list[InjectedFault], *,
                     early_us: int = 0) -> Scores:
    """Match anomalies with faults (see the module docstring)."""
    found = sum(any(matches(a, f, early_us) for a in anomalies) for f in faults)
    true = sum(any(matches(a, f, early_us) for f in faults) for a in anomalies)
    return Scores(len(faults), found, len(anomalies), true)
