"""Spread positions evenly over the visible sky: synthetic targets and star choice."""

from __future__ import annotations

import numpy as np

_GOLDEN_ANGLE_RAD = np.pi * (3.0 - np.sqrt(5.0))


def even_sky_positions(n: int, *, min_el_deg: float = 20.0, max_el_deg: float = 85.0,
                       rotation_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Return n (az_deg, el_deg) spread evenly by area between two elevations.

    A Fibonacci lattice on the spherical zone: equal steps in sin(el) give equal areas,
    the golden angle between successive azimuths avoids alignments. `rotation_deg` turns
    the whole pattern in azimuth.
    """
    if n < 1:
        raise ValueError(f"need at least one position, got {n}")
    if not -90.0 <= min_el_deg < max_el_deg <= 90.0:
        raise ValueError(f"need -90 <= min_el_deg < max_el_deg <= 90, got {min_el_deg}, {max_el_deg}")
    lo, hi = np.sin(np.radians(min_el_deg)), np.sin(np.radians(max_el_deg))
    k = np.arange(n)
    el = np.degrees(np.arcsin(lo + (k + 0.5) / n * (hi - lo)))
    az = np.mod(np.degrees(k * _GOLDEN_ANGLE_RAD) + rotation_deg, 360.0)
    return az, el


def pick_spread(cand_az_deg: np.ndarray, cand_el_deg: np.ndarray, n: int, *,
                min_el_deg: float = 20.0, max_el_deg: float = 85.0) -> np.ndarray:
    """Return indices of n candidates (az/el in degrees) spread evenly over the visible sky.

    Each of n evenly spread target positions takes the nearest unused candidate above
    `min_el_deg` and below `max_el_deg`; raises ValueError if there are fewer than n.
    """
    az = np.radians(np.asarray(cand_az_deg, dtype=float))
    el = np.radians(np.asarray(cand_el_deg, dtype=float))
    ok = np.flatnonzero((el >= np.radians(min_el_deg)) & (el <= np.radians(max_el_deg)))
    if ok.size < n:
        raise ValueError(f"only {ok.size} candidates lie between {min_el_deg}° and "
                         f"{max_el_deg}° elevation; {n} were asked for")
    t_az, t_el = np.radians(even_sky_positions(n, min_el_deg=min_el_deg, max_el_deg=max_el_deg))
    cand = _unit(az[ok], el[ok])
    targets = _unit(t_az, t_el)
    cos_dist = targets @ cand.T
    chosen: list[int] = []
    free = np.ones(ok.size, dtype=bool)
    for row in cos_dist:
        j = int(np.argmax(np.where(free, row, -np.inf)))
        free[j] = False
        chosen.append(int(ok[j]))
    return np.array(chosen, dtype=int)


def _unit(az: np.ndarray, el: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
