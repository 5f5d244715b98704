"""OMM (CCSDS Orbit Mean-Elements Message) in CelesTrak's JSON form.

CelesTrak's ``FORMAT=json`` gives a list of objects with the keywords below; values
may be numbers or strings.  Each record is checked, normalised to the strings that
``sgp4.omm.initialize`` expects, and returned as a TleRecord that keeps the OMM
fields (so propagation uses full OMM precision).
"""

from __future__ import annotations

import json
import re
from datetime import datetime

from sgp4.api import Satrec
from sgp4.exporter import export_tle

from catalogs.exceptions import OmmFormatError
from catalogs.tle import TleRecord

REQUIRED_FIELDS = (
    "OBJECT_NAME", "OBJECT_ID", "EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION",
    "RA_OF_ASC_NODE", "ARG_OF_PERICENTER", "MEAN_ANOMALY", "NORAD_CAT_ID", "BSTAR",
    "MEAN_MOTION_DOT", "MEAN_MOTION_DDOT",
)
# Optional in practice; CelesTrak always sends them, other producers sometimes do not.
DEFAULTS = {"EPHEMERIS_TYPE": "0", "CLASSIFICATION_TYPE": "U", "ELEMENT_SET_NO": "999",
            "REV_AT_EPOCH": "0"}
_FLOAT_FIELDS = ("MEAN_MOTION", "ECCENTRICITY", "INCLINATION", "RA_OF_ASC_NODE",
                 "ARG_OF_PERICENTER", "MEAN_ANOMALY", "BSTAR", "MEAN_MOTION_DOT",
                 "MEAN_MOTION_DDOT")
_INT_FIELDS = ("NORAD_CAT_ID", "EPHEMERIS_TYPE", "ELEMENT_SET_NO", "REV_AT_EPOCH")
_EPOCH = re.compile(r"^(\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2})(\.\d{1,6})?Z?$")
_OBJECT_ID = re.compile(r"^\d{4}-\d{3}[A-Z]{0,3}$")


def _normalise(raw: object, index: int, source: str) -> dict[str, str]:
    if not isinstance(raw, dict):
        raise OmmFormatError(source, index, f"expected a JSON object, got {type(raw).__name__}")
    missing = [k for k in REQUIRED_FIELDS if k not in raw]
    if missing:
        raise OmmFormatError(source, index, f"missing field(s) {', '.join(missing)}")
    fields = {k: str(v) for k, v in {**DEFAULTS, **raw}.items() if v is not None}
    for key in _FLOAT_FIELDS:
        try:
            float(fields[key])
        except ValueError:
            raise OmmFormatError(source, index, f"{key} is {fields[key]!r}, expected a number") from None
    for key in _INT_FIELDS:
        if not re.fullmatch(r"\d+", fields[key]):
            raise OmmFormatError(source, index, f"{key} is {fields[key]!r}, expected an integer")
    m = _EPOCH.match(fields["EPOCH"])
    if not m:
        raise OmmFormatError(source, index, f"EPOCH is {fields['EPOCH']!r}, expected "
                             "YYYY-MM-DDThh:mm:ss.ffffff (UTC)")
    # sgp4.omm.initialize parses exactly '%Y-%m-%dT%H:%M:%S.%f'.
    fields["EPOCH"] = m.group(1) + (m.group(2) or ".0")
    datetime.strptime(fields["EPOCH"], "%Y-%m-%dT%H:%M:%S.%f")
    if not _OBJECT_ID.match(fields["OBJECT_ID"]):
        raise OmmFormatError(source, index, f"OBJECT_ID is {fields['OBJECT_ID']!r}, expected "
                             "a COSPAR id like 1998-067A")
    return fields


def parse_omm_json(text: str, source: str = "<string>") -> list[TleRecord]:
    """Parse CelesTrak OMM JSON (a list of records or one record) into TleRecords.

    Raises OmmFormatError naming the record (0-based index) and the field.
    """
    from sgp4 import omm

    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise OmmFormatError(source, 0, f"not valid JSON (line {exc.lineno}, column {exc.colno}: "
                                        f"{exc.msg})") from None
    items = data if isinstance(data, list) else [data]
    records = []
    for index, raw in enumerate(items):
        fields = _normalise(raw, index, source)
        sat = Satrec()
        omm.initialize(sat, fields)
        line1, line2 = export_tle(sat)
        records.append(TleRecord(fields["OBJECT_NAME"].strip(), line1, line2, source, fields))
    return records
