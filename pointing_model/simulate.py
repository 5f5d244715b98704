"""Synthetic pointing runs: a known model plus Gaussian measurement noise."""

from __future__ import annotations

import numpy as np

from .constants import ARCSEC_PER_RAD
from .model import PointingModel
from .runs import PointingRun, RunParameters
from .sky_sampling import even_sky_positions


def simulate_run(model: PointingModel, n_stars: int, noise_arcsec: float, *,
                 rng: np.random.Generator, min_el_deg: float = 20.0, max_el_deg: float = 85.0,
                 latitude_deg: float = 0.0, caption: str = "Simulated pointing run",
                 ) -> PointingRun:
    """Return a run whose encoder readings follow `model` with noise, stars spread evenly.

    Positions: an even lattice between the elevation limits, turned by a random azimuth.
    Noise: independent Gaussian of standard deviation `noise_arcsec` on each sky axis
    (elevation, and azimuth × cos E), so pure noise has a sky RMS of √2 × noise_arcsec.
    """
    if noise_arcsec < 0:
        raise ValueError(f"noise must be zero or positive, got {noise_arcsec}")
    az, el = even_sky_positions(n_stars, min_el_deg=min_el_deg, max_el_deg=max_el_deg,
                                rotation_deg=float(rng.uniform(0.0, 360.0)))
    enc_az, enc_el = model.observed_to_encoder(az, el)
    noise_rad = noise_arcsec / ARCSEC_PER_RAD
    enc_el = enc_el + np.degrees(rng.normal(0.0, noise_rad, n_stars))
    enc_az = enc_az + np.degrees(rng.normal(0.0, noise_rad, n_stars) / np.cos(np.radians(el)))
    terms = " ".join(f"{t}={v:g}" for t, v in model.as_dict().items())
    comments = tuple(f"sim {i + 1:04d}" for i in range(n_stars))
    return PointingRun(az, el, np.mod(enc_az, 360.0), enc_el, RunParameters(latitude_deg),
                       f"{caption}: {terms}; noise {noise_arcsec:g} arcsec",
                       ("ALTAZ",), comments=comments)
