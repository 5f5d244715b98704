"""Read and write TPOINT's model files (`.mod`, what TPOINT's OUTMOD writes).

Layout, one line each (values and σ in arcseconds):

    caption line (free text)
    T  N_OBS  SKY_RMS  F1  F2        count of observations fitted and sky RMS; F1, F2 are
                                     two further numbers TPOINT writes (read and kept)
    M NAME  VALUE  [SIGMA]           one per term. Column 1 is '&' for a harmonic (generic)
                                     term, column 2 '=' for a term held fixed (no σ)
    END

TPOINT's own term names are kept; a term this package does not implement is refused by
name (see `terms.TPOINT_TERMS_NOT_IMPLEMENTED`), never skipped.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import IO

from .exceptions import ModelFileError, UnknownTermError
from .model import PointingModel
from .terms import get_term

_TERM_LAYOUT = ("a term line '[&][=]NAME VALUE [SIGMA]' (arcsec), e.g. '  IA  -291.2637  0.97020' "
                "or '& HASA2  -1.1554  0.37209', or END")
_T_LAYOUT = "the line 'T N_OBS SKY_RMS ...' after the caption, e.g. 'T   53   1.3005'"


def looks_like_tpoint_model(text: str) -> bool:
    """Return True when `text` has TPOINT's model layout (a `T` line second, not JSON)."""
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return len(lines) >= 2 and not lines[0].lstrip().startswith("{") \
        and lines[1].split()[:1] == ["T"]


def read_tpoint_model(lines: Iterable[str], source: str = "<tpoint model>", *,
                      substitute: Mapping[str, str] | None = None) -> PointingModel:
    """Parse a TPOINT `.mod` model; raises ModelFileError naming the line and what was expected.

    `substitute` maps a TPOINT term this package does not implement to one it does (e.g.
    {"TX10": "TX"}), applied only where the caller says the two agree on its data.
    """
    substitute = {k.upper(): v.upper() for k, v in (substitute or {}).items()}
    caption: str | None = None
    header: tuple[int, float, tuple[float, ...]] | None = None
    names: list[str] = []
    values: list[float] = []
    sigmas: list[float] = []
    fixed: list[str] = []
    tpoint_names: dict[str, str] = {}
    ended = False
    for line_no, raw in enumerate(lines, start=1):
        line = raw.rstrip("\r\n")
        if not line.strip():
            continue
        if caption is None:
            caption = line.strip()
            continue
        where = f"{source}:{line_no}"
        if header is None:
            header = _parse_t_line(line, where)
            continue
        if line.strip().upper() == "END":
            ended = True
            break
        name, value, sigma, is_fixed = _parse_term_line(line, where)
        used = substitute.get(name, name)
        try:
            canonical = get_term(used).name
        except UnknownTermError as exc:
            raise ModelFileError(where, str(exc)) from None
        if canonical in names:
            raise ModelFileError(where, f"term {name} appears twice")
        names.append(canonical)
        values.append(value)
        sigmas.append(sigma)
        if is_fixed:
            fixed.append(canonical)
        if used != name:
            tpoint_names[canonical] = name
    if caption is None or header is None:
        raise ModelFileError(source, "the file ends before the caption and the T line; "
                             f"expected {_T_LAYOUT}")
    if not ended:
        raise ModelFileError(source, "no END line; the file may be cut short")
    n_obs, sky_rms, extra = header
    info = {"format": "tpoint", "caption": caption, "n_obs": n_obs,
            "sky_rms_arcsec": sky_rms, "t_line_extra": list(extra), "fixed": fixed}
    if tpoint_names:
        info["substituted"] = tpoint_names
    return PointingModel(tuple(names), tuple(values),
                         None if all(math.isnan(s) for s in sigmas) else tuple(sigmas), info)


def load_tpoint_model(path: str | Path, *, substitute: Mapping[str, str] | None = None
                      ) -> PointingModel:
    """Read a TPOINT `.mod` file; raises ModelFileError (also for an unreadable file)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return read_tpoint_model(f, str(path), substitute=substitute)
    except OSError as exc:
        raise ModelFileError(str(path), f"cannot read: {exc.strerror or exc}") from exc


def write_tpoint_model(model: PointingModel, out: IO[str], *, caption: str = "",
                       n_obs: int | None = None, sky_rms_arcsec: float | None = None) -> None:
    """Write `model` in TPOINT's `.mod` layout; n_obs and sky RMS default to its fit info."""
    info = model.fit_info
    n = int(n_obs if n_obs is not None else info.get("n_obs", 0))
    rms = float(sky_rms_arcsec if sky_rms_arcsec is not None else info.get("sky_rms_arcsec", 0.0))
    extra = list(info.get("t_line_extra", [0.0, 0.0]))[:2] + [0.0, 0.0]
    fixed = set(info.get("fixed", ()))
    names_back = dict(info.get("substituted", {}))
    out.write((caption or str(info.get("caption", "")) or "VirtualStar pointing model")
              .replace("\n", " ") + "\n")
    out.write(f"T {n:4d} {rms:9.4f} {extra[0]:8.3f} {extra[1]:8.4f}\n")
    for i, name in enumerate(model.terms):
        marker = ("&" if name.startswith("H") else " ") + ("=" if name in fixed else " ")
        line = f"{marker}{names_back.get(name, name):<8s}{model.values_arcsec[i]:+12.4f}"
        sigma = model.sigmas_arcsec[i] if model.sigmas_arcsec is not None else math.nan
        if name not in fixed and math.isfinite(sigma):
            line += f"{sigma:12.5f}"
        out.write(line + "\n")
    out.write("END\n")


def save_tpoint_model(model: PointingModel, path: str | Path, **header: object) -> None:
    """Write `model` to `path` in TPOINT's `.mod` layout (see `write_tpoint_model`)."""
    with open(path, "w", encoding="utf-8") as f:
        write_tpoint_model(model, f, **header)  # type: ignore[arg-type]


def _parse_t_line(line: str, where: str) -> tuple[int, float, tuple[float, ...]]:
    tokens = line.split()
    if not tokens or tokens[0] != "T" or len(tokens) < 3:
        raise ModelFileError(where, f"expected {_T_LAYOUT}, got {line.strip()!r}")
    try:
        n_obs = int(tokens[1])
        numbers = tuple(float(t) for t in tokens[2:])
    except ValueError:
        raise ModelFileError(where, f"the T line has a non-numeric field; expected {_T_LAYOUT}"
                             ) from None
    return n_obs, numbers[0], numbers[1:]


def _parse_term_line(line: str, where: str) -> tuple[str, float, float, bool]:
    marker, body = line[:2], line[2:]
    if marker.strip() not in ("", "&", "=", "&="):
        # a line without the two marker columns, e.g. "IA -291.26": read it leniently
        marker, body = "", line
    is_fixed = "=" in marker
    tokens = body.split()
    if len(tokens) not in (2, 3):
        raise ModelFileError(where, f"expected {_TERM_LAYOUT}, got {line.strip()!r}")
    name = tokens[0].upper()
    try:
        value = float(tokens[1])
        sigma = float(tokens[2]) if len(tokens) == 3 else math.nan
    except ValueError:
        raise ModelFileError(where, f"term {name}: value and σ must be numbers; expected "
                             f"{_TERM_LAYOUT}") from None
    if not (math.isfinite(value) and (math.isnan(sigma) or math.isfinite(sigma))):
        raise ModelFileError(where, f"term {name}: value and σ must be finite")
    return name, value, sigma, is_fixed
