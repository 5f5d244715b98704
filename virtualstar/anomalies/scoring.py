"""Score detections against faults injected at known times: precision and recall."""

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


def _overlaps(a: Anomaly, f: InjectedFault, early_us: int) -> bool:
    """The anomaly begins inside the fault's window (or at most `early_us` before it): a
    flag that was already up before the fault cannot count as finding it."""
    return f.start_us - early_us <= a.start_us < f.end_us


def score_detections(anomalies: list[Anomaly], faults: list[InjectedFault], *,
                     early_us: int = 0) -> Scores:
    """Match anomalies with faults.

    A fault is found when an anomaly of its kind and axis begins in its window; an anomaly
    is true when it begins in the window of any fault of the recording (a rattling part
    also moves the current: that flag is no false alarm). `early_us` lets an anomaly
    begin that much before the injection (a window's start is rounded down).
    """
    found = sum(any(a.kind == f.kind and a.axis == f.axis and _overlaps(a, f, early_us)
                    for a in anomalies) for f in faults)
    true = sum(any(_overlaps(a, f, early_us) for f in faults) for a in anomalies)
    return Scores(len(faults), found, len(anomalies), true)
