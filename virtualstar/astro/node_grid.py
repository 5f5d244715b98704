"""Exact directions on an absolute time grid, splined between: what a track samples chunk by chunk.

A star's (or a planet's) exact direction costs an ERFA or skyfield call per instant; it is
smooth, so it is computed on a coarse grid of *nodes* and a cubic spline serves every
requested time with its analytic derivative (≤ 0.01 mas on 60-s nodes, tests/astro).

The nodes lie on an absolute grid: whole multiples of `grid_step_s` SI seconds counted in
TAI from J2000.0 (TAI), not from the first requested time. A trajectory is sampled in
chunks (the feeder's few seconds ahead, every correction's replacement), and on an absolute
grid every chunk meets the same nodes: their values are kept per (target, site, Earth
orientation, step) in a small cache and computed once, so a refresh costs a spline through
cached nodes instead of a fresh round of ERFA. TAI counts the leap second, as the sky does
(the spline runs in elapsed SI seconds, see timescales.py).
"""

from __future__ import annotations

import math
import threading
import warnings
from collections import OrderedDict
from collections.abc import Callable, Hashable

import erfa
import numpy as np
from scipy.interpolate import CubicSpline

from .constants import DAY_S, J2000_JD
from .timescales import UtcTimes

__all__ = ["NodeCache", "spline_or_exact"]

#: Time step of the central difference giving rates when times are sparse, seconds.
SPARSE_RATE_STEP_S = 0.5
#: Nodes on each side of the requested span: the spline's ends stay away from the times asked.
EDGE_NODES = 2
#: A span of at most this many nodes is always splined, however few the times (a track's
#: single instants: its nodes are cached, three exact calls for a rate would cost more).
#: The rule depends on the times alone, never on what the cache holds: a result is the same
#: whatever ran before it.
SPLINE_ALWAYS_NODES = 16
#: Nodes are computed in whole aligned blocks of this many (k // NODE_BLOCK): a node's value is
#: then always computed in the same batch at the same place, whatever the cache held before
#: (vectorised ufuncs may round the last bit by an element's place in the batch), so a
#: lockstep run is the same to the bit whatever the process computed before it.
NODE_BLOCK = 8
#: The grid's origin, TAI two-part Julian date: J2000.0 read as TAI.
_ORIGIN_TAI_JD = J2000_JD


