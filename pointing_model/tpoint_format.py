"""Read and write TPOINT's input format for alt-az pointing runs.

Layout (lines starting with `!` are comments anywhere, blank lines are skipped):

    caption line (free text)
    : ALTAZ                       option lines start with ':'; ALTAZ is required here
    : ROTNL
    -30 14 40.3 [Y M D [T_C [P_hPa [H_m [RH [λ_um [lapse_K_m]]]]]]]   run parameters
    A_obs E_obs A_raw E_raw [aux ...] [; comment]                        one per star, degrees
    ; A_obs E_obs A_raw E_raw ...  a record masked by a leading ';' (TPOINT skips it): read
                                  past and counted in `PointingRun.masked_lines`
    END                           optional; anything after it is ignored

A line starting with ';' that does not hold a record is a comment.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import IO

import numpy as np

from .exceptions import DataFormatError
from .runs import PointingRun, RunParameters

_PARAMETERS_LAYOUT = ("latitude as 'deg min sec' with its sign (e.g. -30 14 40.3), optionally "
                      "followed by 'year month day', temperature °C, pressure hPa, height m, "
                      "relative humidity 0-1, wavelength µm, lapse rate K/m")
_RECORD_LAYOUT = ("a record 'A_obs E_obs A_raw E_raw [aux ...] [; comment]' in decimal degrees, "
                  "or END")


def read_tpoint(lines: Iterable[str], source: str = "<tpoint>") -> PointingRun:
    """Parse a TPOINT alt-az run from an iterable of lines (e.g. an open text file).

    Raises DataFormatError naming `source`, the line and what was expected there.
    """
    caption: str | None = None
    options: list[str] = []
    params: RunParameters | None = None
    rows: list[tuple[float, float, float, float]] = []
    aux: list[tuple[float, ...]] = []
    comments: list[str] = []
    line_numbers: list[int] = []
    masked: list[int] = []
    last_line_no = 0
    for line_no, raw in enumerate(lines, start=1):
        last_line_no = line_no
        line = raw.rstrip("\r\n")
        text = line.strip()
        if not text or text.startswith("!"):
            continue
        if caption is None:
            caption = text
            continue
        if params is None and text.startswith(":"):
            options.append(text[1:].strip().upper())
            continue
        if params is None:
            _check_options(options, source, line_no, line)
            params = _parse_parameters(text, source, line_no, line)
            continue
        if text.upper() == "END":
            break
        if text.startswith(";"):
            if _is_masked_record(text[1:]):
                masked.append(line_no)
            continue
        if text.startswith(":"):
            raise DataFormatError(source, line_no, "option line after the run-parameters line",
                                  "options (': ALTAZ') before the latitude line", line)
        row, extra, comment = _parse_record(text, source, line_no, line)
        rows.append(row)
        aux.append(extra)
        comments.append(comment)
        line_numbers.append(line_no)
    if caption is None:
        raise DataFormatError(source, None, "the file is empty", "a caption line first")
    if params is None:
        raise DataFormatError(source, last_line_no + 1, "the file ends before the run-parameters "
                              "line", _PARAMETERS_LAYOUT)
    if not rows:
        raise DataFormatError(source, last_line_no + 1, "no observation records", _RECORD_LAYOUT)
    data = np.array(rows, dtype=float)
    return PointingRun(data[:, 0], data[:, 1], data[:, 2], data[:, 3], params, caption,
                       tuple(options), tuple(aux), tuple(comments), tuple(line_numbers), source,
                       masked_lines=tuple(masked))


def _is_masked_record(text: str) -> bool:
    """Return True when `text` (a line after its leading ';') holds a record's four numbers."""
    tokens = text.partition(";")[0].split()
    return len(tokens) >= 4 and all(_is_float(t) for t in tokens[:4])


def load_tpoint(path: str | Path) -> PointingRun:
    """Read a TPOINT alt-az run from a file path; raises DataFormatError or OSError."""
    with open(path, encoding="utf-8", errors="replace") as f:
        return read_tpoint(f, str(path))


