"""Rise, culmination and set of any target, and satellite passes.

A coarse scan of the observed elevation finds the brackets; scipy's brentq
then refines each crossing (elevation = horizon) and each culmination
(elevation rate = 0) on the exact per-time computation of the target.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .earth_orientation import EarthOrientation
from .site import Site
from .timescales import UtcTimes

#: Scan step for stars, planets and the Sun/Moon, seconds.
SKY_SCAN_STEP_S = 600.0
#: Scan step for satellites, seconds (a LEO pass above the horizon lasts minutes).
SATELLITE_SCAN_STEP_S = 20.0
#: Root tolerance in time, seconds.
TIME_TOLERANCE_S = 1e-3


@dataclass(frozen=True)
class Event:
    """One event: kind ("rise", "culmination", "set"), time, az/el in degrees."""

    kind: str
    utc: UtcTimes
    az_deg: float
    el_deg: float


@dataclass(frozen=True)
class Pass:
    """A satellite pass above min_el: rise/set are None when cut by the search window."""

    rise: Event | None
    culmination: Event
    set: Event | None


def find_events(target, site: Site, start: UtcTimes, duration_s: float, *,
                horizon_deg: float = 0.0, step_s: float | None = None,
                eop: EarthOrientation | None = None) -> list[Event]:
    """Return rises, culminations (upper, above the horizon) and sets in a window, in time order.

    Elevations are observed (refracted when the site's refraction is on);
    horizon_deg is the elevation counted as rising/setting.
    """
    step = step_s or (SATELLITE_SCAN_STEP_S if _is_satellite(target) else SKY_SCAN_STEP_S)
    n = max(int(math.ceil(duration_s / step)), 1) + 1
    offsets = np.linspace(0.0, duration_s, n)
    obs = target.observe(start.shifted(offsets), site, eop)
    h = math.radians(horizon_deg)
    el, rate = obs.el_rad - h, obs.el_rate_rad_s

    seen: dict[float, object] = {}

    def at(s: float):
        # the same instant is asked for again (each bracket's ends by _root and by brentq,
        # an event's place at its root): computed once, the same figures
        o = seen.get(s)
        if o is None:
            o = seen[s] = target.observe(start.shifted(np.array([s])), site, eop)
        return o

    events: list[tuple[float, str]] = []
    for i in np.flatnonzero(np.sign(el[:-1]) != np.sign(el[1:])):
        s = _root(lambda x: float(at(x).el_rad[0]) - h, offsets[i], offsets[i + 1])
        events.append((s, "rise" if el[i] < el[i + 1] else "set"))
    for i in np.flatnonzero((rate[:-1] > 0) & (rate[1:] <= 0)):
        s = _root(lambda x: float(at(x).el_rate_rad_s[0]), offsets[i], offsets[i + 1])
        events.append((s, "culmination"))
    events.sort()
    out = []
    for s, kind in events:
        o = at(s)
        if kind == "culmination" and o.el_rad[0] < h:
            continue
        out.append(Event(kind, start.shifted(s), math.degrees(o.az_rad[0]),
                         math.degrees(o.el_rad[0])))
    return out


def satellite_passes(satellite, site: Site, start: UtcTimes, end: UtcTimes, *,
                     min_el_deg: float = 0.0, step_s: float = SATELLITE_SCAN_STEP_S,
                     eop: EarthOrientation | None = None) -> list[Pass]:
    """Return the passes of a satellite whose culmination reaches min_el_deg, in time order."""
    duration = float(end.seconds_since(start.jd1[0], start.jd2[0])[0])
    if duration <= 0:
        raise ValueError("the end of the pass search must come after its start")
    events = find_events(satellite, site, start, duration, horizon_deg=min_el_deg,
                         step_s=step_s, eop=eop)
    passes: list[Pass] = []
    rise: Event | None = None
    culm: Event | None = None
    for ev in events:
        if ev.kind == "rise":
            rise, culm = ev, None
        elif ev.kind == "culmination":
            if culm is None or ev.el_deg > culm.el_deg:
                culm = ev
        elif ev.kind == "set":
            if culm is not None:
                passes.append(Pass(rise, culm, ev))
            rise, culm = None, None
    if culm is not None:
        passes.append(Pass(rise, culm, None))
    return passes


def _root(f: Callable[[float], float], a: float, b: float) -> float:
    fa, fb = f(a), f(b)
    if fa == 0.0:
        return a
    if fb == 0.0 or np.sign(fa) == np.sign(fb):
        return b
    return float(brentq(f, a, b, xtol=TIME_TOLERANCE_S))


def _is_satellite(target) -> bool:
    return hasattr(target, "satrec")