class NodeCache:
    """Exact node values per key (target, site, Earth orientation, step), least recently used
    keys dropped beyond `max_keys`, oldest nodes of a key beyond `max_nodes` (a night at 60 s
    is 720 nodes). Safe to share between threads (the server plans beside its tracks)."""

    def __init__(self, *, max_keys: int = 64, max_nodes: int = 4096,
                 max_splines: int = 256) -> None:
        self.max_keys = max_keys
        self.max_nodes = max_nodes
        self.max_splines = max_splines
        self._nodes: OrderedDict[Hashable, dict[int, np.ndarray]] = OrderedDict()
        self._splines: OrderedDict[tuple, CubicSpline] = OrderedDict()
        self._lock = threading.Lock()
        self.computed = 0  # nodes computed (misses), for the tests and the benchmark
        self.reused = 0  # nodes served from the cache

    def values(self, key: Hashable | None, ks: np.ndarray,
               compute: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """Return the (len(ks), 3) values of nodes `ks`, computing the missing ones at once."""
        if key is None:
            return _in_blocks(ks, compute)
        with self._lock:
            known = self._nodes.get(key)
            if known is None:
                known = self._nodes[key] = {}
                while len(self._nodes) > self.max_keys:
                    self._nodes.popitem(last=False)
            else:
                self._nodes.move_to_end(key)
            rows = [known.get(int(k)) for k in ks]
        missing = [i for i, row in enumerate(rows) if row is None]
        if missing:
            blocks = np.unique(ks[missing] // NODE_BLOCK)
            fresh_ks = (blocks[:, None] * NODE_BLOCK + np.arange(NODE_BLOCK)).ravel()
            fresh = dict(zip(fresh_ks.tolist(), compute(fresh_ks), strict=True))
            for i in missing:
                rows[i] = fresh[int(ks[i])]
            with self._lock:
                known.update(fresh)
                while len(known) > self.max_nodes:
                    known.pop(next(iter(known)))
                self.computed += len(fresh_ks)
        with self._lock:
            self.reused += len(ks) - len(missing)
        return np.array(rows)

    def spline(self, key: Hashable | None, k0: int, k1: int, grid_step_s: float,
               compute: Callable[[np.ndarray], np.ndarray]) -> CubicSpline:
        """Return the cubic spline through nodes k0..k1 (its x: SI seconds from node k0).

        Built once per span and key: a track's consecutive chunks, and the single instants
        between them, mostly fall within the same span of nodes (building a spline costs
        more than evaluating it). The same nodes give the same spline, cached or not.
        """
        ks = np.arange(k0, k1 + 1, dtype=np.int64)
        if key is None:
            return CubicSpline((ks - k0) * float(grid_step_s), _in_blocks(ks, compute), axis=0)
        span = (key, k0, k1)
        with self._lock:
            hit = self._splines.get(span)
            if hit is not None:
                self._splines.move_to_end(span)
                return hit
        spline = CubicSpline((ks - k0) * float(grid_step_s), self.values(key, ks, compute),
                             axis=0)
        with self._lock:
            self._splines[span] = spline
            while len(self._splines) > self.max_splines:
                self._splines.popitem(last=False)
        return spline

    def clear(self) -> None:
        with self._lock:
            self._nodes.clear()
            self._splines.clear()


def _in_blocks(ks: np.ndarray, compute: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Compute nodes `ks` as the cache does: in whole aligned blocks of NODE_BLOCK."""
    blocks = np.unique(ks // NODE_BLOCK)
    fresh_ks = (blocks[:, None] * NODE_BLOCK + np.arange(NODE_BLOCK)).ravel()
    values = compute(fresh_ks)
    return values[np.searchsorted(fresh_ks, ks)]


#: The one cache of the process (targets and sites are values, Earth orientation tables
#: are compared by identity: a key never mixes two tables).
NODE_CACHE = NodeCache()


def spline_or_exact(exact: Callable[[UtcTimes], np.ndarray], times: UtcTimes,
                    grid_step_s: float, *, key: Hashable | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate `exact(UtcTimes) -> (N,3)` on the absolute node grid and spline it, or per
    point if the times are sparse.

    Returns (vectors, rates per SI second). `key` names what `exact` computes (hashable:
    target, site, Earth orientation table, step) so that its nodes are reused from
    `NODE_CACHE`; None computes every node afresh. Sparse times (fewer than a third of the
    nodes their span needs, and more than SPLINE_ALWAYS_NODES of those) are computed
    exactly, rates by a central difference. A node's value does not depend on which other
    nodes are computed with it, so a result is the same whether its nodes were cached.
    """
    tai1, tai2 = times.tai()
    step_days = grid_step_s / DAY_S
    # which nodes: to a tenth of a microsecond (float seconds since 2000), plenty for an index
    since_days = (tai1 - _ORIGIN_TAI_JD) + tai2
    k0 = math.floor(float(since_days.min()) / step_days) - EDGE_NODES
    k1 = math.ceil(float(since_days.max()) / step_days) + EDGE_NODES
    if (k1 - k0 + 1) > max(3 * len(times), SPLINE_ALWAYS_NODES):
        half = SPARSE_RATE_STEP_S
        v = exact(times)
        rate = (exact(times.si_shifted(half)) - exact(times.si_shifted(-half))) / (2 * half)
        return v, rate
    n1, n2 = _node_tai(np.array([k0]), grid_step_s)
    # elapsed SI seconds from the first node, from two-part dates: exact to picoseconds
    s = ((tai1 - n1[0]) + (tai2 - n2[0])) * DAY_S
    spline = NODE_CACHE.spline(None if key is None else (key, float(grid_step_s)), k0, k1,
                               grid_step_s, lambda k: exact(_node_times(k, grid_step_s)))
    return spline(s), spline(s, 1)


def _node_tai(ks: np.ndarray, grid_step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """TAI two-part Julian dates of nodes `ks` (whole days apart from the fraction)."""
    total_s = ks.astype(float) * float(grid_step_s)
    days = np.floor(total_s / DAY_S)
    return _ORIGIN_TAI_JD + days, (total_s - days * DAY_S) / DAY_S


def _node_times(ks: np.ndarray, grid_step_s: float) -> UtcTimes:
    """The nodes as UTC (ERFA's quasi-JD: a node inside a leap second is 23:59:60.x)."""
    n1, n2 = _node_tai(np.asarray(ks, np.int64), grid_step_s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)  # "dubious year", as in tai()
        utc1, utc2 = erfa.taiutc(n1, n2)
    return UtcTimes.from_jd(utc1, utc2)
