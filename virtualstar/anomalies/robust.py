"""Windows over segments, robust scores against a reference stretch, runs of flags."""

from __future__ import annotations

import numpy as np

__all__ = ["MAD_TO_SIGMA", "robust_center_scale", "runs", "window_median", "window_reduce",
           "window_starts"]

MAD_TO_SIGMA = 1.4826  # median absolute deviation → standard deviation of a normal law


def window_starts(n: int, per_window: int) -> np.ndarray:
    """Return the first segment index of each window of `per_window` segments (the last
    window may be shorter)."""
    return np.arange(0, n, max(1, per_window), dtype=np.int64)


def window_reduce(x: np.ndarray, starts: np.ndarray, valid: np.ndarray, *,
                  min_count: int = 1) -> np.ndarray:
    """Return the mean of the valid entries of `x` (rows) in each window; NaN in a window
    with fewer than `min_count` of them (a short last window would be a poor estimate)."""
    x = np.asarray(x, dtype=np.float64)
    w = valid.astype(np.float64)
    xv = np.where(valid[:, None] if x.ndim == 2 else valid, x, 0.0)
    sums = np.add.reduceat(xv, starts, axis=0)
    counts = np.add.reduceat(w, starts)
    counts = np.where(counts >= max(1, min_count), counts, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / (counts[:, None] if x.ndim == 2 else counts)


def window_median(x: np.ndarray, starts: np.ndarray, valid: np.ndarray, *,
                  min_count: int = 1) -> np.ndarray:
    """Return the median of the valid rows of `x` (segments × k) in each window."""
    n = len(x)
    per = int(starts[1] - starts[0]) if len(starts) > 1 else n
    padded = np.full((len(starts) * per, x.shape[1]), np.nan)
    padded[:n] = np.where(valid[:, None], x, np.nan)
    cube = padded.reshape(len(starts), per, x.shape[1])
    counts = np.sum(np.isfinite(cube[:, :, 0]), axis=1)
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN window is NaN
            med = np.nanmedian(cube, axis=1)
    med[counts < max(1, min_count)] = np.nan
    return med


def robust_center_scale(x: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the median and the MAD-based sigma of `x` over the reference rows `ref`."""
    r = x[ref]
    r = r[np.all(np.isfinite(r), axis=tuple(range(1, r.ndim)))] if r.ndim > 1 else r[np.isfinite(r)]
    if len(r) == 0:
        shape = x.shape[1:]
        return np.full(shape, np.nan), np.full(shape, np.nan)
    med = np.median(r, axis=0)
    return med, MAD_TO_SIGMA * np.median(np.abs(r - med), axis=0)


def runs(flags: np.ndarray, *, bridge: int = 1) -> list[tuple[int, int]]:
    """Return [first, last] index pairs of runs of True, joining runs `bridge` apart or less."""
    idx = np.flatnonzero(flags)
    if len(idx) == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > bridge + 1)
    firsts = np.r_[idx[0], idx[breaks + 1]]
    lasts = np.r_[idx[breaks], idx[-1]]
    return [(int(a), int(b)) for a, b in zip(firsts, lasts, strict=True)]
