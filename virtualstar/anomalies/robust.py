"""Robust centre and scale of a statistic over the reference."""

from __future__ import annotations

import numpy as np

__all__ = ["MAD_TO_SIGMA", "robust_center_scale"]

MAD_TO_SIGMA = 1.4826  # median absolute deviation → standard deviation of a normal law


def robust_center_scale(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the median and the MAD-based sigma of the finite rows of `x` (1-D or
    rows × k), NaN when there are none."""
    x = np.asarray(x, dtype=np.float64)
    rows = np.all(np.isfinite(x), axis=tuple(range(1, x.ndim))) if x.ndim > 1 \
        else np.isfinite(x)
    r = x[rows]
    if len(r) == 0:
        shape = x.shape[1:]
        return np.full(shape, np.nan), np.full(shape, np.nan)
    med = np.median(r, axis=0)
    return med, MAD_TO_SIGMA * np.median(np.abs(r - med), axis=0)
