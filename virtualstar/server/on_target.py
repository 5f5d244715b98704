"""On-target truth: where the boresight is against where the target really is.

The mount streams its *following* error (demand − encoders): how well the axes
follow what the VSS sent. That is not what the sky sees when the VSS chose to send
something other than the target (a keyhole near the zenith, a rate or limit clip,
a guide or user offset). From the same samples this module gives, per sample:

* **on target**: the encoders against the target's true place — the target
  observed at that mount time (`virtualstar.astro`, checked against astropy and
  skyfield in the tests), moved by the offsets in force (`offsets.Offsets`: the
  observer's, the guider's and the closed loop's — deliberate, so reported apart and
  not counted as error; `offset_path.OffsetPath` applies them exactly as to the
  demand), taken
  through the loaded pointing model into the encoder frame, as the VSS knows the
  mount's geometry (no model: the encoders are the observed place);
* **planned deviation**: the demand (encoders + following error) against the same
  true place: what the VSS chose to send, shown apart.

Both are great-circle distances (ERFA `seps`) in arcseconds. Comparing in the encoder
frame instead of taking each sample through the model's inverse differs from it by the
model's Jacobian (terms of ≤ 0.1 % of the distance for models of hundreds of arcseconds).

The true place is computed on a 50 ms grid of mount time, 30 s at a time, and
interpolated with cubic Hermite polynomials from the places and rates (well below a
milliarcsecond for stars, and for satellites outside the last second before the zenith).
"""

from __future__ import annotations

import logging
import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import erfa
import numba
import numpy as np

from virtualstar.astro import observe_mount_times
from virtualstar.astro.constants import ARCSEC_PER_RAD

from .offset_path import OffsetPath
from .offsets import Offsets
from .trajectories import Points, observed_to_encoder

__all__ = ["OnTarget", "TargetTruth", "warm_up"]

log = logging.getLogger("virtualstar.server")

GRID_US = 50_000  # the true place is computed this often (mount time) and interpolated
CHUNK_US = 30_000_000  # ... this much of it at a time
KEEP_ENDED = 4  # ended references kept for samples that arrive late


@dataclass
class TargetTruth:
    """A target's true place in the encoder frame, from `from_us` until `to_us` (mount µs)."""

    target: Any
    name: str
    site: Any
    eop: Any
    model: Any
    from_us: int
    to_us: int | None = None
    op_id: int | None = None  # the operation that follows it
    planned: list[str] = field(default_factory=list)  # what the VSS chose to send apart
    offsets: Offsets | None = None  # the intended place moves with them
    _chunk: tuple[np.ndarray, ...] | None = None  # t_us, az, el, az rate, el rate
    failed: str = ""

    def grid(self, first_us: int, last_us: int) -> tuple[np.ndarray, ...]:
        """The true place on the grid around [first_us, last_us]: (t_us, az, el, az rate,
        el rate) in the encoder frame (rad, rad/s), the azimuth continuous."""
        c = self._chunk
        if c is None or first_us < c[0][0] or last_us > c[0][-1]:
            c = self._chunk = self._compute(first_us, last_us)
        return c

    @property
    def offset(self) -> bool:
        """Whether offsets move the intended place (then it is sampled through OffsetPath)."""
        return self.offsets is not None and self.offsets.any

    def intended(self, t_us: np.ndarray) -> Points:
        """The intended place at mount times in the encoder frame: the truth moved by the
        offsets, as the feeder moves the demand."""
        lat = math.radians(self.site.lat_deg)
        return OffsetPath(_GridPath(self), self.offsets or Offsets(), lat).sample(t_us)

    def _compute(self, first_us: int, last_us: int) -> tuple[np.ndarray, ...]:
        start = first_us // GRID_US * GRID_US
        n = max(CHUNK_US, last_us - start + GRID_US) // GRID_US + 2
        t = start + GRID_US * np.arange(n, dtype=np.int64)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the feeder has already said it (EOP, TLE age)
            o = observe_mount_times(self.target, t, self.site, self.eop)
        az, el, v_az, v_el = observed_to_encoder(self.model, np.unwrap(o.az_rad), o.el_rad,
                                                 o.az_rate_rad_s, o.el_rate_rad_s)
        return t, np.unwrap(az), el, v_az, v_el


