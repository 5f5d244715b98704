"""Give the emulated mount a true, hidden geometry and a guide camera that sees it.

The seven TPOINT alt-azimuth terms, in arcseconds, with TPOINT's sign
conventions: azimuth A from north through east, elevation E; the residual
observed − raw (encoder) at observed position (A, E) is ``A − A_enc = ΔA``,
``E − E_enc = ΔE`` (so ``A_enc = A − ΔA`` puts the star on the optical axis), with

    ΔA = −IA − CA·secE − NPAE·tanE − AN·sinA·tanE − AW·cosA·tanE
    ΔE = +IE − AN·cosA + AW·sinA − TF·cosE

(first-order, as in TPOINT's term list: IA azimuth index, IE elevation index,
AN/AW azimuth-axis tilt toward north (A = 0) / west (A = 270°), NPAE az/el
non-perpendicularity, CA collimation, TF tube flexure). IA > 0 means the
azimuth encoder reads IA more than the true azimuth, as in TPOINT. The emulator
implements them here on purpose and never imports the project's fitter.

The guide camera inverts the model: from the encoder readings it finds where
the optical axis points on the sky, and reports the commanded star's offset
from it, ``(ΔA·cosE, ΔE)`` in arcseconds, plus Gaussian seeing noise.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from mount_emulator.exceptions import ConfigError

__all__ = ["DEFAULT_SEEING_ARCSEC", "Geometry", "GuideCamera"]

ARCSEC = math.pi / 180.0 / 3600.0
DEFAULT_SEEING_ARCSEC = 0.3  # 1-σ per axis of a guide-camera centroid
MIN_RAW_RMS_ARCSEC = 100.0  # a seeded geometry is scaled up to at least this raw error
_SEED_SIGMA_ARCSEC = {"ia": 150.0, "ie": 80.0, "an": 40.0, "aw": 40.0, "npae": 25.0, "ca": 60.0,
                      "tf": 20.0}


@dataclass(frozen=True)
class Geometry:
    """True geometric errors of the mount, arcseconds (TPOINT names, lower case)."""

    ia: float = 0.0
    ie: float = 0.0
    an: float = 0.0
    aw: float = 0.0
    npae: float = 0.0
    ca: float = 0.0
    tf: float = 0.0

    @classmethod
    def from_seed(cls, seed: int) -> Geometry:
        """Draw a geometry at random; its raw pointing error is at least 100″ RMS over the sky."""
        rng = np.random.default_rng(seed)
        geom = cls(**{k: float(rng.normal(0.0, s)) for k, s in _SEED_SIGMA_ARCSEC.items()})
        rms = geom.raw_rms_arcsec()
        if rms < MIN_RAW_RMS_ARCSEC:
            scale = MIN_RAW_RMS_ARCSEC / rms * 1.05
            geom = cls(**{k: v * scale for k, v in asdict(geom).items()})
        return geom

    @classmethod
    def from_file(cls, path: str | Path) -> Geometry:
        """Load a geometry from TOML (a ``[geometry]`` table or top level) or JSON, arcsec.

        Raises ConfigError naming the file and the accepted keys.
        """
        path = Path(path)
        try:
            text = path.read_bytes()
            data = json.loads(text) if path.suffix.lower() == ".json" else tomllib.loads(text.decode())
        except FileNotFoundError:
            raise ConfigError(f"geometry file {path} does not exist") from None
        except (ValueError, UnicodeDecodeError) as exc:
            raise ConfigError(f"geometry file {path} is not valid "
                              f"{'JSON' if path.suffix.lower() == '.json' else 'TOML'}: {exc}") from None
        return cls.from_mapping(data.get("geometry", data), where=str(path))

    @classmethod
    def from_mapping(cls, data: dict, where: str = "geometry") -> Geometry:
        """Build from {term: arcsec}; keys are case-insensitive TPOINT names, optionally ``_arcsec``."""
        names = [f.name for f in fields(cls)]
        values = {}
        for key, value in data.items():
            term = key.lower().removesuffix("_arcsec")
            if term not in names:
                raise ConfigError(f"{where}: unknown geometry term {key!r}; expected some of "
                                  f"{', '.join(n.upper() for n in names)} (arcsec)")
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ConfigError(f"{where}: {key} must be a finite number of arcseconds, got {value!r}")
            values[term] = float(value)
        return cls(**values)

    def corrections(self, az_rad, el_rad):
        """Return (ΔA, ΔE) in radians at observed (A, E): observed − encoder = Δ (TPOINT)."""
        az = np.asarray(az_rad, dtype=float)
        el = np.asarray(el_rad, dtype=float)
        sa, ca_ = np.sin(az), np.cos(az)
        tan_e, cos_e = np.tan(el), np.cos(el)
        d_az = (-self.ia - self.ca / cos_e - self.npae * tan_e
                - self.an * sa * tan_e - self.aw * ca_ * tan_e)
        d_el = self.ie - self.an * ca_ + self.aw * sa - self.tf * cos_e
        return d_az * ARCSEC, d_el * ARCSEC

    def encoder_of_sky(self, az_rad, el_rad):
        """Return the encoder (raw) position that puts observed (A, E) on the optical axis."""
        d_az, d_el = self.corrections(az_rad, el_rad)
        return np.asarray(az_rad) - d_az, np.asarray(el_rad) - d_el

    def sky_of_encoder(self, enc_az_rad, enc_el_rad):
        """Return where the optical axis points (observed A, E) for given encoder readings."""
        az = np.asarray(enc_az_rad, dtype=float)
        el = np.asarray(enc_el_rad, dtype=float)
        sky_az, sky_el = az, el
        for _ in range(4):  # fixed point: Δ varies slowly, converges to < 1e-9″
            d_az, d_el = self.corrections(sky_az, sky_el)
            sky_az, sky_el = az + d_az, el + d_el
        return sky_az, sky_el

    def raw_rms_arcsec(self) -> float:
        """Return the RMS on-sky pointing error without a model, over 5°–85° elevation."""
        az, el = np.meshgrid(np.radians(np.arange(0, 360, 10.0)), np.radians(np.arange(5, 86, 5.0)))
        d_az, d_el = self.corrections(az, el)
        return float(np.sqrt(np.mean((d_az * np.cos(el)) ** 2 + d_el**2)) / ARCSEC)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


class GuideCamera:
    """Report where a star appears relative to the optical axis, arcseconds."""

    def __init__(self, geometry: Geometry, *, seeing_arcsec: float = DEFAULT_SEEING_ARCSEC,
                 seed: int | None = None) -> None:
        self.geometry = geometry
        self.seeing_arcsec = seeing_arcsec
        self._rng = np.random.default_rng(seed)

    def offset_arcsec(self, enc_az_rad: float, enc_el_rad: float, star_az_rad: float,
                      star_el_rad: float) -> tuple[float, float]:
        """Return (left-right ΔA·cosE, up-down ΔE) of the star from the optical axis, arcsec.

        Positive when the star lies at larger azimuth / higher elevation than the axis.
        """
        axis_az, axis_el = self.geometry.sky_of_encoder(enc_az_rad, enc_el_rad)
        d_az = math.remainder(float(star_az_rad - axis_az), 2 * math.pi)
        dx = d_az * math.cos(star_el_rad) / ARCSEC
        dy = float(star_el_rad - axis_el) / ARCSEC
        if self.seeing_arcsec > 0:
            dx += float(self._rng.normal(0.0, self.seeing_arcsec))
            dy += float(self._rng.normal(0.0, self.seeing_arcsec))
        return dx, dy
