"""Tracking-error statistics from the mount's per-tick error stream.

Samples (mount time µs, azimuth and elevation following error in arcsec,
elevation in rad) are reduced on arrival into fixed bins of `bin_us` mount
time holding the count, the sums of squares and the peak of the on-sky error
(azimuth error × cos(elevation) combined with the elevation error) and of each
axis. Any window's RMS and peak are then exact sums over bins, and memory is
bounded by the number of bins kept (rows of one array), whatever the sample rate.

Three errors, kept apart (`on_target.py` computes the last two per sample):

* the **following error** (`rms_arcsec`, `peak_arcsec`): what the *encoders* miss of
  the demand the VSS sent — the mount's servo error;
* the **on-target error** (`on_target_*`): the encoders (through the pointing model)
  against the target's true place — what the sky sees; with the time spent farther
  than `off_target_arcsec` from it (`off_target_s`);
* the **planned deviation** (`planned_deviation_*`): the demand against the target's
  true place — what the VSS chose to send (a keyhole, a clipped rate, offsets).

The sky misses more when the mount clock is off UTC: the mount is then where the
target was (or will be) `offset` earlier, `rate × |offset|` away on the sky. So the
history also keeps the target's on-sky rate per bin (from the points the feeder
pushed) and the clock offsets TimeS measured, and reports the **on-sky error**:
per bin the clock term added to the on-target RMS in quadrature and to its peak
linearly (the two may point the same way). Where no target is followed (a slew, a
fixed place, a hand-pad move) the demand is the goal, and the following error
stands in for the on-target one.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["ErrorStats", "TrackingErrorHistory", "warm_up"]

DEFAULT_BIN_US = 100_000  # 0.1 s of mount time
DEFAULT_MAX_BINS = 36_000  # one hour of mount time at 0.1 s
DEFAULT_OFF_TARGET_ARCSEC = 5.0

# a bin: [index, n, Σsky², Σaz², Σel², peak sky,
#         n on target, Σon², peak on, µs off target, peak deviation, µs deviating]
_IDX, _N, _SKY, _AZ, _EL, _PEAK, _NT, _ON, _PEAK_ON, _OFF_US, _PEAK_DEV, _DEV_US = range(12)


@dataclass(frozen=True)
class ErrorStats:
    """Error figures over a window (arcsec; n samples; times in mount µs).

    `rms_arcsec`/`peak_arcsec`: the following error (encoders vs demand). `on_target_*`:
    the encoders vs the target's true place (NaN where no target was followed);
    `planned_deviation_*`: the demand vs that place. `on_sky_*`: on target (or, where
    nothing is followed, the following error) with the clock term.
    """

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
    target_samples: int = 0
    on_target_rms_arcsec: float = math.nan
    on_target_peak_arcsec: float = math.nan
    off_target_s: float = 0.0  # mount seconds farther than the threshold from the target
    off_target_threshold_arcsec: float = DEFAULT_OFF_TARGET_ARCSEC
    planned_deviation_peak_arcsec: float = math.nan
    planned_deviation_s: float = 0.0  # mount seconds the demand was beyond the threshold

    def as_dict(self) -> dict:
        return {"n": self.n, "rms_arcsec": self.rms_arcsec, "peak_arcsec": self.peak_arcsec,
                "az_rms_arcsec": self.az_rms_arcsec, "el_rms_arcsec": self.el_rms_arcsec,
                "on_sky_rms_arcsec": self.on_sky_rms_arcsec,
                "on_sky_peak_arcsec": self.on_sky_peak_arcsec,
                "clock_error_peak_arcsec": self.clock_error_peak_arcsec,
                "clock_offset_us": self.clock_offset_us,
                "target_samples": self.target_samples,
                "on_target_rms_arcsec": self.on_target_rms_arcsec,
                "on_target_peak_arcsec": self.on_target_peak_arcsec,
                "off_target_s": self.off_target_s,
                "off_target_threshold_arcsec": self.off_target_threshold_arcsec,
                "planned_deviation_peak_arcsec": self.planned_deviation_peak_arcsec,
                "planned_deviation_s": self.planned_deviation_s,
                "from_us": self.from_us, "to_us": self.to_us}

    def track_summary(self, degraded_after_s: float, planned: list[str]) -> dict:
        """A finished track's figures for its operation: `tracking_*` is on target (the
        truth; the following error if no target sample arrived), `following_*` the
        servo error, the planned deviation apart with what it was planned for, and
        `outcome`: `degraded` when off target longer than `degraded_after_s`, else `done`."""
        has_target = self.target_samples > 0
        return {
            "tracking_rms_arcsec": self.on_target_rms_arcsec if has_target else self.rms_arcsec,
            "tracking_peak_arcsec": (self.on_target_peak_arcsec if has_target
                                     else self.peak_arcsec),
            "following_rms_arcsec": self.rms_arcsec, "following_peak_arcsec": self.peak_arcsec,
            "on_sky_rms_arcsec": self.on_sky_rms_arcsec,
            "on_sky_peak_arcsec": self.on_sky_peak_arcsec,
            "clock_error_peak_arcsec": self.clock_error_peak_arcsec,
            "off_target_s": self.off_target_s,
            "off_target_threshold_arcsec": self.off_target_threshold_arcsec,
            "planned_deviation_peak_arcsec": self.planned_deviation_peak_arcsec,
            "planned_deviation_s": self.planned_deviation_s, "planned_deviation": planned,
            "outcome": "degraded" if self.off_target_s > degraded_after_s else "done"}


class TrackingErrorHistory:
    """Bounded history of error bins; feed it with `add(t_us, az_as, el_as, el_rad, ...)`."""

    def __init__(self, *, bin_us: int = DEFAULT_BIN_US, max_bins: int = DEFAULT_MAX_BINS,
                 off_target_arcsec: float = DEFAULT_OFF_TARGET_ARCSEC) -> None:
        self.bin_us = int(bin_us)
        self.off_target_arcsec = float(off_target_arcsec)
        # the bins, oldest first, as rows of one array (rows[lo:hi]): a window is a view
        self._rows = np.zeros((min(256, 2 * max_bins), 12))
        self._lo = self._hi = 0
        self._max_bins = max_bins
        self._rates: dict[int, float] = {}  # bin index -> the target's on-sky rate, arcsec/s
        self._offset_t: list[int] = []  # mount times of clock-offset measurements (increasing)
        self._offset_us: list[int] = []
        self._period_us = 1000.0  # the stream's sample period, learnt from the samples
        self.samples = 0
        self.last_t_us = 0
        self.last_sky_arcsec = 0.0
        self.last_on_target_arcsec = math.nan  # the newest sample's (NaN: no target)
        self.last_deviation_arcsec = math.nan

    def clear(self) -> None:
        self._lo = self._hi = 0
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

    def add(self, t_us: np.ndarray, az_err_arcsec: np.ndarray, el_err_arcsec: np.ndarray,
            el_rad: np.ndarray, on_target_arcsec: np.ndarray | None = None,
            deviation_arcsec: np.ndarray | None = None) -> None:
        """Reduce a block of samples into the bins (times increasing).

        `on_target_arcsec` and `deviation_arcsec` (from `OnTarget.measure`, NaN where no
        target is followed) are optional: without them the bins have no target samples.
        """
        t = np.asarray(t_us, np.int64)
        if t.size == 0:
            return
        if t.size > 1:
            self._period_us = float(t[-1] - t[0]) / (t.size - 1)
        el = np.asarray(el_rad, float)
        az_err, el_err = np.asarray(az_err_arcsec, float), np.asarray(el_err_arcsec, float)
        if on_target_arcsec is None:
            on_target_arcsec = deviation_arcsec = np.full(t.size, math.nan)
        rows = _bin_rows(t, az_err, el_err, el, np.asarray(on_target_arcsec, float),
                         np.asarray(deviation_arcsec, float), self.bin_us,
                         self.off_target_arcsec, self._period_us)
        for row in rows.tolist():
            b = row[0]
            last = self._rows[self._hi - 1] if self._hi > self._lo else None
            if last is not None and last[0] == b:
                for j in (_N, _SKY, _AZ, _EL, _NT, _ON, _OFF_US, _DEV_US):
                    last[j] = float(last[j]) + row[j]
                for j in (_PEAK, _PEAK_ON, _PEAK_DEV):
                    last[j] = max(float(last[j]), row[j])
            elif last is None or last[0] < b:
                self._append(row)
        self.samples += int(t.size)
        self.last_t_us = int(t[-1])
        self.last_sky_arcsec = float(math.hypot(az_err[-1] * math.cos(el[-1]), el_err[-1]))
        self.last_on_target_arcsec = float(on_target_arcsec[-1])
        self.last_deviation_arcsec = float(deviation_arcsec[-1])

    def _append(self, row: list[float]) -> None:
        """Add a bin after the newest; beyond `max_bins` the oldest is forgotten."""
        if self._hi == len(self._rows):  # full: move the kept bins to the front, or grow
            kept = self._rows[self._lo:self._hi].copy()
            size = len(self._rows)
            if len(kept) > size // 2 and size < 2 * self._max_bins:
                size = min(2 * size, 2 * self._max_bins)
            self._rows = np.zeros((size, 12))
            self._rows[:len(kept)] = kept
            self._lo, self._hi = 0, len(kept)
        self._rows[self._hi] = row
        self._hi += 1
        if self._hi - self._lo > self._max_bins:
            self._lo += 1

    def _select(self, from_us: int | None, to_us: int | None) -> np.ndarray:
        """Return the bins whose start lies in [from_us, to_us), oldest first (a view)."""
        rows = self._rows[self._lo:self._hi]
        lo = 0 if from_us is None else np.searchsorted(
            rows[:, 0], int(from_us) // self.bin_us, "left")
        hi = len(rows) if to_us is None else np.searchsorted(
            rows[:, 0], -(-int(to_us) // self.bin_us), "left")
        return rows[lo:hi]

    def stats(self, from_us: int | None = None, to_us: int | None = None) -> ErrorStats:
        """Return the figures over bins whose start lies in [from_us, to_us)."""
        sel = self._select(from_us, to_us)
        if not len(sel) or not sel[:, _N].any():
            return ErrorStats(0, math.nan, math.nan, math.nan, math.nan,
                              int(from_us or 0), int(to_us or 0),
                              off_target_threshold_arcsec=self.off_target_arcsec)
        # every status asks for three windows (711 bins): the sums run compiled, in the
        # bins' order, with Python's own rules (sequential sums, first of equal maxima)
        rates = np.array([self._rates.get(b, 0.0) for b in sel[:, _IDX].astype(np.int64).tolist()],
                         dtype=np.float64)
        off_t, off_us = self._offsets_around(int(sel[0][0]) * self.bin_us,
                                             int(sel[-1][0]) * self.bin_us)
        (n, sky2, peak, az2, el2, sky_n, sky_s, sky_peak, clock_peak, clock_offset, n_t, on2,
         peak_on, off_us_sum, peak_dev, dev_us_sum) = _reduce_bins(sel, rates, self.bin_us,
                                                                   off_t, off_us)
        return ErrorStats(
            int(n),
            math.sqrt(sky2 / n),
            peak,
            math.sqrt(az2 / n),
            math.sqrt(el2 / n),
            int(sel[0][0]) * self.bin_us,
            (int(sel[-1][0]) + 1) * self.bin_us,
            on_sky_rms_arcsec=math.sqrt(sky_s / sky_n),
            on_sky_peak_arcsec=sky_peak,
            clock_error_peak_arcsec=clock_peak,
            clock_offset_us=int(clock_offset),
            target_samples=int(n_t),
            on_target_rms_arcsec=math.sqrt(on2 / n_t) if n_t else math.nan,
            on_target_peak_arcsec=peak_on,
            off_target_s=off_us_sum / 1e6,
            off_target_threshold_arcsec=self.off_target_arcsec,
            planned_deviation_peak_arcsec=peak_dev,
            planned_deviation_s=dev_us_sum / 1e6,
        )

    def _offsets_around(self, t0_us: int, t1_us: int) -> tuple[np.ndarray, np.ndarray]:
        """The clock-offset measurements a bin starting in [t0_us, t1_us] may use: the last
        one at or before t0_us, those between, and the first after t1_us."""
        lo = max(bisect.bisect_right(self._offset_t, t0_us) - 1, 0)
        hi = bisect.bisect_right(self._offset_t, t1_us) + 1
        return (np.array(self._offset_t[lo:hi], dtype=np.int64),
                np.array(self._offset_us[lo:hi], dtype=np.int64))

    def window(self, seconds: float) -> ErrorStats:
        """Return the statistics of the last `seconds` of mount time received."""
        return self.stats(self.last_t_us - int(seconds * 1e6), None)

    def series(self, from_us: int | None = None, to_us: int | None = None,
               max_points: int = 5000) -> dict[str, list]:
        """Return per bin (t_us; following error rms, peak, az and el RMS on the sky; on-target
        RMS and peak and the peak planned deviation, None where no target was followed) in
        arcsec, decimated to at most `max_points`."""
        sel = self._select(from_us, to_us)
        step = max(1, math.ceil(len(sel) / max_points))
        out: dict[str, list] = {k: [] for k in (
            "t_us", "rms_arcsec", "peak_arcsec", "az_rms_arcsec", "el_rms_arcsec",
            "on_target_rms_arcsec", "on_target_peak_arcsec", "planned_deviation_arcsec")}
        for k in range(0, len(sel), step):
            group = sel[k:k + step].tolist()
            n = sum(b[_N] for b in group)
            n_t = sum(b[_NT] for b in group)
            out["t_us"].append(int(group[0][0]) * self.bin_us)
            out["rms_arcsec"].append(math.sqrt(sum(b[_SKY] for b in group) / n))
            out["peak_arcsec"].append(max(b[_PEAK] for b in group))
            out["az_rms_arcsec"].append(math.sqrt(sum(b[_AZ] for b in group) / n))
            out["el_rms_arcsec"].append(math.sqrt(sum(b[_EL] for b in group) / n))
            out["on_target_rms_arcsec"].append(
                math.sqrt(sum(b[_ON] for b in group) / n_t) if n_t else None)
            out["on_target_peak_arcsec"].append(max(b[_PEAK_ON] for b in group) if n_t else None)
            out["planned_deviation_arcsec"].append(max(b[_PEAK_DEV] for b in group) if n_t
                                                   else None)
        return out


def warm_up() -> None:
    """Compile the kernel (or load it from numba's cache) before the first packet arrives."""
    x = np.zeros(2)
    _bin_rows(np.zeros(2, np.int64), x, x, x, x, x, DEFAULT_BIN_US, 1.0, 1000.0)
    _reduce_bins(np.zeros((1, 12)), np.zeros(1), DEFAULT_BIN_US, np.zeros(1, np.int64),
                 np.zeros(1, np.int64))


@numba.njit(cache=True, nogil=True)
def _reduce_bins(bins, rates, bin_us, off_t, off_us):  # pragma: no cover - compiled
    """`stats`' sums over bin rows, in their order, as the Python it replaces computed them:
    sums left to right from zero, a maximum replaced only by a larger value (NaN never
    replaces), the clock offset of a bin the larger in size of the measurements just
    before and just after its start, the first of equal sizes."""
    n = sky2 = az2 = el2 = n_t = on2 = off_s = dev_s = 0.0
    sky_n = sky_s = sky_peak = 0.0
    peak = bins[0, 5]
    peak_on = peak_dev = math.nan
    clock_peak = 0.0
    clock_offset = 0
    targeted = False
    k = 0
    m = off_t.shape[0]
    for i in range(bins.shape[0]):
        b = bins[i]
        n += b[1]
        sky2 += b[2]
        az2 += b[3]
        el2 += b[4]
        if i > 0 and b[5] > peak:
            peak = b[5]
        n_t += b[6]
        off_s += b[9]
        dev_s += b[11]
        # the clock term: bisect_right over the measurements
        t = np.int64(b[0]) * bin_us
        while k < m and off_t[k] <= t:
            k += 1
        if m == 0:
            offset = 0
        elif k == 0 or k >= m:
            offset = off_us[max(k - 1, 0)]
        else:
            offset = off_us[k - 1]
            if abs(off_us[k]) > abs(offset):
                offset = off_us[k]
        c = rates[i] * abs(offset) / 1e6
        if i == 0:
            clock_peak = c
            clock_offset = offset
        else:
            if c > clock_peak:
                clock_peak = c
            if abs(offset) > abs(clock_offset):
                clock_offset = offset
        if b[6] > 0:
            cnt, s2, pk = b[6], b[7], b[8]
            on2 += b[7]
            if not targeted:
                peak_on, peak_dev = b[8], b[10]
                targeted = True
            else:
                if b[8] > peak_on:
                    peak_on = b[8]
                if b[10] > peak_dev:
                    peak_dev = b[10]
        else:
            cnt, s2, pk = b[1], b[2], b[5]
        sky_n += cnt
        sky_s += s2 + cnt * c * c
        if pk + c > sky_peak:
            sky_peak = pk + c
    return (n, sky2, peak, az2, el2, sky_n, sky_s, sky_peak, clock_peak, clock_offset, n_t, on2,
            peak_on, off_s, peak_dev, dev_s)


@numba.njit(cache=True, nogil=True)
def _bin_rows(t, az_err, el_err, el, on, dev, bin_us, limit, period_us):  # pragma: no cover
    """Reduce samples (times increasing) into bin rows laid out as the history's bins:
    following error on the sky and per axis; on target (NaN: no target) and deviation."""
    n = t.shape[0]
    rows = np.zeros((n, 12))
    r = -1
    last = -(2**62)
    for i in range(n):
        b = t[i] // bin_us
        if b != last:
            r += 1
            last = b
            rows[r, 0] = b
            rows[r, 5] = 0.0
            rows[r, 8] = -1.0
            rows[r, 10] = -1.0
        a = az_err[i] * math.cos(el[i])
        e = el_err[i]
        sky2 = a * a + e * e
        rows[r, 1] += 1.0
        rows[r, 2] += sky2
        rows[r, 3] += a * a
        rows[r, 4] += e * e
        rows[r, 5] = max(rows[r, 5], math.sqrt(sky2))
        if not math.isnan(on[i]):
            rows[r, 6] += 1.0
            rows[r, 7] += on[i] * on[i]
            rows[r, 8] = max(rows[r, 8], on[i])
            if on[i] > limit:
                rows[r, 9] += period_us
            rows[r, 10] = max(rows[r, 10], dev[i])
            if dev[i] > limit:
                rows[r, 11] += period_us
    return rows[:r + 1]
