"""A simulated camera from a TOML file: the truth it sees and its settings.

```toml
[truth]                      # exactly one of: a satellite, or a star's catalogue place
tle_file = "stations.tle"    # relative to this file; or line1 = "1 ...", line2 = "2 ..."
sat = "ISS"                  # the satellite in tle_file (default: the first)
along_s = 2.0                # the truth is moved this far along the track ...
across_arcsec = 40.0         # ... and across it, measured at:
at = "2024-05-18T19:55:00Z"  # (needed with across_arcsec)
# ra_deg = 279.23, dec_deg = 38.78 (+ pm_ra_cosdec_mas_yr, pm_dec_mas_yr, parallax_mas,
# rv_km_s, epoch_jyear): a star; `vs server` also takes star = "Vega" (the bundled catalog)

[camera]                     # guide_camera.CameraConfig's fields (all optional)
period_s = 0.1
exposure_s = 0.05
readout_latency_s = 0.05
noise_arcsec = 0.5
fov_radius_arcsec = 3600.0
dropout_fraction = 0.0
seed = 0
```

Errors name the file and the key (CameraConfigError).
"""

from __future__ import annotations

import math
import tomllib
from datetime import datetime
from pathlib import Path
from typing import Any

from .exceptions import CameraConfigError
from .frames import CameraConfig
from .tle_shift import shifted_elements
from .truth import CameraSite, SatelliteTruth, StarTruth

__all__ = ["load_camera_file", "read_tle_set"]

_SAT_KEYS = {"tle_file", "sat", "line1", "line2", "along_s", "across_arcsec", "at"}
_STAR_KEYS = {"ra_deg", "dec_deg", "pm_ra_cosdec_mas_yr", "pm_dec_mas_yr", "parallax_mas",
              "rv_km_s", "epoch_jyear"}


def read_camera_file(path: str | Path) -> dict[str, Any]:
    """Parse the TOML file into {"truth": {...}, "camera": {...}} (CameraConfigError)."""
    try:
        doc = tomllib.loads(Path(path).read_text("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise CameraConfigError(f"cannot read camera file {path}: {exc}") from None
    unknown = sorted(set(doc) - {"truth", "camera"})
    if unknown or not isinstance(doc.get("truth"), dict):
        raise CameraConfigError(f"{path}: expected a [truth] table (and optionally [camera]); "
                                f"unknown: {unknown}")
    return doc


def load_camera_file(path: str | Path, site: CameraSite) -> tuple[Any, CameraConfig]:
    """Return (truth, camera config) from a camera file (docstring above)."""
    path = Path(path)
    doc = read_camera_file(path)
    return truth_from_table(doc["truth"], site, path), camera_config(doc.get("camera", {}), path)


def camera_config(table: Any, where: Path | str) -> CameraConfig:
    if not isinstance(table, dict):
        raise CameraConfigError(f"{where}: [camera] must be a table")
    fields = CameraConfig.__dataclass_fields__
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise CameraConfigError(f"{where}: unknown [camera] keys {unknown}; valid: "
                                f"{', '.join(fields)}")
    try:
        return CameraConfig(**table)
    except CameraConfigError as exc:
        raise CameraConfigError(f"{where}: {exc}") from None


def truth_from_table(t: dict[str, Any], site: CameraSite, where: Path | str):
    keys = set(t)
    if keys & _SAT_KEYS and keys & _STAR_KEYS or not keys & (_SAT_KEYS | _STAR_KEYS):
        raise CameraConfigError(f"{where}: [truth] must hold a satellite (tle_file/sat or "
                                "line1/line2, along_s, across_arcsec, at) or a star (ra_deg, "
                                "dec_deg, ...), not both")
    unknown = sorted(keys - _SAT_KEYS - _STAR_KEYS)
    if unknown:
        raise CameraConfigError(f"{where}: unknown [truth] keys {unknown}")
    if keys & _STAR_KEYS:
        return StarTruth(site=site, **{k: _number(t, k, where) for k in keys})
    if "tle_file" in t:
        base = Path(where).parent if isinstance(where, Path) else Path(".")
        line1, line2 = read_tle_set(base / str(t["tle_file"]), t.get("sat"))
    elif "line1" in t and "line2" in t:
        line1, line2 = str(t["line1"]), str(t["line2"])
    else:
        raise CameraConfigError(f"{where}: a satellite needs tle_file (+ sat) or line1 and line2")
    along = _number(t, "along_s", where) if "along_s" in t else 0.0
    across = _number(t, "across_arcsec", where) if "across_arcsec" in t else 0.0
    if along or across:
        if "at" not in t:
            raise CameraConfigError(f"{where}: a moved satellite needs at = \"UTC\" (where "
                                    "across_arcsec is measured)")
        try:
            at = datetime.fromisoformat(str(t["at"]).replace("Z", "+00:00"))
            at_us = int(round(at.timestamp() * 1e6))
        except ValueError:
            raise CameraConfigError(f"{where}: at = {t['at']!r}: expected ISO-8601 UTC") from None
        return SatelliteTruth.from_satrec(
            shifted_elements(line1, line2, along_s=along, across_arcsec=across, at_us=at_us,
                             site=site), site)
    return SatelliteTruth(line1, line2, site)


def read_tle_set(path: Path, name: Any = None) -> tuple[str, str]:
    """The element lines of one satellite in a 2- or 3-line TLE file (the first, or `name`)."""
    try:
        lines = [ln.rstrip() for ln in path.read_text("utf-8").splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise CameraConfigError(f"cannot read TLE file {path}: {exc}") from None
    sets, label = [], ""
    for i, line in enumerate(lines):
        if line.startswith("1 ") and i + 1 < len(lines) and lines[i + 1].startswith("2 "):
            sets.append((label, line, lines[i + 1]))
        elif not line.startswith("2 "):
            label = line.strip()
    if not sets:
        raise CameraConfigError(f"{path}: no TLE set (lines '1 ...' and '2 ...')")
    if name is None:
        return sets[0][1], sets[0][2]
    key = str(name).strip().lower()
    for label, l1, l2 in sets:
        if label.lower() == key or key in label.lower():
            return l1, l2
    raise CameraConfigError(f"{path}: no satellite named {name!r}")


def _number(t: dict[str, Any], key: str, where: Path | str) -> float:
    v = t[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise CameraConfigError(f"{where}: {key} = {v!r}: expected a finite number")
    return float(v)