class _GridPath:
    """A target's true place as a `trajectories.Path`: cubic Hermite on its grid."""

    end_us = 2**62  # a truth has no end

    def __init__(self, ref: TargetTruth) -> None:
        self.ref = ref

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        g_t, az, el, v_az, v_el = self.ref.grid(int(t.min()), int(t.max()))
        k = np.clip((t - g_t[0]) // GRID_US, 0, g_t.shape[0] - 2)
        s = (t - g_t[k]) / GRID_US
        h = GRID_US / 1e6
        s2, s3 = s * s, s * s * s
        w = (2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * h, -2 * s3 + 3 * s2, (s3 - s2) * h)
        dw = ((6 * s2 - 6 * s) / h, 3 * s2 - 4 * s + 1, (-6 * s2 + 6 * s) / h, 3 * s2 - 2 * s)

        def at(weights, p, v):
            return (weights[0] * p[k] + weights[1] * v[k] + weights[2] * p[k + 1]
                    + weights[3] * v[k + 1])

        return Points(t, at(w, az, v_az), at(w, el, v_el), at(dw, az, v_az), at(dw, el, v_el))


class _ObservedPath:
    """A target's observed place as a `trajectories.Path` (computed at each time)."""

    end_us = 2**62

    def __init__(self, target, site, eop) -> None:
        self.target, self.site, self.eop = target, site, eop

    def sample(self, t_us: np.ndarray) -> Points:
        t = np.asarray(t_us, np.int64)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            o = observe_mount_times(self.target, t, self.site, self.eop)
        return Points(t, o.az_rad, o.el_rad, o.az_rate_rad_s, o.el_rate_rad_s)


@numba.njit(cache=True, nogil=True)
def _sep_arcsec(az1, el1, az2, el2):  # pragma: no cover - compiled
    """Great-circle distance of two directions (arcsec): atan2(|a × b|, a · b), as ERFA."""
    c1, c2 = math.cos(el1), math.cos(el2)
    ax, ay, az = c1 * math.cos(az1), c1 * math.sin(az1), math.sin(el1)
    bx, by, bz = c2 * math.cos(az2), c2 * math.sin(az2), math.sin(el2)
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz),
                      ax * bx + ay * by + az * bz) * ARCSEC_PER_RAD


