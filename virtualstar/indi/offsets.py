"""VirtualStar's INDI properties for offsets and closed-loop tracking (docs/alpaca-indi.md).

* ``VS_OFFSET`` (Number, group "Offsets"): the running track's offsets — ``RA``, ``DEC``
  (arcsec on the sky east/north), ``AZ``, ``EL`` (arcsec of the axes), ``PATH`` (seconds
  of time along the track), ``TRANSVERSE`` (arcsec across it, + left of travel). Writing
  members *sets* those totals (the VSS `offset` command, op=set, applied from 20 ms after
  it is accepted, within the offset limits); the values follow the VSS's status.
* ``VS_OFFSET_RESET`` (Switch): ``RESET`` On takes every offset back to 0.
* ``VS_CLOSED_LOOP`` (Switch): ``CLOSED_LOOP_ON`` / ``OFF``: whether a satellite track
  started with SAT_TRACKING_STAT (and a track started with TELESCOPE_TRACK_STATE) is
  guided by the server's guide camera.
"""

from __future__ import annotations

from typing import Any

from .protocol import Element, Vector

__all__ = ["MEMBERS", "offset_vectors", "offsets_from_status", "offset_requests"]

GROUP = "Offsets"
#: member -> (VSS axis, VSS unit key, unit shown)
MEMBERS = {"RA": ("ra", "arcsec"), "DEC": ("dec", "arcsec"), "AZ": ("az", "arcsec"),
           "EL": ("el", "arcsec"), "PATH": ("path", "seconds"),
           "TRANSVERSE": ("transverse", "arcsec")}
_LIMIT = {"arcsec": 3600.0, "seconds": 30.0}


def offset_vectors(device: str) -> list[Vector]:
    numbers = [Element(m, f"{m.title()} ({'s' if unit == 'seconds' else 'arcsec'})", 0.0, "%.3f",
                       -_LIMIT[unit], _LIMIT[unit], 0.0) for m, (_, unit) in MEMBERS.items()]
    return [
        Vector(device, "VS_OFFSET", "Number", "Offsets", GROUP, numbers),
        Vector(device, "VS_OFFSET_RESET", "Switch", "Reset offsets", GROUP,
               [Element("RESET", "Reset", False)], rule="AtMostOne"),
        Vector(device, "VS_CLOSED_LOOP", "Switch", "Closed loop", GROUP,
               [Element("CLOSED_LOOP_ON", "On", False), Element("CLOSED_LOOP_OFF", "Off", True)]),
    ]


def offset_requests(members: dict[str, float]) -> list[dict[str, Any]]:
    """The VSS `offset` commands (op=set) that a write of VS_OFFSET members asks for."""
    out = []
    for name, value in members.items():
        axis, unit = MEMBERS[name]
        out.append({"axis": axis, "op": "set", unit: float(value)})
    return out


def offsets_from_status(st: dict[str, Any]) -> dict[str, float]:
    """The VS_OFFSET values of a VSS status (0 for axes never offset, or no track)."""
    axes = ((st.get("corrections") or {}).get("offsets") or {}).get("axes") or {}
    values = {}
    for member, (axis, unit) in MEMBERS.items():
        doc = axes.get(axis) or {}
        values[member] = float(doc.get("total_s" if unit == "seconds" else "total_arcsec", 0.0))
    return values
