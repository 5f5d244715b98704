"""A window's error figures the plain way: the history's bins summed one by one in Python.

The reference for `TrackingErrorHistory.stats`, which sums the same bins compiled: the
test of the pure parts (test_vss_parts.py) compares every figure to the last bit, and
benchmarks/bench_vss_cpu.py times both.
"""

from __future__ import annotations

import bisect
import math


def stats_by_plain_python(h, from_us, to_us) -> dict:
    """The window's figures from the history's bins, summed one by one in Python (the rules
    `stats` states: sequential sums, the first of equal maxima, a bin's clock offset the
    larger in size of the measurements just before and after its start)."""
    sel = h._select(from_us, to_us).tolist()
    n = sum(b[1] for b in sel)
    clock = []
    for b in sel:
        k = bisect.bisect_right(h._offset_t, int(b[0]) * h.bin_us)
        around = h._offset_us[max(k - 1, 0):k + 1]
        offset = max(around, key=abs) if around else 0
        clock.append((h._rates.get(int(b[0]), 0.0) * abs(offset) / 1e6, offset))
    sky_n = sky_s = sky_peak = 0.0
    for b, (c, _) in zip(sel, clock, strict=True):
        cnt, s2, pk = (b[6], b[7], b[8]) if b[6] > 0 else (b[1], b[2], b[5])
        sky_n += cnt
        sky_s += s2 + cnt * c * c
        sky_peak = max(sky_peak, pk + c)
    targeted = [b for b in sel if b[6] > 0]
    n_t = sum(b[6] for b in sel)
    return {"n": int(n), "rms_arcsec": math.sqrt(sum(b[2] for b in sel) / n),
            "peak_arcsec": max(b[5] for b in sel),
            "az_rms_arcsec": math.sqrt(sum(b[3] for b in sel) / n),
            "el_rms_arcsec": math.sqrt(sum(b[4] for b in sel) / n),
            "from_us": int(sel[0][0]) * h.bin_us, "to_us": (int(sel[-1][0]) + 1) * h.bin_us,
            "on_sky_rms_arcsec": math.sqrt(sky_s / sky_n), "on_sky_peak_arcsec": sky_peak,
            "clock_error_peak_arcsec": max(c[0] for c in clock),
            "clock_offset_us": max((c[1] for c in clock), key=abs), "target_samples": int(n_t),
            "on_target_rms_arcsec": math.sqrt(sum(b[7] for b in targeted) / n_t) if n_t
            else math.nan,
            "on_target_peak_arcsec": max((b[8] for b in targeted), default=math.nan),
            "off_target_s": sum(b[9] for b in sel) / 1e6,
            "off_target_threshold_arcsec": h.off_target_arcsec,
            "planned_deviation_peak_arcsec": max((b[10] for b in targeted), default=math.nan),
            "planned_deviation_s": sum(b[11] for b in sel) / 1e6}
