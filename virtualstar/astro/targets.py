"""Targets: what the mount should follow, and how a user names it.

Every target answers `observe(times, site, eop=None) -> Observation` (observed
az/el in radians and rates in rad/s), which is all the VirtualStar Server
needs; `observe_mount_times` takes mount time (int64 µs since 1970 UTC).

Kinds: IcrsStar (catalog star or user RA/Dec), SolarSystemBody, Satellite,
FixedAltAz. `resolve_target("Vega" | "05h34m31.94s +22d00m52.2s" | "mars")`
turns user text into one of them.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .bodies import BODY_SEGMENTS, SolarSystemBody
from .earth_orientation import EarthOrientation
from .exceptions import CoordinateParseError, UnknownTarget
from .observed import Observation
from .site import Site
from .stars import IcrsStar
from .timescales import UtcTimes

RADEC_FORMS = ('"05h34m31.94s +22d00m52.2s", "05:34:31.94 +22:00:52.2" (RA in hours), '
               '"83.633 22.0145" or "83.633,22.0145" (degrees)')


@runtime_checkable
class Target(Protocol):
    """Anything that gives observed az/el and rates for arrays of UTC times."""

    name: str

    def observe(self, times: UtcTimes, site: Site,
                eop: EarthOrientation | None = None) -> Observation: ...


@dataclass(frozen=True)
class FixedAltAz:
    """A fixed observed direction (a terrestrial target, a park position), degrees.

    The given elevation is the observed one: refraction is not applied again.
    """

    az_deg: float
    el_deg: float
    name: str = "fixed"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.az_deg) and -90.0 <= self.el_deg <= 90.0):
            raise CoordinateParseError(
                f"fixed target az={self.az_deg}, el={self.el_deg}: expected a finite azimuth "
                "and an elevation between -90 and 90 degrees")

    def observe(self, times: UtcTimes, site: Site,
                eop: EarthOrientation | None = None) -> Observation:
        """Return the constant direction with zero rates for every time."""
        n = len(times)
        return Observation(np.full(n, math.radians(self.az_deg % 360.0)),
                           np.full(n, math.radians(self.el_deg)), np.zeros(n), np.zeros(n))


def observe_mount_times(target: Target, t_us: np.ndarray, site: Site,
                        eop: EarthOrientation | None = None) -> Observation:
    """Return observed az/el (rad) and rates (rad/s) at mount times (int64 µs, UTC, POSIX)."""
    return target.observe(UtcTimes.from_unix_us(t_us), site, eop)


def parse_radec(text: str) -> tuple[float, float]:
    """Parse an ICRS RA/Dec pair given by a user; return (ra_deg, dec_deg).

    Accepts sexagesimal with units (05h34m31.94s +22d00m52.2s), colons (RA in
    hours) or decimal degrees, separated by a comma or spaces. Raises
    CoordinateParseError showing the accepted forms.
    """
    from catalogs import parse_dec_deg, parse_ra_deg

    ra_text, dec_text = _split_pair(text)
    try:
        ra = parse_ra_deg(ra_text)
    except ValueError as exc:
        raise CoordinateParseError(f"bad RA {ra_text!r} in {text!r}: {exc}; "
                                   f"expected {RADEC_FORMS}") from None
    try:
        dec = parse_dec_deg(dec_text)
    except ValueError as exc:
        raise CoordinateParseError(f"bad Dec {dec_text!r} in {text!r}: {exc}; "
                                   f"expected {RADEC_FORMS}") from None
    return ra, dec


def parse_altaz(text: str) -> tuple[float, float]:
    """Parse a fixed direction "AZ EL" given by a user (degrees, comma or spaces between);
    return (az_deg, el_deg): 0 <= az < 360 (north through east), -90 <= el <= 90.

    Raises CoordinateParseError saying what was wrong and what is expected.
    """
    try:
        az, el = (float(p) for p in text.replace(",", " ").split())
    except ValueError:
        raise CoordinateParseError(f"{text!r}: expected two numbers \"AZ EL\" in degrees, "
                                   "e.g. \"180 45\"") from None
    if not (math.isfinite(az) and 0.0 <= az < 360.0):
        raise CoordinateParseError(f"{text!r}: azimuth {az:g}° is outside 0..360° (north "
                                   "through east)")
    if not -90.0 <= el <= 90.0:
        raise CoordinateParseError(f"{text!r}: elevation {el:g}° is outside -90..90°")
    return az, el


def _split_pair(text: str) -> tuple[str, str]:
    if "," in text:
        parts = [p.strip() for p in text.split(",")]
    else:
        tokens = text.split()
        if len(tokens) == 6:  # "05 34 31.94 +22 00 52.2" or "05h 34m 31.94s +22d 00m 52.2s"
            glue = "" if re.search(r"[a-z]", text, re.IGNORECASE) else ":"
            parts = [glue.join(tokens[:3]), glue.join(tokens[3:])]
        else:
            # "05h 34m 31.94s +22d 00m 52.2s": Dec starts at a sign or after the RA seconds.
            joined = re.sub(r"\s+", "", text)
            m = re.fullmatch(r"([0-9.]+h[0-9.]*m?[0-9.]*s?)([+-]?[0-9].*)", joined)
            parts = [m.group(1), m.group(2)] if m and len(tokens) > 2 else tokens
    if len(parts) != 2 or not all(parts):
        raise CoordinateParseError(f"cannot read {text!r} as an RA/Dec pair; expected {RADEC_FORMS}")
    return parts[0], parts[1]


def looks_like_coordinates(text: str) -> bool:
    """Return True when text starts like a number (an RA), not like a name."""
    return bool(re.match(r"\s*[0-9]", text)) and not text.strip().lower().startswith("hip")


def resolve_target(text: str, *, catalog=None) -> Target:
    """Turn user text into a target: a coordinate pair, a planet name or a catalog star.

    Raises CoordinateParseError for a malformed pair, UnknownTarget for a name
    that is neither a body nor a star (with the catalog's suggestions).
    """
    stripped = text.strip()
    if not stripped:
        raise UnknownTarget("empty target: give a star name, a planet or an RA/Dec pair")
    if looks_like_coordinates(stripped) and not stripped.isdigit():
        ra, dec = parse_radec(stripped)
        return IcrsStar(ra, dec, name=f"RA {ra:.5f} Dec {dec:+.5f}")
    if stripped.lower() in BODY_SEGMENTS:
        return SolarSystemBody(stripped.lower())
    from catalogs import UnknownStar, bright_stars

    cat = catalog if catalog is not None else bright_stars()
    try:
        star = cat.lookup(stripped)
    except UnknownStar as exc:
        raise UnknownTarget(f"{exc}; planets: {', '.join(BODY_SEGMENTS)}; or give RA/Dec "
                            f"such as {RADEC_FORMS}") from None
    return IcrsStar.from_catalog(star)
