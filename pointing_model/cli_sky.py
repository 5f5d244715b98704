"""Sky positions for the CLI (`plan`, CSV rows given as RA/Dec), via virtualstar.astro.

This is the one module of `pointing_model` that imports our astronomy and catalogs; the
core (terms, fit, formats) never does. Imports happen on first use so `fit` on a TPOINT
file does not load ERFA tables.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .sky_sampling import pick_spread


@dataclass(frozen=True)
class PlannedStar:
    """A catalogue star chosen for a pointing run, with its observed place at `utc`."""

    name: str
    hip: int | None
    vmag: float | None
    ra_deg: float
    dec_deg: float
    utc: str
    az_deg: float
    el_deg: float


def make_site(site_option: str | None, site_file: str | None) -> Any:
    """Return a virtualstar.astro Site: the site file (or default), then LAT,LON,HEIGHT_M."""
    from virtualstar.astro import load_site, parse_site_option

    site = load_site(site_file)
    if site_option:
        lat, lon, height = parse_site_option(site_option)
        site = site.with_overrides(lat_deg=lat, lon_deg=lon, height_m=height)
    return site


def radec_to_observed_altaz(utcs: Sequence[str], ra_deg: np.ndarray, dec_deg: np.ndarray,
                            site: Any) -> tuple[np.ndarray, np.ndarray]:
    """Return observed (refracted per the site) az/el in degrees of ICRS RA/Dec at UTCs."""
    from virtualstar.astro import IcrsStar, UtcTimes

    az, el = np.empty(len(utcs)), np.empty(len(utcs))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # predicted-EOP notices, once per row otherwise
        for i, utc in enumerate(utcs):
            obs = IcrsStar(float(ra_deg[i]), float(dec_deg[i])).observe(
                UtcTimes.from_iso([utc]), site)
            az[i], el[i] = np.degrees(obs.az_rad[0]), np.degrees(obs.el_rad[0])
    return az, el


def plan_stars(n_stars: int, site: Any, *, at_utc: str | None = None,
               min_el_deg: float = 20.0, max_el_deg: float = 85.0,
               max_vmag: float | None = None, exclude=None) -> list[PlannedStar]:
    """Pick `n_stars` bundled bright stars spread evenly over the sky visible at `at_utc`.

    `at_utc` is ISO 8601 (default: now). `exclude(az_deg, el_deg, times)`, if given,
    returns a mask of places not to use (behind the horizon profile, near the Sun).
    Raises ValueError if too few stars qualify.
    """
    from catalogs import bright_stars
    from virtualstar.astro import IcrsStar, UtcTimes

    times = UtcTimes.from_iso([at_utc]) if at_utc else UtcTimes.now()
    utc = times.iso(0)[0]
    stars = [s for s in bright_stars()
             if (max_vmag is None or (s.vmag is not None and s.vmag <= max_vmag))
             and _can_rise_above(s.dec_deg, site.lat_deg, min_el_deg)]
    az, el = np.empty(len(stars)), np.empty(len(stars))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # predicted-EOP notices, once per star otherwise
        for i, star in enumerate(stars):
            obs = IcrsStar.from_catalog(star).observe(times, site)
            az[i], el[i] = np.degrees(obs.az_rad[0]), np.degrees(obs.el_rad[0])
    if exclude is not None and len(stars):
        keep = ~np.asarray(exclude(az, el, times), bool)
        stars, az, el = [s for s, k in zip(stars, keep, strict=True) if k], az[keep], el[keep]
    chosen = pick_spread(az, el, n_stars, min_el_deg=min_el_deg, max_el_deg=max_el_deg)
    return [PlannedStar(stars[i].label, stars[i].hip, stars[i].vmag, stars[i].ra_deg,
                        stars[i].dec_deg, utc, float(az[i]), float(el[i])) for i in chosen]


def _can_rise_above(dec_deg: float, lat_deg: float, min_el_deg: float) -> bool:
    # Highest elevation reached at transit is 90° − |lat − dec|.
    return 90.0 - abs(lat_deg - dec_deg) >= min_el_deg - 1.0  # 1° margin: refraction
