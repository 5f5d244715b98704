"""Tracking-error statistics from the mount's per-tick error stream.

Samples (mount time µs, azimuth and elevation following error in arcsec,
elevation in rad) are reduced on arrival into fixed bins of `bin_us` mount
time holding the count, the sums of squares and the peak of the on-sky error
(azimuth error × cos(elevation) combined with the elevation error) and of each
axis. Any window's RMS and peak are then exact sums over bins, and memory is
bounded by the number of bins kept (a deque), whatever the sample rate.

The following error is what the *encoders* miss. The sky misses more when the
mount clock is off UTC: the mount is then where the target was (or will be)
`offset` earlier, `rate × |offset|` away on the sky. So the history also keeps
the target's on-sky rate per bin (from the points the feeder pushed) and the
clock offsets TimeS measured, and reports the **on-sky error** beside the
encoder error: per bin the clock term is added to the encoder RMS in quadrature
and to its peak linearly (the two may point the same way).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["ErrorStats", "TrackingErrorHistory"]

DEFAULT_BIN_US = 100_000  # 0.1 s of mount time
DEFAULT_MAX_BINS = 36_000  # one hour of mount time at 0.1 s


@dataclass(frozen=True)
class ErrorStats:
    """RMS and peak of the tracking error over a window (arcsec); n samples."""

    n: int
    rms_arcsec: float
    peak_arcsec: float
    az_rms_arcsec: float
    el_rms_arcsec: float
    from_us: int
    to_us: int
    on_sky_rms_arcsec: float = math.nan
    on_sky_peak_arcsec: float = math.nan
    clock_error_peak_arcsec: float = math.nan  # the largest rate × |clock offset| in the window
    clock_offset_us: int | None = None  # the offset of largest size applied in the window

    def as_dict(self) -> dict:
        return {"n": self.n, "rms_arcsec": self.rms_arcsec, "peak_arcsec": self.peak_arcsec,
                "az_rms_arcsec": self.az_rms_arcsec, "el_rms_arcsec": self.el_rms_arcsec,
                "on_sky_rms_arcsec": self.on_sky_rms_arcsec,
                "on_sky_peak_arcsec": self.on_sky_peak_arcsec,
                "clock_error_peak_arcsec": self.clock_error_peak_arcsec,
                "clock_offset_us": self.clock_offset_us,
                "from_us": self.from_us, "to_us": self.to_us}


class TrackingErrorHistory:
    """Bounded history of tracking-error bins; feed it with `add(t_us, az_as, el_as, el_rad)`."""

    def __init__(self, *, bin_us: int = DEFAULT_BIN_US, max_bins: int = DEFAULT_MAX_BINS) -> None:
        self.bin_us = int(bin_us)
        # each bin: [bin index, n, sum sky², sum az², sum el², peak sky]
        self._bins: deque[list[float]] = deque(maxlen=max_bins)
        self._max_bins = max_bins
        self._rates: dict[int, float] = {}  # bin index -> the target's on-sky rate, arcsec/s
        self._offset_t: list[int] = []  # mount times of clock-offset measurements (increasing)
        self._offset_us: list[int] = []
        self.samples = 0
        self.last_t_us = 0
        self.last_sky_arcsec = 0.0

    def clear(self) -> None:
        self._bins.clear()
        self._rates.clear()
        self._offset_t.clear()
        self._offset_us.clear()

    def note_rates(self, t_us: np.ndarray, rate_arcsec_s: np.ndarray) -> None:
        """Record the target's on-sky rate at trajectory points (later points overwrite)."""
        t = np.asarray(t_us, np.int64)
        if t.size == 0:
            return
        idx = t // self.bin_us
        rate = np.asarray(rate_arcsec_s, float)
        starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
        peaks = np.maximum.reduceat(np.abs(rate), starts)
        for b, r in zip(idx[starts].tolist(), peaks.tolist(), strict=True):
            self._rates[b] = r
        while len(self._rates) > self._max_bins:
            del self._rates[next(iter(self._rates))]

    def note_clock_offset(self, t_us: int, offset_us: int) -> None:
        """Record the mount clock's offset from UTC measured at mount time `t_us`."""
        if self._offset_t and t_us < self._offset_t[-1]:
            return
        self._offset_t.append(int(t_us))
        self._offset_us.append(int(offset_us))
        if len(self._offset_t) > self._max_bins:
            del self._offset_t[0], self._offset_us[0]

    def _offset_at(self, t_us: int) -> int:
        """Return the larger of the offsets measured just before and just after `t_us`.

        Between two measurements a drifting clock's offset lies between them, so the
        larger one bounds it (after the newest measurement, that one alone).
        """
        k = bisect.bisect_right(self._offset_t, t_us)
        around = self._offset_us[max(k - 1, 0):k + 1]
        return max(around, key=abs) if around else 0

    def add(self, t_us: np.ndarray, az_err_arcsec: np.ndarray, el_err_arcsec: np.ndarray,
            el_rad: np.ndarray) -> None:
        """Reduce a block of samples into the bins (times increasing)."""
        t = np.asarray(t_us, np.int64)
        if t.size == 0:
            return
        az_sky = np.asarray(az_err_arcsec, float) * np.cos(np.asarray(el_rad, float))
        el = np.asarray(el_err_arcsec, float)
        sky2 = az_sky**2 + el**2
        idx = t // self.bin_us
        starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
        n = np.diff(np.r_[starts, t.size])
        s_sky = np.add.reduceat(sky2, starts)
        s_az = np.add.reduceat(az_sky**2, starts)
        s_el = np.add.reduceat(el**2, starts)
        peak = np.sqrt(np.maximum.reduceat(sky2, starts))
        for k, i0 in enumerate(starts):
            b = int(idx[i0])
            if self._bins and self._bins[-1][0] == b:
                last = self._bins[-1]
                last[1] += n[k]
                last[2] += s_sky[k]
                last[3] += s_az[k]
                last[4] += s_el[k]
                last[5] = max(last[5], peak[k])
            elif not self._bins or self._bins[-1][0] < b:
                self._bins.append([b, float(n[k]), s_sky[k], s_az[k], s_el[k], peak[k]])
        self.samples += int(t.size)
        self.last_t_us = int(t[-1])
        self.last_sky_arcsec = float(math.sqrt(sky2[-1]))

    def _select(self, from_us: int | None, to_us: int | None) -> list[list[float]]:
        """Return the bins whose start lies in [from_us, to_us), oldest first.

        Recent windows (the common case) are found scanning from the newest bin.
        """
        lo = -(2**62) if from_us is None else int(from_us) // self.bin_us
        hi = 2**62 if to_us is None else -(-int(to_us) // self.bin_us)
        sel = []
        for b in reversed(self._bins):
            if b[0] < lo:
                break
            if b[0] < hi:
                sel.append(b)
        sel.reverse()
        return sel

    def stats(self, from_us: int | None = None, to_us: int | None = None) -> ErrorStats:
        """Return RMS and peak over bins whose start lies in [from_us, to_us)."""
        sel = self._select(from_us, to_us)
        n = sum(b[1] for b in sel)
        if n == 0:
            return ErrorStats(0, math.nan, math.nan, math.nan, math.nan,
                              int(from_us or 0), int(to_us or 0))
        sky2 = sum(b[2] for b in sel)
        clock = self._clock_terms(sel)
        return ErrorStats(
            int(n),
            math.sqrt(sky2 / n),
            max(b[5] for b in sel),
            math.sqrt(sum(b[3] for b in sel) / n),
            math.sqrt(sum(b[4] for b in sel) / n),
            int(sel[0][0] * self.bin_us),
            int((sel[-1][0] + 1) * self.bin_us),
            on_sky_rms_arcsec=math.sqrt((sky2 + sum(b[1] * c[0] ** 2 for b, c in
                                                    zip(sel, clock, strict=True))) / n),
            on_sky_peak_arcsec=max(b[5] + c[0] for b, c in zip(sel, clock, strict=True)),
            clock_error_peak_arcsec=max(c[0] for c in clock),
            clock_offset_us=max((c[1] for c in clock), key=abs),
        )

    def _clock_terms(self, sel: list[list[float]]) -> list[tuple[float, int]]:
        """Return per bin (rate × |clock offset| in arcsec, the offset in µs)."""
        out = []
        for b in sel:
            offset = self._offset_at(int(b[0]) * self.bin_us)
            out.append((self._rates.get(int(b[0]), 0.0) * abs(offset) / 1e6, offset))
        return out

    def window(self, seconds: float) -> ErrorStats:
        """Return the statistics of the last `seconds` of mount time received."""
        return self.stats(self.last_t_us - int(seconds * 1e6), None)

    def series(self, from_us: int | None = None, to_us: int | None = None,
               max_points: int = 5000) -> dict[str, list]:
        """Return per-bin (t_us, rms, peak, az and el RMS on the sky) in arcsec, decimated to
        at most `max_points`."""
        sel = self._select(from_us, to_us)
        step = max(1, math.ceil(len(sel) / max_points))
        out: dict[str, list] = {"t_us": [], "rms_arcsec": [], "peak_arcsec": [],
                                "az_rms_arcsec": [], "el_rms_arcsec": []}
        for k in range(0, len(sel), step):
            group = sel[k:k + step]
            n = sum(b[1] for b in group)
            out["t_us"].append(int(group[0][0] * self.bin_us))
            out["rms_arcsec"].append(math.sqrt(sum(b[2] for b in group) / n))
            out["peak_arcsec"].append(max(b[5] for b in group))
            out["az_rms_arcsec"].append(math.sqrt(sum(b[3] for b in group) / n))
            out["el_rms_arcsec"].append(math.sqrt(sum(b[4] for b in group) / n))
        return out
