"""Open a pointing-run file by its format: `.csv` is CSV, anything else TPOINT."""

from __future__ import annotations

from pathlib import Path

from .csv_format import RaDecToAltAz, load_csv
from .runs import PointingRun
from .tpoint_format import load_tpoint


def load_run(path: str | Path, *, radec_to_altaz: RaDecToAltAz | None = None) -> PointingRun:
    """Read a pointing run; raises DataFormatError (names file and line) or OSError."""
    if Path(path).suffix.lower() == ".csv":
        return load_csv(path, radec_to_altaz=radec_to_altaz)
    return load_tpoint(path)