def write_tpoint(run: PointingRun, out: IO[str]) -> None:
    """Write `run` in TPOINT's input format (alt-az, decimal degrees) to a text stream."""
    out.write((run.caption or "VirtualStar pointing run").replace("\n", " ") + "\n")
    options = list(run.options) or ["ALTAZ"]
    if "ALTAZ" not in options:
        options.insert(0, "ALTAZ")
    for option in options:
        out.write(f": {option}\n")
    params = run.parameters or RunParameters(latitude_deg=0.0)
    out.write(format_parameters(params) + "\n")
    for i in range(len(run)):
        fields = [f"{run.obs_az_deg[i]:12.7f}", f"{run.obs_el_deg[i]:11.7f}",
                  f"{run.enc_az_deg[i]:12.7f}", f"{run.enc_el_deg[i]:11.7f}"]
        if run.aux and run.aux[i]:
            fields += [f"{v:.7f}" for v in run.aux[i]]
        line = " ".join(fields)
        if run.comments and run.comments[i]:
            line += " ; " + run.comments[i].replace("\n", " ")
        out.write(line + "\n")
    out.write("END\n")


def format_parameters(params: RunParameters) -> str:
    """Return the run-parameters line: signed latitude as deg min sec, then optional fields."""
    sign = "-" if params.latitude_deg < 0 else "+"
    total = round(abs(params.latitude_deg) * 36000)  # tenths of an arcsecond
    deg, rem = divmod(total, 36000)
    minutes, tenths = divmod(rem, 600)
    parts = [f"{sign}{deg:02d}", f"{minutes:02d}", f"{tenths / 10:04.1f}"]
    optional = [params.temperature_c, params.pressure_hpa, params.height_m, params.humidity,
                params.wavelength_um, params.lapse_rate_k_m]
    if params.date is not None:
        parts += [str(v) for v in params.date]
        while optional and optional[-1] is None:
            optional.pop()
        parts += ["0" if v is None else f"{v:g}" for v in optional]
    return " ".join(parts)


def _check_options(options: list[str], source: str, line_no: int, line: str) -> None:
    words = {w for opt in options for w in opt.split()}
    if "ALTAZ" not in words:
        raise DataFormatError(
            source, line_no, "no ': ALTAZ' option line before the run parameters (TPOINT would "
            "read the records as equatorial; only alt-az runs are supported)",
            "': ALTAZ' between the caption and the latitude line", line)


def _parse_parameters(text: str, source: str, line_no: int, line: str) -> RunParameters:
    tokens = text.split()
    if len(tokens) not in (3, 6, 7, 8, 9, 10, 11, 12):
        raise DataFormatError(source, line_no, f"run-parameters line has {len(tokens)} fields",
                              _PARAMETERS_LAYOUT, line)
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        raise DataFormatError(source, line_no, "run-parameters line has a non-numeric field",
                              _PARAMETERS_LAYOUT, line) from None
    deg, minutes, seconds = values[:3]
    if not (0 <= abs(deg) <= 90 and 0 <= minutes < 60 and 0 <= seconds < 60):
        raise DataFormatError(source, line_no, "latitude out of range",
                              "degrees within ±90, minutes and seconds within 0-60", line)
    negative = tokens[0].lstrip().startswith("-")
    latitude = abs(deg) + minutes / 60 + seconds / 3600
    latitude = -latitude if negative else latitude
    date = None
    if len(values) >= 6:
        y, m, d = values[3:6]
        if not (all(v == int(v) for v in (y, m, d)) and 1 <= m <= 12 and 1 <= d <= 31):
            raise DataFormatError(source, line_no, "the date after the latitude is not valid",
                                  "'year month day' as integers, e.g. 2022 4 6", line)
        date = (int(y), int(m), int(d))
    rest = values[6:] + [None] * (6 - len(values[6:]))
    return RunParameters(latitude, date, *rest)


def _parse_record(text: str, source: str, line_no: int, line: str
                  ) -> tuple[tuple[float, float, float, float], tuple[float, ...], str]:
    data, _, comment = text.partition(";")
    tokens = data.split()
    if len(tokens) < 4:
        raise DataFormatError(source, line_no, f"record has {len(tokens)} numeric field(s)",
                              _RECORD_LAYOUT, line)
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise DataFormatError(source, line_no, f"field {bad!r} is not a number",
                              _RECORD_LAYOUT, line) from None
    if not all(math.isfinite(v) for v in values):
        raise DataFormatError(source, line_no, "record has a non-finite number",
                              _RECORD_LAYOUT, line)
    a_obs, e_obs, a_raw, e_raw = values[:4]
    for name, el in (("E_obs", e_obs), ("E_raw", e_raw)):
        if not -90.0 <= el <= 90.0:
            raise DataFormatError(source, line_no, f"{name} = {el:g} is not an elevation",
                                  "elevations within [-90, 90] degrees", line)
    return (a_obs, e_obs, a_raw, e_raw), tuple(values[4:]), comment.strip()


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True
