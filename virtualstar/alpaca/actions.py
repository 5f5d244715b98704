"""The Parameters of VirtualStar's Alpaca Actions, read without I/O (hostile text in, a VSS
command's parameters out).

* ``Action("TrackSatellite", TLE)``: the TLE text (name line and two element lines); or
  JSON ``{"tle": "...", "sat": "ISS", "closed_loop": true}`` — closed loop: guided by
  the server's guide camera (docs/vss.md, "Closed loop").
* ``Action("Offset", "dec add 5")``: ``AXIS [OP] [VALUE][s]`` — axis ra, dec, az, el,
  path, transverse (or all with reset); op add (default), set, rate, reset; VALUE
  arcsec (rate: per second), or seconds of time along the track with an ``s`` suffix
  (path only: ``path add 1.5s``). Or JSON ``{"axis", "op", "arcsec" | "seconds"}``:
  the VSS's `offset` command (docs/vss-api.md).

Errors are `AlpacaError(INVALID_VALUE)` with the expected form in the message.
"""

from __future__ import annotations

import json
import math
from typing import Any

from .protocol import INVALID_VALUE, AlpacaError

__all__ = ["offset_params", "track_satellite_params"]

MAX_PARAMETERS = 64 * 1024  # a TLE set is ~170 bytes; JSON of an offset far less
OFFSET_FORM = ("expected 'AXIS [add|set|rate|reset] [VALUE][s]' (e.g. 'dec add 5', "
               "'path add 1.5s', 'all reset') or JSON {\"axis\", \"op\", \"arcsec\" | "
               "\"seconds\"}")
_OFFSET_KEYS = {"axis", "op", "arcsec", "seconds"}


def _json_object(text: str, what: str) -> dict[str, Any] | None:
    if not text.lstrip().startswith("{"):
        return None
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise AlpacaError(INVALID_VALUE, f"{what}: Parameters is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise AlpacaError(INVALID_VALUE, f"{what}: Parameters must be a JSON object")
    return doc


def track_satellite_params(text: str) -> dict[str, Any]:
    """The VSS `track` parameters of Action("TrackSatellite", text)."""
    if len(text) > MAX_PARAMETERS:
        raise AlpacaError(INVALID_VALUE, "TrackSatellite: Parameters too long for a TLE")
    doc = _json_object(text, "TrackSatellite")
    if doc is None:
        if not text.strip():
            raise AlpacaError(INVALID_VALUE, "TrackSatellite: Parameters must hold the TLE "
                              "(name line and the two element lines)")
        return {"tle": text}
    unknown = sorted(set(doc) - {"tle", "sat", "closed_loop"})
    tle, sat, loop = doc.get("tle"), doc.get("sat"), doc.get("closed_loop", False)
    if unknown or not isinstance(tle, str) or not tle.strip() \
            or not (sat is None or isinstance(sat, str)) or not isinstance(loop, bool):
        raise AlpacaError(INVALID_VALUE, "TrackSatellite: expected the TLE text, or JSON "
                          "{\"tle\": TEXT, \"sat\": NAME (optional), \"closed_loop\": true|false}"
                          + (f"; unknown keys {unknown}" if unknown else ""))
    params: dict[str, Any] = {"tle": tle}
    if sat is not None:
        params["sat"] = sat
    if loop:
        params["closed_loop"] = True
    return params


def offset_params(text: str) -> dict[str, Any]:
    """The VSS `offset` parameters of Action("Offset", text); the VSS checks the ranges."""
    if len(text) > 1024:
        raise AlpacaError(INVALID_VALUE, f"Offset: Parameters too long; {OFFSET_FORM}")
    doc = _json_object(text, "Offset")
    if doc is not None:
        unknown = sorted(set(doc) - _OFFSET_KEYS)
        if unknown or not isinstance(doc.get("axis"), str):
            raise AlpacaError(INVALID_VALUE, f"Offset: {OFFSET_FORM}"
                              + (f"; unknown keys {unknown}" if unknown else ""))
        return doc
    words = text.split()
    if not 1 <= len(words) <= 3:
        raise AlpacaError(INVALID_VALUE, f"Offset: {text!r}: {OFFSET_FORM}")
    params: dict[str, Any] = {"axis": words[0].lower()}
    if not params["axis"].isalpha():
        raise AlpacaError(INVALID_VALUE, f"Offset: axis {words[0]!r}; {OFFSET_FORM}")
    rest = words[1:]
    if rest and rest[0].lower() in ("add", "set", "rate", "reset"):
        params["op"] = rest.pop(0).lower()
    if params.get("op", "add") != "reset" and not rest:
        raise AlpacaError(INVALID_VALUE, f"Offset: {text!r} needs a value; {OFFSET_FORM}")
    if rest:
        value = rest[0]
        key = "arcsec"
        if value.lower().endswith("s"):
            key, value = "seconds", value[:-1]
        try:
            number = float(value)
        except ValueError:
            raise AlpacaError(INVALID_VALUE, f"Offset: {rest[0]!r} is not a number; "
                              f"{OFFSET_FORM}") from None
        if not math.isfinite(number):
            raise AlpacaError(INVALID_VALUE, f"Offset: {rest[0]!r} must be finite")
        params[key] = number
    return params
