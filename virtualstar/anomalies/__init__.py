"""Find where a recorded mount behaves unlike itself (`vs data anomalies`).

The store is reduced to short segments (`segments`), each labelled with what the mount was
doing — its motion phase from the mount's and the VSS's events or the signals, and per axis
its speed regime (`phases`). A reference stretch is chosen or given, and refused when the
detectors cannot learn from it (`reference`). The detectors (`current_detector`,
`vibration`, `spikes`, `trends`) compare residuals — the current minus a motion model
fitted on the reference (`current_model`), the tracking error's spectrum, one-sample
jumps, the temperature's trend, the clock rate seen in the sample times — with the same
statistic on the reference, class by class, in windows that never mix classes
(`windows`). `pipeline.Detection` fits them once and feeds them chunk by chunk, offline
(`detect_anomalies`, `report`) and live (`live.LiveAnomalies`). docs/anomalies.md.
"""

from .detectors import Anomaly, Check, DetectorConfig, ScoreTrace
from .reference import ReferenceRefused
from .report import AnomalyReport, detect_anomalies

__all__ = ["Anomaly", "AnomalyReport", "Check", "DetectorConfig", "ReferenceRefused",
           "ScoreTrace", "detect_anomalies"]
