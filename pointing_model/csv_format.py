"""Read pointing runs from CSV.

A header row names the columns (any order; extra columns are ignored):

    utc, ra_deg, dec_deg, obs_az_deg, obs_el_deg, enc_az_deg, enc_el_deg

Every row needs `enc_az_deg, enc_el_deg` and either `obs_az_deg, obs_el_deg` (observed
place) or `utc, ra_deg, dec_deg` (catalogue ICRS place at that UTC). The core does not
compute sky positions: RA/Dec rows are converted by a `radec_to_altaz` callable the
caller passes in (the `pointing-model` CLI passes one built on virtualstar.astro).
Lines starting with `#` are comments; `# latitude_deg = -30.2445` sets the site latitude.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

from .exceptions import DataFormatError
from .runs import PointingRun, RunParameters

#: (utc strings, ra_deg, dec_deg) -> (observed az_deg, observed el_deg)
RaDecToAltAz = Callable[[Sequence[str], np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]

_EXPECTED = ("columns enc_az_deg, enc_el_deg and either obs_az_deg, obs_el_deg "
             "or utc, ra_deg, dec_deg")


def read_csv(lines: Iterable[str], source: str = "<csv>", *,
             radec_to_altaz: RaDecToAltAz | None = None) -> PointingRun:
    """Parse a CSV pointing run; raises DataFormatError naming the line and the layout."""
    latitude: float | None = None
    numbered: list[tuple[int, str]] = []
    for line_no, raw in enumerate(lines, start=1):
        text = raw.strip()
        if not text:
            continue
        if text.startswith("#"):
            key, _, value = text[1:].partition("=")
            if key.strip() == "latitude_deg":
                latitude = _number(value, source, line_no, raw, "latitude_deg = <degrees>")
            continue
        numbered.append((line_no, raw))
    if not numbered:
        raise DataFormatError(source, None, "no header row", _EXPECTED)
    header_no, header_line = numbered[0]
    header = [h.strip().lower() for h in next(csv.reader([header_line]))]
    if not {"enc_az_deg", "enc_el_deg"} <= set(header) or not (
            {"obs_az_deg", "obs_el_deg"} <= set(header) or {"utc", "ra_deg", "dec_deg"} <= set(header)):
        raise DataFormatError(source, header_no, f"header has columns {', '.join(header)}",
                              _EXPECTED, header_line)
    col = {name: i for i, name in enumerate(header)}
    obs, enc, radec, utcs, line_numbers, raw_lines = [], [], [], [], [], []
    for line_no, raw in numbered[1:]:
        cells = [c.strip() for c in next(csv.reader([raw]))]
        if len(cells) < len(header):
            cells += [""] * (len(header) - len(cells))

        def cell(name: str, cells: list[str] = cells) -> str:
            return cells[col[name]] if name in col else ""

        def num(name: str, line_no: int = line_no, raw: str = raw) -> float:
            return _number(cell(name), source, line_no, raw, f"a number in column {name}")

        enc.append((num("enc_az_deg"), num("enc_el_deg")))
        if cell("obs_az_deg") or cell("obs_el_deg"):
            obs.append((num("obs_az_deg"), num("obs_el_deg")))
            radec.append(None)
            utcs.append(cell("utc"))
        elif cell("ra_deg") and cell("dec_deg") and cell("utc"):
            obs.append((math.nan, math.nan))
            radec.append((num("ra_deg"), num("dec_deg")))
            utcs.append(cell("utc"))
        else:
            raise DataFormatError(source, line_no, "row has neither obs_az_deg/obs_el_deg nor "
                                  "utc/ra_deg/dec_deg", _EXPECTED, raw)
        line_numbers.append(line_no)
        raw_lines.append(raw)
    if not enc:
        raise DataFormatError(source, header_no + 1, "no data rows after the header", _EXPECTED)
    obs_arr = np.array(obs, dtype=float)
    todo = [i for i, r in enumerate(radec) if r is not None]
    if todo:
        if radec_to_altaz is None:
            raise DataFormatError(
                source, line_numbers[todo[0]], "row gives RA/Dec, which needs a site and an "
                "astronomy library to convert", "obs_az_deg, obs_el_deg (or read the file with "
                "the pointing-model CLI, which converts RA/Dec with virtualstar.astro)",
                raw_lines[todo[0]])
        ra = np.array([radec[i][0] for i in todo])
        dec = np.array([radec[i][1] for i in todo])
        az, el = radec_to_altaz([utcs[i] for i in todo], ra, dec)
        obs_arr[todo, 0] = az
        obs_arr[todo, 1] = el
    enc_arr = np.array(enc, dtype=float)
    for arr, what in ((obs_arr, "obs_el_deg"), (enc_arr, "enc_el_deg")):
        bad = np.flatnonzero(np.abs(arr[:, 1]) > 90)
        if bad.size:
            raise DataFormatError(source, line_numbers[bad[0]], f"{what} is not an elevation",
                                  "elevations within [-90, 90] degrees")
    params = RunParameters(latitude) if latitude is not None else None
    return PointingRun(obs_arr[:, 0], obs_arr[:, 1], enc_arr[:, 0], enc_arr[:, 1], params,
                       caption=f"CSV pointing run {source}", line_numbers=tuple(line_numbers),
                       comments=tuple(utcs), source=source)


def load_csv(path: str | Path, *, radec_to_altaz: RaDecToAltAz | None = None) -> PointingRun:
    """Read a CSV pointing run from a path; raises DataFormatError or OSError."""
    with open(path, encoding="utf-8", errors="replace", newline="") as f:
        return read_csv(f, str(path), radec_to_altaz=radec_to_altaz)


def _number(text: str, source: str, line_no: int, line: str, expected: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise DataFormatError(source, line_no, f"{text.strip()!r} is not a number", expected,
                              line) from None
    if not math.isfinite(value):
        raise DataFormatError(source, line_no, f"{text.strip()!r} is not finite", expected, line)
    return value