@numba.njit(cache=True, nogil=True)
def _distances(t, enc_az, enc_el, dem_az, dem_el, i0, i1, g_t, grid_us, az, el, v_az, v_el,
               on, dev):  # pragma: no cover - compiled
    """For samples i0..i1: the true place by cubic Hermite on the grid, then the encoders'
    and the demand's distances from it (arcsec) into `on` and `dev`."""
    h = grid_us / 1e6
    last = g_t.shape[0] - 2
    for i in range(i0, i1):
        k = min(max((t[i] - g_t[0]) // grid_us, 0), last)
        s = (t[i] - g_t[k]) / grid_us
        s2 = s * s
        s3 = s2 * s
        h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * h, -2 * s3 + 3 * s2, \
            (s3 - s2) * h
        ta = h00 * az[k] + h10 * v_az[k] + h01 * az[k + 1] + h11 * v_az[k + 1]
        te = h00 * el[k] + h10 * v_el[k] + h01 * el[k + 1] + h11 * v_el[k + 1]
        on[i] = _sep_arcsec(enc_az[i], enc_el[i], ta, te)
        dev[i] = _sep_arcsec(dem_az[i], dem_el[i], ta, te)


def warm_up() -> None:
    """Compile the kernel (or load it from numba's cache) now, not in the middle of a session:
    a first compile holds the event loop for seconds on a loaded host."""
    t = np.zeros(2, np.int64)
    x = np.zeros(2)
    _distances(t, x, x, x, x, 0, 2, np.array([0, GRID_US], np.int64), GRID_US, x, x, x, x,
               x.copy(), x.copy())


class OnTarget:
    """The targets the VSS follows over mount time, and their truth for each sample."""

    def __init__(self, site, eop) -> None:
        self.site = site
        self.eop = eop
        self._refs: list[TargetTruth] = []

    @property
    def current(self) -> TargetTruth | None:
        """The target being followed now (None between operations)."""
        ref = self._refs[-1] if self._refs else None
        return ref if ref is not None and ref.to_us is None else None

    def follow(self, target, name: str, *, model, from_us: int, op_id: int | None = None,
               planned: list[str] | None = None, offsets: Offsets | None = None) -> TargetTruth:
        """From mount time `from_us` the boresight should be on `target`, moved by the
        operation's `offsets` if any (ends the one before)."""
        self.end(from_us)
        ref = TargetTruth(target, name, self.site, self.eop, model, int(from_us),
                          op_id=op_id, planned=list(planned or []), offsets=offsets)
        self._refs = [*self._refs[-KEEP_ENDED:], ref]
        return ref

    def end(self, at_us: int, *, op_id: int | None = None) -> None:
        """The target followed until now is no longer the boresight's (at mount time `at_us`);
        with `op_id`, only if that operation follows it (an operation that ended early)."""
        ref = self.current
        if ref is not None and (op_id is None or ref.op_id == op_id):
            ref.to_us = max(int(at_us), ref.from_us)

    def planned_for(self, op_id: int) -> list[str]:
        """What the demand of an operation's newest target was planned to leave it for."""
        for ref in reversed(self._refs):
            if ref.op_id == op_id:
                return list(ref.planned)
        return []

    def measure(self, t_us: np.ndarray, enc_az: np.ndarray, enc_el: np.ndarray,
                dem_az: np.ndarray, dem_el: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Return (on target, planned deviation) in arcsec per sample, NaN where no target
        is followed; None when no sample has one (encoders and demand in rad)."""
        t = np.asarray(t_us, np.int64)
        if t.size == 0 or not self._refs:
            return None
        on = dev = None
        t0, t1 = int(t[0]), int(t[-1])
        for ref in self._refs:
            if ref.failed or t1 < ref.from_us or (ref.to_us is not None and t0 > ref.to_us):
                continue
            i0 = int(np.searchsorted(t, ref.from_us))
            i1 = t.size if ref.to_us is None else int(np.searchsorted(t, ref.to_us, "right"))
            if i1 <= i0:
                continue
            try:
                g_t, az, el, v_az, v_el = ref.grid(int(t[i0]), int(t[i1 - 1]))
                place = ref.intended(t[i0:i1]) if ref.offset else None
            except Exception as exc:  # noqa: BLE001 - a truth that cannot be computed is said once
                ref.failed = str(exc)
                log.warning("on-target truth for %s unavailable: %s", ref.name, exc)
                continue
            if on is None:
                on, dev = np.full(t.size, math.nan), np.full(t.size, math.nan)
            if place is not None:  # offsets in force: the intended place at each sample
                part = slice(i0, i1)
                on[part] = erfa.seps(np.asarray(enc_az, float)[part], np.asarray(enc_el, float)[part],
                                     place.az_rad, place.el_rad) * ARCSEC_PER_RAD
                dev[part] = erfa.seps(np.asarray(dem_az, float)[part], np.asarray(dem_el, float)[part],
                                      place.az_rad, place.el_rad) * ARCSEC_PER_RAD
                continue
            _distances(t, np.asarray(enc_az, float), np.asarray(enc_el, float),
                       np.asarray(dem_az, float), np.asarray(dem_el, float), i0, i1, g_t,
                       GRID_US, az, el, v_az, v_el, on, dev)
        return None if on is None else (on, dev)

    def now(self, t_us: int, obs_az_deg: float, obs_el_deg: float) -> dict[str, Any] | None:
        """The target followed now, its true observed place at `t_us` and the boresight's
        distance from it (observed az/el of the boresight, degrees), for the status."""
        ref = self.current
        if ref is None or t_us < ref.from_us:
            return None
        t = np.array([t_us], np.int64)
        observed = _ObservedPath(ref.target, self.site, self.eop)
        p = (OffsetPath(observed, ref.offsets, math.radians(self.site.lat_deg)).sample(t)
             if ref.offset else observed.sample(t))
        place = (p.az_rad, p.el_rad)
        az, el = float(place[0][0]), float(place[1][0])
        sep = float(erfa.seps(math.radians(obs_az_deg), math.radians(obs_el_deg), az, el))
        return {"target": ref.name, "since_us": ref.from_us, "at_us": int(t_us),
                "az_deg": math.degrees(az) % 360.0, "el_deg": math.degrees(el),
                "error_arcsec": sep * ARCSEC_PER_RAD, "planned": list(ref.planned)}
