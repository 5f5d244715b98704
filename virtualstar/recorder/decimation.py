"""Min/max envelopes of long signals: pure functions over arrays.

An envelope keeps, for each time bucket, the count, minimum and maximum of each signal,
so a plot of millions of samples at a few thousand pixels still shows every peak.
Buckets are aligned on an origin in mount time (integer µs, 0 by default): bucket k
covers [origin + k·bucket_us, origin + (k+1)·bucket_us), which lets envelopes computed
piecewise (one per flushed block) merge exactly into coarser ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Envelope", "envelope", "merge_envelope", "rebucket"]


@dataclass(frozen=True)
class Envelope:
    """Per-bucket count, minimum and maximum of named signals.

    `t_us[i]` is the start of bucket i (mount time, µs); `mins[name][i]`, `maxs[name][i]`
    the extremes of the samples in it, `n[i]` their number (NaN samples are ignored by
    min/max; a bucket of only NaN holds NaN).
    """

    bucket_us: int
    t_us: np.ndarray
    n: np.ndarray
    mins: dict[str, np.ndarray]
    maxs: dict[str, np.ndarray]

    @property
    def names(self) -> list[str]:
        return list(self.mins)

    def __len__(self) -> int:
        return int(self.t_us.shape[0])


def _bucket_starts(t_us: np.ndarray, bucket_us: int,
                   origin_us: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Return (bucket start µs per distinct bucket, index of its first sample); t_us sorted."""
    keys = np.floor_divide(t_us - origin_us, bucket_us)
    first = np.flatnonzero(np.diff(keys, prepend=keys[:1] - 1))
    return origin_us + keys[first] * bucket_us, first


def envelope(t_us: np.ndarray, columns: dict[str, np.ndarray], bucket_us: int,
             origin_us: int = 0) -> Envelope:
    """Return the envelope of `columns` sampled at sorted `t_us` in buckets of `bucket_us` µs
    counted from `origin_us`.

    Raises ValueError for a non-positive bucket or columns of another length than t_us.
    """
    if bucket_us <= 0:
        raise ValueError(f"bucket_us must be > 0, got {bucket_us}")
    t_us = np.asarray(t_us, dtype=np.int64)
    if len(t_us) == 0:
        empty = np.empty(0)
        return Envelope(bucket_us, np.empty(0, np.int64), np.empty(0, np.int64),
                        {k: empty for k in columns}, {k: empty for k in columns})
    starts, first = _bucket_starts(t_us, bucket_us, origin_us)
    counts = np.diff(np.append(first, len(t_us)))
    mins, maxs = {}, {}
    for name, values in columns.items():
        v = np.asarray(values)
        if v.shape[0] != t_us.shape[0]:
            raise ValueError(f"column {name} has {v.shape[0]} samples for {t_us.shape[0]} times")
        mins[name], maxs[name] = _reduce(v, first)
    return Envelope(bucket_us, starts, counts, mins, maxs)


def _reduce(v: np.ndarray, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if v.dtype.kind == "f" and np.isnan(v).any():
        lo = np.fmin.reduceat(v, first)
        hi = np.fmax.reduceat(v, first)
    else:
        lo = np.minimum.reduceat(v, first)
        hi = np.maximum.reduceat(v, first)
    return lo, hi


def rebucket(env: Envelope, bucket_us: int, origin_us: int = 0) -> Envelope:
    """Return `env` merged into coarser buckets of `bucket_us` µs counted from `origin_us`.

    `bucket_us` must be a multiple of env's bucket, and `origin_us` a bucket boundary of
    env, or a fine bucket would straddle two coarse ones (ValueError).
    """
    if bucket_us % env.bucket_us or origin_us % env.bucket_us:
        raise ValueError(f"bucket {bucket_us} µs and origin {origin_us} µs must be multiples "
                         f"of {env.bucket_us} µs")
    if len(env) == 0:
        return Envelope(bucket_us, env.t_us, env.n, env.mins, env.maxs)
    order = np.argsort(env.t_us, kind="stable")
    t = env.t_us[order]
    starts, first = _bucket_starts(t, bucket_us, origin_us)
    n = np.add.reduceat(env.n[order], first)
    mins = {k: np.fmin.reduceat(v[order], first) for k, v in env.mins.items()}
    maxs = {k: np.fmax.reduceat(v[order], first) for k, v in env.maxs.items()}
    return Envelope(bucket_us, starts, n, mins, maxs)


def merge_envelope(parts: list[Envelope]) -> Envelope:
    """Return one envelope of several with the same bucket width (buckets may repeat)."""
    if not parts:
        raise ValueError("no envelopes to merge")
    bucket_us = parts[0].bucket_us
    if any(p.bucket_us != bucket_us for p in parts):
        raise ValueError("envelopes of different bucket widths; rebucket them first")
    names = parts[0].names
    joined = Envelope(bucket_us, np.concatenate([p.t_us for p in parts]),
                      np.concatenate([p.n for p in parts]),
                      {k: np.concatenate([p.mins[k] for p in parts]) for k in names},
                      {k: np.concatenate([p.maxs[k] for p in parts]) for k in names})
    return rebucket(joined, bucket_us)
