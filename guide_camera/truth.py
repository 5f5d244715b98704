"""Where the target truly is: observed az/el from skyfield, with the site's air.

The camera simulator's truth, independent of the VSS: skyfield's apparent
topocentric place (light time, aberration, nutation; UT1 and polar motion from
skyfield-data's IERS table, DE421 from skyfield-data, offline) of a star (catalogue place with
proper motion and parallax) or of a satellite (its own *truth* TLE through SGP4),
lifted by refraction with ERFA's constants for the site's air (refco: pressure,
temperature, humidity, wavelength), A·tan z + B·tan³ z. Places are computed on a
grid (0.2 s for a satellite, 2 s for a star) a chunk at a time and interpolated
with cubic splines: the error is below a milliarcsecond (tests/guide_camera; measured
0.07 mas for the ISS over ±300 s of its 80° pass, horizon included: a 0.1-s grid was no
better, 0.67 mas, its nodes' own rounding amplified, and cost twice the skyfield calls).
"""

from __future__ import annotations

import functools
import math
import tomllib
import warnings
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import erfa
import numpy as np
from scipy.interpolate import CubicSpline

from .exceptions import CameraConfigError

__all__ = ["CameraSite", "SatelliteTruth", "StarTruth"]

SAT_STEP_US = 200_000
STAR_STEP_US = 2_000_000
CHUNK_POINTS = 400  # grid points per chunk (80 s of a satellite, 13 min of a star)
EDGE_POINTS = 4  # chunks overlap by this many points so the splines agree at the seams


