"""Observing site: geodetic position and the weather that drives refraction.

A Site is a frozen dataclass; load it from TOML with `load_site`, override
fields from the command line with `Site.with_overrides` / `parse_site_option`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import erfa
import numpy as np

from .constants import WGS84
from .exceptions import SiteError

#: Environment variable naming a site TOML file that replaces the packaged default.
SITE_ENV_VAR = "VIRTUALSTAR_SITE"


@dataclass(frozen=True)
class Site:
    """Where the telescope stands and the air it looks through.

    lat_deg: geodetic latitude (WGS84), lon_deg: longitude east, height_m:
    ellipsoidal height. pressure_hpa = 0 means "no refraction" (the ERFA
    convention). humidity is relative, 0..1; wavelength_um > 100 means radio.
    """

    lat_deg: float
    lon_deg: float
    height_m: float = 0.0
    pressure_hpa: float = 1013.25
    temperature_c: float = 10.0
    humidity: float = 0.5
    wavelength_um: float = 0.55
    name: str = "site"

    def __post_init__(self) -> None:
        checks = [
            ("lat_deg", -90.0 <= self.lat_deg <= 90.0, "between -90 and 90"),
            ("lon_deg", -360.0 <= self.lon_deg <= 360.0, "between -360 and 360 (east positive)"),
            ("height_m", -500.0 <= self.height_m <= 10_000.0, "between -500 and 10000"),
            ("pressure_hpa", 0.0 <= self.pressure_hpa <= 1200.0, "between 0 (no refraction) and 1200"),
            ("temperature_c", -90.0 <= self.temperature_c <= 60.0, "between -90 and 60"),
            ("humidity", 0.0 <= self.humidity <= 1.0, "a fraction between 0 and 1"),
            ("wavelength_um", self.wavelength_um > 0.0, "positive"),
        ]
        for field, ok, expected in checks:
            value = getattr(self, field)
            if not (isinstance(value, int | float) and math.isfinite(value) and ok):
                raise SiteError(f"site {field}={value!r} is invalid: expected {expected}")

    @property
    def lat_rad(self) -> float:
        return math.radians(self.lat_deg)

    @property
    def lon_rad(self) -> float:
        return math.radians(self.lon_deg)

    @property
    def refraction(self) -> bool:
        """True when the site's pressure switches refraction on."""
        return self.pressure_hpa > 0.0

    def without_refraction(self) -> Site:
        """Return the same site with refraction switched off (pressure 0)."""
        return dataclasses.replace(self, pressure_hpa=0.0)

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Site:
        """A Site from its fields as `dataclasses.asdict` writes them (other keys ignored)."""
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in doc.items() if k in known})

    def with_overrides(self, **values: Any) -> Site:
        """Return a copy with the given fields replaced; None values are ignored."""
        return dataclasses.replace(self, **{k: v for k, v in values.items() if v is not None})

    def itrs_position_m(self) -> np.ndarray:
        """Return the site's geocentric ITRS position (WGS84) in metres, shape (3,)."""
        return np.asarray(erfa.gd2gc(WGS84, self.lon_rad, self.lat_rad, self.height_m))

    def enu_matrix(self) -> np.ndarray:
        """Return the 3x3 rotation from ITRS axes to local (north, east, up) axes."""
        sl, cl = math.sin(self.lat_rad), math.cos(self.lat_rad)
        so, co = math.sin(self.lon_rad), math.cos(self.lon_rad)
        return np.array(
            [[-sl * co, -sl * so, cl], [-so, co, 0.0], [cl * co, cl * so, sl]]
        )


def parse_site_option(text: str) -> tuple[float, float, float]:
    """Parse "LAT,LON,HEIGHT_M" (degrees, degrees east, metres).

    Raises SiteError showing the expected layout.
    """
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (2, 3):
        raise SiteError(
            f"--site {text!r}: expected LAT,LON,HEIGHT_M, e.g. 52.40,16.88,85 "
            "(degrees, degrees east, metres)"
        )
    try:
        values = [float(p) for p in parts] + ([0.0] if len(parts) == 2 else [])
    except ValueError:
        raise SiteError(
            f"--site {text!r}: every part must be a number; expected LAT,LON,HEIGHT_M "
            "e.g. 52.40,16.88,85"
        ) from None
    return values[0], values[1], values[2]


def _parse_toml(text: str, origin: str) -> dict:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SiteError(f"{origin}: not valid TOML: {exc}") from None


def read_site_file(path: str | os.PathLike[str]) -> dict:
    """Return the parsed TOML of a site file (its [site] and [safety] tables, ...);
    SiteError naming the file when it cannot be read or is not TOML."""
    try:
        text = Path(path).read_text("utf-8")
    except OSError as exc:
        raise SiteError(f"cannot read site file {str(path)!r}: {exc.strerror}") from None
    return _parse_toml(text, str(path))


def _site_from_toml(data: dict, origin: str) -> Site:
    table = data.get("site")
    if not isinstance(table, dict):
        raise SiteError(f"{origin}: expected a [site] table with lat_deg, lon_deg, height_m, ...")
    known = {f.name for f in dataclasses.fields(Site)}
    unknown = sorted(set(table) - known)
    if unknown:
        raise SiteError(f"{origin}: unknown keys {unknown}; valid keys: {sorted(known)}")
    missing = [k for k in ("lat_deg", "lon_deg") if k not in table]
    if missing:
        raise SiteError(f"{origin}: [site] misses {missing}")
    try:
        return Site(**table)
    except SiteError as exc:
        raise SiteError(f"{origin}: {exc}") from None
    except TypeError as exc:
        raise SiteError(f"{origin}: {exc}") from None


def load_site(path: str | os.PathLike[str] | None = None) -> Site:
    """Load a Site from a TOML file with a [site] table.

    Without a path, the file named by $VIRTUALSTAR_SITE is used, else the
    documented default packaged as virtualstar/data/site.toml. Raises SiteError.
    """
    if path is None:
        path = os.environ.get(SITE_ENV_VAR) or None
    if path is None:
        text = resources.files("virtualstar").joinpath("data/site.toml").read_text("utf-8")
        return _site_from_toml(_parse_toml(text, "default site.toml"), "default site.toml")
    return _site_from_toml(read_site_file(path), str(path))


def site_from_options(*, site_file: str | os.PathLike[str] | None = None,
                      site_text: str | None = None, pressure_hpa: float | None = None,
                      temperature_c: float | None = None, humidity: float | None = None,
                      no_refraction: bool = False) -> Site:
    """Return the configured site with command-line overrides applied (None = keep).

    site_text is "LAT,LON,HEIGHT_M"; no_refraction sets the pressure to 0.
    Raises SiteError.
    """
    site = load_site(site_file)
    if site_text is not None:
        lat, lon, height = parse_site_option(site_text)
        site = site.with_overrides(lat_deg=lat, lon_deg=lon, height_m=height,
                                   name=f"{lat:g},{lon:g},{height:g}")
    site = site.with_overrides(pressure_hpa=pressure_hpa, temperature_c=temperature_c,
                               humidity=humidity)
    return site.without_refraction() if no_refraction else site
