"""Windows that never mix classes, cut chunk by chunk as segments arrive.

A window is at most `per` consecutive segments of one class (anomalies.phases): a new
window begins at a class change, at a forced break (a recording gap, the join of two
reference stretches) and every `per` segments within a run. The cut depends only on the
sequence, so a night cut in one piece or minute by minute gives the same windows:
`WindowCutter` hands back the closed windows of what it was given and keeps the open
one for the next chunk.
"""

from __future__ import annotations

import numpy as np

__all__ = ["WindowCutter", "class_window_starts", "window_mean", "window_median"]


def class_window_starts(cls: np.ndarray, per: int, breaks: np.ndarray | None = None
                        ) -> np.ndarray:
    """Return the first segment index of each window (see the module docstring)."""
    n = len(cls)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    new_run = np.r_[True, cls[1:] != cls[:-1]]
    if breaks is not None:
        new_run |= breaks
    run_id = np.cumsum(new_run) - 1
    run_start = np.flatnonzero(new_run)
    pos = np.arange(n) - run_start[run_id]
    return np.flatnonzero(pos % max(1, per) == 0).astype(np.int64)


def window_mean(x: np.ndarray, starts: np.ndarray, use: np.ndarray, *, need: int = 1
                ) -> np.ndarray:
    """Mean of the rows `use` of `x` in each window (NaN with fewer than `need` of them)."""
    x = np.asarray(x, dtype=np.float64)
    if len(starts) == 0:
        return np.zeros((0,) + x.shape[1:])
    mask = use[:, None] if x.ndim == 2 else use
    sums = np.add.reduceat(np.where(mask, x, 0.0), starts, axis=0)
    counts = np.add.reduceat(use.astype(np.float64), starts)
    counts = np.where(counts >= max(1, need), counts, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / (counts[:, None] if x.ndim == 2 else counts)


def window_median(x: np.ndarray, starts: np.ndarray, use: np.ndarray, *, need: int = 1
                  ) -> np.ndarray:
    """Median of the rows `use` of `x` (segments × k) in each window of any length."""
    n, k = x.shape
    if len(starts) == 0:
        return np.zeros((0, k))
    lengths = np.diff(np.r_[starts, n])
    width = int(lengths.max())
    idx = starts[:, None] + np.arange(width)[None, :]
    inside = np.arange(width)[None, :] < lengths[:, None]
    idx = np.where(inside, idx, 0)
    cube = np.where((inside & use[idx])[:, :, None], x[idx], np.nan)
    counts = np.sum(inside & use[idx], axis=1)
    out = np.full((len(starts), k), np.nan)
    ok = counts >= max(1, need)
    if ok.any():
        out[ok] = np.nanmedian(cube[ok], axis=1)
    return out


class WindowCutter:
    """Cut chunks of per-segment arrays into class windows, keeping the open window.

    `push(arrays, cls, breaks)` returns (arrays, starts, closed): the pending segments
    followed by the new ones, the window starts over them, and how many windows are
    closed (all of them when `final`). The segments of the windows not closed stay
    pending.
    """

    def __init__(self, per: int) -> None:
        self.per = max(1, int(per))
        self._pending: dict[str, np.ndarray] | None = None

    @property
    def pending(self) -> int:
        """Segments of the open window, waiting for the next chunk."""
        return 0 if self._pending is None else len(self._pending["cls"])

    def push(self, arrays: dict[str, np.ndarray] | None, *, final: bool = False
             ) -> tuple[dict[str, np.ndarray], np.ndarray, int]:
        """`arrays` None: nothing new (with `final`, close what is pending)."""
        if arrays is None:
            arrays, self._pending = (self._pending or {"cls": np.zeros(0, np.int64)}), None
        elif self._pending is not None:
            arrays = {k: np.concatenate([self._pending[k], v]) for k, v in arrays.items()}
        n = len(arrays["cls"])
        starts = class_window_starts(arrays["cls"], self.per, arrays.get("breaks"))
        if final or len(starts) == 0:
            self._pending = None
            return arrays, starts, len(starts)
        last = int(starts[-1])
        full = n - last >= self.per
        closed = len(starts) if full else len(starts) - 1
        keep_from = n if full else last
        self._pending = {k: v[keep_from:] for k, v in arrays.items()} if keep_from < n else None
        return arrays, starts, closed
