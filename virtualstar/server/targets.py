"""Sky targets from API request parameters (one of radec, ra_deg+dec_deg, star, altaz, az_deg+el_deg)."""

from __future__ import annotations

import math
from typing import Any

from virtualstar.astro import IcrsStar, parse_altaz, parse_radec, resolve_target
from virtualstar.astro.exceptions import AstroError

from .exceptions import BadRequest

__all__ = ["parse_target"]


def parse_target(params: dict[str, Any]) -> tuple[Any, str, tuple[float, float] | None]:
    """Return (astro target, display name, fixed alt-az or None) from request parameters.

    Exactly one of ``radec`` ("RA DEC" text), ``ra_deg``+``dec_deg``, ``star`` (name),
    ``altaz`` ("AZ EL" text) or ``az_deg``+``el_deg`` must be given. Raises BadRequest.
    """
    given = [k for k in ("radec", "ra_deg", "star", "altaz", "az_deg") if params.get(k) is not None]
    if len(given) != 1:
        raise BadRequest("give exactly one target: radec (\"RA DEC\"), ra_deg+dec_deg, star "
                         f"(a name), altaz (\"AZ EL\") or az_deg+el_deg; got {given or 'none'}")
    key = given[0]
    try:
        if key == "radec":
            ra, dec = parse_radec(str(params["radec"]))
            return IcrsStar(ra, dec, name=f"RA {ra:.4f} Dec {dec:+.4f}"), str(params["radec"]), None
        if key == "ra_deg":
            ra, dec = _number(params, "ra_deg"), _number(params, "dec_deg")
            if not (0 <= ra < 360 and -90 <= dec <= 90):
                raise BadRequest(f"ra_deg={ra}, dec_deg={dec}: expected 0 <= ra < 360, -90 <= dec <= 90")
            return IcrsStar(ra, dec, name=f"RA {ra:.4f} Dec {dec:+.4f}"), f"RA {ra:g} Dec {dec:g}", None
        if key == "star":
            target = resolve_target(str(params["star"]))
            return target, getattr(target, "name", "") or str(params["star"]), None
        if key == "altaz":
            try:
                az, el = parse_altaz(str(params["altaz"]))
            except AstroError as exc:
                raise BadRequest(f"altaz {exc}") from None
        else:
            az, el = _number(params, "az_deg"), _number(params, "el_deg")
    except AstroError as exc:
        raise BadRequest(str(exc)) from None
    if not (math.isfinite(az) and 0.0 <= az < 360.0):
        raise BadRequest(f"az {az:g}: expected 0 <= az < 360 degrees (north through east)")
    if not -90.0 <= el <= 90.0:
        raise BadRequest(f"el {el:g}: expected -90 <= el <= 90 degrees")
    return None, f"az {az:g} el {el:g}", (az, el)


def _number(params: dict[str, Any], key: str) -> float:
    value = params.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise BadRequest(f"{key}={value!r}: expected a finite number")
    return float(value)

