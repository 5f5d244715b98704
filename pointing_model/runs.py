"""A pointing run: observed and encoder positions of a set of stars, with its metadata."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constants import ARCSEC_PER_RAD


@dataclass(frozen=True)
class RunParameters:
    """TPOINT's run-parameters record: site latitude, then optional date and weather."""

    latitude_deg: float
    date: tuple[int, int, int] | None = None  # UTC year, month, day
    temperature_c: float | None = None
    pressure_hpa: float | None = None
    height_m: float | None = None
    humidity: float | None = None  # relative, 0..1
    wavelength_um: float | None = None
    lapse_rate_k_m: float | None = None


@dataclass(frozen=True)
class PointingRun:
    """Observations of one pointing run, positions in degrees.

    `obs_*` is where the star really was (observed, i.e. refracted, place); `enc_*` is
    what the encoders read with the star on axis (TPOINT's "raw" position). Azimuths are
    kept as written in the source. `aux` holds extra numeric columns per record,
    `comments` the text after `;`, `line_numbers` the source line of each record.
    """

    obs_az_deg: np.ndarray
    obs_el_deg: np.ndarray
    enc_az_deg: np.ndarray
    enc_el_deg: np.ndarray
    parameters: RunParameters | None = None
    caption: str = ""
    options: tuple[str, ...] = ("ALTAZ",)
    aux: tuple[tuple[float, ...], ...] = ()
    comments: tuple[str, ...] = ()
    line_numbers: tuple[int, ...] = ()
    source: str = "<run>"
    extra: dict[str, str] = field(default_factory=dict)
    masked_lines: tuple[int, ...] = ()  # source lines of records masked with ';' (not read)

    def __post_init__(self) -> None:
        arrays = [np.asarray(getattr(self, n), dtype=float).ravel()
                  for n in ("obs_az_deg", "obs_el_deg", "enc_az_deg", "enc_el_deg")]
        if len({a.size for a in arrays}) != 1:
            raise ValueError("obs_az_deg, obs_el_deg, enc_az_deg, enc_el_deg must have one length")
        for name, arr in zip(("obs_az_deg", "obs_el_deg", "enc_az_deg", "enc_el_deg"), arrays,
                             strict=True):
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.obs_az_deg.size)

    def residuals_rad(self) -> tuple[np.ndarray, np.ndarray]:
        """Return (ΔA·cos E, ΔE) = observed − encoder in radians.

        ΔA is taken modulo 360° into (−180°, 180°], so encoder azimuths wrapped differently
        from the observed ones (e.g. −170 against 190) give the small difference.
        """
        da_deg = wrap_deg_180(self.obs_az_deg - self.enc_az_deg)
        el = np.radians(self.obs_el_deg)
        return np.radians(da_deg) * np.cos(el), np.radians(self.obs_el_deg - self.enc_el_deg)

    def raw_sky_rms_arcsec(self) -> float:
        """Return the sky RMS of observed − encoder before any model (arcsec)."""
        s, e = self.residuals_rad()
        return float(np.sqrt(np.mean(s**2 + e**2)) * ARCSEC_PER_RAD) if len(self) else 0.0

    def subset(self, mask: np.ndarray) -> PointingRun:
        """Return the run restricted to the records where `mask` is true."""
        idx = np.flatnonzero(mask)

        def pick(seq: tuple) -> tuple:
            return tuple(seq[i] for i in idx) if seq else ()

        return PointingRun(self.obs_az_deg[idx], self.obs_el_deg[idx], self.enc_az_deg[idx],
                           self.enc_el_deg[idx], self.parameters, self.caption, self.options,
                           pick(self.aux), pick(self.comments), pick(self.line_numbers),
                           self.source, dict(self.extra), self.masked_lines)


def wrap_deg_180(angle_deg: np.ndarray) -> np.ndarray:
    """Return angles (degrees) reduced modulo 360 into (−180, 180]."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, dtype=float), 360.0)
