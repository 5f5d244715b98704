"""Sample times of a stream packet, by the rule of docs/astcom-protocol.md §6.

Sample i of a DATA packet was taken at ``first_t_us + round_half_up(i * period_us)``:
``i * period_us`` is one IEEE-754 double multiplication and ties round toward +∞,
which is exactly JavaScript's ``Math.round(i * periodUs)``; so every client, in any
language with doubles, gets the same integer microseconds. (Python's ``round`` and
``numpy.round`` round ties to even and would disagree on, e.g., 2.5 µs.)
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["round_half_up", "sample_offsets_us"]


def round_half_up(x: float) -> int:
    """Return the integer nearest to `x` (a double), ties toward +∞ (JavaScript's Math.round)."""
    floor = math.floor(x)
    return floor + (x - floor >= 0.5)  # x - floor(x) is exact for doubles


def sample_offsets_us(period_us: float, n: int) -> np.ndarray:
    """Return round_half_up(i * period_us) for i in 0..n-1 as int64 µs."""
    x = np.arange(n, dtype=np.float64) * np.float64(period_us)
    floor = np.floor(x)
    return (floor + (x - floor >= 0.5)).astype(np.int64)
