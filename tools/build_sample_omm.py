"""Make catalogs/data/stations.json (CelesTrak-style OMM JSON) from catalogs/data/stations.tle.

    .venv/bin/python tools/build_sample_omm.py

Each element set of the bundled stations TLE file is converted with sgp4's own
exporter (``sgp4.exporter.export_omm``) and reduced to the keywords CelesTrak's
``FORMAT=json`` output carries, in CelesTrak's order and with numbers as JSON
numbers.  The OMM set therefore describes the same orbits as the TLE set, which
lets the tests check the OMM reader against the TLE reader.
"""

from __future__ import annotations

import json
from pathlib import Path

from sgp4.api import Satrec
from sgp4.exporter import export_omm

DATA = Path(__file__).resolve().parents[1] / "catalogs" / "data"
CELESTRAK_KEYS = (
    "OBJECT_NAME", "OBJECT_ID", "EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION",
    "RA_OF_ASC_NODE", "ARG_OF_PERICENTER", "MEAN_ANOMALY", "EPHEMERIS_TYPE",
    "CLASSIFICATION_TYPE", "NORAD_CAT_ID", "ELEMENT_SET_NO", "REV_AT_EPOCH", "BSTAR",
    "MEAN_MOTION_DOT", "MEAN_MOTION_DDOT",
)


def main() -> int:
    lines = [ln.rstrip() for ln in (DATA / "stations.tle").read_text().splitlines() if ln.strip()]
    records = []
    for name, line1, line2 in zip(lines[0::3], lines[1::3], lines[2::3], strict=True):
        omm = export_omm(Satrec.twoline2rv(line1, line2), name.strip())
        records.append({k: omm[k] for k in CELESTRAK_KEYS})
    (DATA / "stations.json").write_text(json.dumps(records, indent=1) + "\n")
    print(f"wrote {len(records)} OMM records to {DATA / 'stations.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