@dataclass(frozen=True)
class CameraSite:
    """Where the camera is and its air (the same fields as the VSS's site file)."""

    lat_deg: float
    lon_deg: float
    height_m: float = 0.0
    pressure_hpa: float = 0.0
    temperature_c: float = 10.0
    humidity: float = 0.5
    wavelength_um: float = 0.55

    def __post_init__(self) -> None:
        checks = (("lat_deg", -90, 90), ("lon_deg", -180, 360), ("height_m", -500, 10_000),
                  ("pressure_hpa", 0, 1200), ("temperature_c", -80, 60), ("humidity", 0, 1),
                  ("wavelength_um", 0.1, 30))
        for name, lo, hi in checks:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise CameraConfigError(f"site {name}={v!r}: expected a number in {lo}..{hi}")

    @classmethod
    def from_toml(cls, path: str | Path) -> CameraSite:
        """Read a site file (virtualstar/data/site.toml's layout: a [site] table or top level)."""
        try:
            doc = tomllib.loads(Path(path).read_text("utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise CameraConfigError(f"cannot read site file {path}: {exc}") from None
        doc = {k: v for k, v in doc.get("site", doc).items()
               if k != "name" and not isinstance(v, dict)}
        fields = cls.__dataclass_fields__
        unknown = sorted(set(doc) - set(fields))
        if unknown:
            raise CameraConfigError(f"{path}: unknown site keys {unknown}; expected "
                                    f"{', '.join(fields)}")
        try:
            return cls(**doc)
        except TypeError as exc:
            raise CameraConfigError(f"{path}: {exc}") from None

    @classmethod
    def from_object(cls, site: Any) -> CameraSite:
        """Copy the fields of any object that has them (the VSS's `Site`)."""
        return cls(**{k: float(getattr(site, k)) for k in cls.__dataclass_fields__})


@functools.lru_cache(maxsize=1)
def _skyfield():
    """skyfield's timescale with UT1 *and polar motion* from skyfield-data's IERS file."""
    from skyfield.api import Loader
    from skyfield.data import iers
    from skyfield_data import get_skyfield_data_path

    loader = Loader(get_skyfield_data_path(), verbose=False)
    with warnings.catch_warnings():
        # skyfield-data says its finals2000A.all "expired": it still holds the measured past
        warnings.simplefilter("ignore")
        ts = loader.timescale(builtin=False)
        with loader.open("finals2000A.all") as f:
            iers.install_polar_motion_table(ts, iers.parse_x_y_dut1_from_finals_all(f))
        eph = loader("de421.bsp")
    return ts, eph


class _GriddedTruth:
    """Observed places computed on a grid chunk by chunk and splined (subclasses: `_apparent`)."""

    step_us = SAT_STEP_US

    def __init__(self, site: CameraSite) -> None:
        self.site = site
        self._chunks: dict[int, tuple[int, CubicSpline, CubicSpline]] = {}
        self._refa, self._refb = erfa.refco(site.pressure_hpa, site.temperature_c, site.humidity,
                                            site.wavelength_um)

    def place(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Observed (refracted) azimuth and elevation, radians, at true UTC µs."""
        t = np.atleast_1d(np.asarray(t_us, np.int64))
        az = np.empty(t.shape)
        el = np.empty(t.shape)
        span = self.step_us * CHUNK_POINTS
        keys = t // span
        for key in np.unique(keys):
            sel = keys == key
            t0, s_az, s_el = self._chunk(int(key))
            x = (t[sel] - t0) * 1e-6
            az[sel] = np.mod(s_az(x), 2 * math.pi)
            el[sel] = s_el(x)
        return az, el

    def exact(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Observed (refracted) azimuth and elevation, radians, computed at exactly these
        true UTC µs (no grid): for a few instants, where a whole chunk would be wasted."""
        t = np.atleast_1d(np.asarray(t_us, np.int64))
        az, el = self._observed(t)
        return np.mod(az, 2 * math.pi), el

    def _chunk(self, key: int):
        if key not in self._chunks:
            if len(self._chunks) > 64:
                self._chunks.pop(next(iter(self._chunks)))
            span = self.step_us * CHUNK_POINTS
            t0 = key * span - EDGE_POINTS * self.step_us
            grid = t0 + np.arange(CHUNK_POINTS + 2 * EDGE_POINTS + 1, dtype=np.int64) * self.step_us
            az, el = self._observed(grid)
            x = (grid - t0) * 1e-6
            self._chunks[key] = (t0, CubicSpline(x, np.unwrap(az)), CubicSpline(x, el))
        return self._chunks[key]

    def _observed(self, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ts, eph = _skyfield()
        from skyfield.api import wgs84

        earth = eph["earth"]
        here = earth + wgs84.latlon(self.site.lat_deg, self.site.lon_deg, self.site.height_m)
        times = ts.from_datetimes([datetime.fromtimestamp(int(x) // 1_000_000, UTC).replace(
            microsecond=int(x) % 1_000_000) for x in t_us])
        alt, az, _ = self._apparent(here.at(times), earth).altaz()
        el = alt.radians
        tan_z = np.tan(np.pi / 2 - np.maximum(el, math.radians(-1.0)))
        return az.radians, el + self._refa * tan_z + self._refb * tan_z**3

    def _apparent(self, observer_at, earth):  # pragma: no cover - subclasses
        raise NotImplementedError


class SatelliteTruth(_GriddedTruth):
    """A satellite's true place from its truth TLE (lines 1 and 2), or its elements."""

    step_us = SAT_STEP_US

    def __init__(self, line1: str, line2: str, site: CameraSite, name: str = "truth") -> None:
        line1, line2 = _checked_tle(line1, line2)
        from sgp4.api import Satrec

        self._setup(Satrec.twoline2rv(line1, line2), site, name)
        self.line1, self.line2 = line1, line2

    @classmethod
    def from_satrec(cls, satrec, site: CameraSite, name: str = "truth") -> SatelliteTruth:
        """From an sgp4 `Satrec` (full-precision elements: `tle_shift.shifted_elements`)."""
        err, _, _ = satrec.sgp4(satrec.jdsatepoch, satrec.jdsatepochF)
        if err:
            raise CameraConfigError(f"SGP4 cannot propagate the truth elements (error {err})")
        self = cls.__new__(cls)
        self._setup(satrec, site, name)
        from sgp4.exporter import export_tle

        self.line1, self.line2 = export_tle(satrec)  # for display: angles to 1e-4°
        return self

    @classmethod
    def of(cls, elements, site: CameraSite) -> SatelliteTruth:
        """From (line1, line2) or a `Satrec`."""
        if isinstance(elements, tuple):
            return cls(*elements, site)
        return cls.from_satrec(elements, site)

    def _setup(self, satrec, site: CameraSite, name: str) -> None:
        from skyfield.api import EarthSatellite

        _GriddedTruth.__init__(self, site)
        self.satrec = satrec
        self.name = name
        self.satellite = EarthSatellite.from_satrec(satrec, _skyfield()[0])

    def _apparent(self, observer_at, earth):
        return observer_at.observe(earth + self.satellite).apparent()


def _checked_tle(line1: str, line2: str) -> tuple[str, str]:
    """Refuse anything but two element lines SGP4 can propagate (CameraConfigError)."""
    from sgp4.api import Satrec

    if not (isinstance(line1, str) and isinstance(line2, str)):
        raise CameraConfigError("the truth TLE must be two lines of text")
    a, b = line1.strip(), line2.strip()
    layout = "expected '1 NNNNNU ...' and '2 NNNNN ...', 69 characters each"
    if len(a) != 69 or len(b) != 69 or not a.startswith("1 ") or not b.startswith("2 "):
        raise CameraConfigError(f"the truth TLE is not two element lines: {layout}")
    if a[2:7] != b[2:7]:
        raise CameraConfigError("the truth TLE's lines are of two different satellites")
    try:
        sat = Satrec.twoline2rv(a, b)
        err, _, _ = sat.sgp4(sat.jdsatepoch, sat.jdsatepochF)
    except (ValueError, IndexError) as exc:
        raise CameraConfigError(f"the truth TLE cannot be read: {exc}; {layout}") from None
    if err:
        raise CameraConfigError(f"SGP4 cannot propagate the truth TLE (error {err})")
    return a, b


class StarTruth(_GriddedTruth):
    """A star's true place from its catalogue place (ICRS, epoch `epoch_jyear`)."""

    step_us = STAR_STEP_US

    def __init__(self, ra_deg: float, dec_deg: float, site: CameraSite, *,
                 pm_ra_cosdec_mas_yr: float = 0.0, pm_dec_mas_yr: float = 0.0,
                 parallax_mas: float = 0.0, rv_km_s: float = 0.0,
                 epoch_jyear: float = 2000.0) -> None:
        from skyfield.api import Star

        super().__init__(site)
        if not (math.isfinite(ra_deg) and -90.0 <= dec_deg <= 90.0):
            raise CameraConfigError(f"star RA/Dec ({ra_deg}, {dec_deg}): expected finite RA and "
                                    "Dec in -90..90 degrees")
        ts = _skyfield()[0]
        self.star = Star(ra_hours=(ra_deg % 360.0) / 15.0, dec_degrees=dec_deg,
                         ra_mas_per_year=pm_ra_cosdec_mas_yr, dec_mas_per_year=pm_dec_mas_yr,
                         parallax_mas=parallax_mas, radial_km_per_s=rv_km_s,
                         epoch=ts.J(epoch_jyear))

    def _apparent(self, observer_at, earth):
        return observer_at.observe(self.star).apparent()
