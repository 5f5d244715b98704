"""Find where a recorded mount behaves unlike itself (`vs data anomalies`).

The store is reduced to short segments (`segments`), the detectors (`detectors`) compare
residuals — the current minus a motion model fitted on a reference stretch
(`current_model`), the tracking error's spectrum, one-sample jumps, the temperature's
trend, the clock rate seen in the sample times — with the same statistic on the
reference, and `detect_anomalies` returns the flagged stretches. docs/anomalies.md.
"""

from .detectors import Anomaly, DetectorConfig, ScoreTrace
from .report import AnomalyReport, detect_anomalies

__all__ = ["Anomaly", "AnomalyReport", "DetectorConfig", "ScoreTrace", "detect_anomalies"]
