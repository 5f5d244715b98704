"""User star catalogs from CSV files.

Header row required; columns (case-insensitive): ``name``, ``ra``, ``dec`` and
optionally ``pm_ra_cosdec_mas_yr`` (alias ``pmra``), ``pm_dec_mas_yr`` (``pmdec``),
``parallax_mas`` (``plx``), ``rv_km_s`` (``rv``), ``vmag``, ``epoch_jyear`` (default
2000.0), ``hip``, ``bayer``.  RA is degrees when a plain number ("83.633") and hours
when sexagesimal ("05h34m31.94s", "05:34:31.94", "5 34 31.94"); Dec is degrees either
way ("22.0145", "+22d00m52.2s", "+22:00:52.2").  Lines starting with '#' are comments.
"""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path
from typing import TextIO

from catalogs.exceptions import StarCsvError
from catalogs.stars import Star, StarCatalog

DEFAULT_USER_EPOCH_JYEAR = 2000.0
_ALIASES = {
    "pmra": "pm_ra_cosdec_mas_yr", "pmdec": "pm_dec_mas_yr", "plx": "parallax_mas",
    "parallax": "parallax_mas", "rv": "rv_km_s", "mag": "vmag", "epoch": "epoch_jyear",
    "ra_deg": "ra", "dec_deg": "dec",
}
_OPTIONAL_FLOATS = ("pm_ra_cosdec_mas_yr", "pm_dec_mas_yr", "parallax_mas", "rv_km_s",
                    "vmag", "epoch_jyear")
_PLAIN_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def parse_ra_deg(text: str) -> float:
    """Return RA in degrees from decimal degrees or sexagesimal hours; raises ValueError."""
    text = text.strip()
    if _PLAIN_NUMBER.match(text):
        value = float(text)
    else:
        from astropy import units as u
        from astropy.coordinates import Angle

        value = Angle(text, unit=u.hourangle).degree
    if not 0.0 <= value < 360.0:
        raise ValueError(f"RA {text!r} is outside 0..360 degrees (0..24 h)")
    return float(value)


def parse_dec_deg(text: str) -> float:
    """Return Dec in degrees from decimal or sexagesimal degrees; raises ValueError."""
    text = text.strip()
    if _PLAIN_NUMBER.match(text):
        value = float(text)
    else:
        from astropy import units as u
        from astropy.coordinates import Angle

        value = Angle(text, unit=u.deg).degree
    if not -90.0 <= value <= 90.0:
        raise ValueError(f"Dec {text!r} is outside -90..+90 degrees")
    return float(value)


def _row_to_star(row: dict[str, str], source: str, line_number: int) -> Star:
    def fail(problem: str):
        raise StarCsvError(source, line_number, problem)

    name = (row.get("name") or "").strip()
    if not name:
        fail("empty 'name'; every star needs a name")
    try:
        ra_deg = parse_ra_deg(row.get("ra") or "")
    except ValueError as exc:
        fail(f"bad 'ra' {row.get('ra')!r} ({exc}); expected degrees like 83.633 "
             "or hours like 05h34m31.94s / 05:34:31.94")
    try:
        dec_deg = parse_dec_deg(row.get("dec") or "")
    except ValueError as exc:
        fail(f"bad 'dec' {row.get('dec')!r} ({exc}); expected degrees like 22.0145 "
             "or +22d00m52.2s / +22:00:52.2")
    values: dict[str, float] = {}
    for key in _OPTIONAL_FLOATS:
        text = (row.get(key) or "").strip()
        if text:
            try:
                values[key] = float(text)
            except ValueError:
                fail(f"bad '{key}' {text!r}; expected a number")
    hip_text = (row.get("hip") or "").strip()
    if hip_text and not hip_text.isdigit():
        fail(f"bad 'hip' {hip_text!r}; expected a Hipparcos number like 91262")
    return Star(
        name=name,
        hip=int(hip_text) if hip_text else None,
        bayer=(row.get("bayer") or "").strip(),
        ra_deg=ra_deg,
        dec_deg=dec_deg,
        pm_ra_cosdec_mas_yr=values.get("pm_ra_cosdec_mas_yr", 0.0),
        pm_dec_mas_yr=values.get("pm_dec_mas_yr", 0.0),
        parallax_mas=values.get("parallax_mas", 0.0),
        rv_km_s=values.get("rv_km_s", 0.0),
        rv_known="rv_km_s" in values,
        vmag=values.get("vmag"),
        epoch_jyear=values.get("epoch_jyear", DEFAULT_USER_EPOCH_JYEAR),
    )


def read_star_csv(file: TextIO, source: str = "<stream>") -> StarCatalog:
    """Read a user star catalog from an open text file; raises StarCsvError naming the line."""
    numbered = [(i + 1, line) for i, line in enumerate(file.read().splitlines())]
    body = [(n, line) for n, line in numbered if line.strip() and not line.lstrip().startswith("#")]
    if not body:
        raise StarCsvError(source, len(numbered), "no header row; expected e.g. 'name,ra,dec'")
    header_line, header = body[0]
    columns = [_ALIASES.get(c.strip().lower(), c.strip().lower()) for c in next(csv.reader([header]))]
    missing = [c for c in ("name", "ra", "dec") if c not in columns]
    if missing:
        raise StarCsvError(source, header_line, f"header lacks column(s) {', '.join(missing)}; "
                           f"got {', '.join(columns)}; expected at least name,ra,dec")
    stars = []
    for line_number, line in body[1:]:
        cells = next(csv.reader([line]))
        if len(cells) != len(columns):
            raise StarCsvError(source, line_number, f"{len(cells)} values but the header has "
                               f"{len(columns)} columns ({', '.join(columns)})")
        stars.append(_row_to_star(dict(zip(columns, cells, strict=True)), source, line_number))
    return StarCatalog(stars)


def load_star_csv(path: str | Path) -> StarCatalog:
    """Read a user star catalog CSV file (see the module docstring for the columns)."""
    path = Path(path)
    with path.open(encoding="utf-8", newline="") as f:
        return read_star_csv(f, source=path.name)


def read_star_csv_text(text: str, source: str = "<string>") -> StarCatalog:
    """Read a user star catalog from CSV text."""
    return read_star_csv(io.StringIO(text), source)
