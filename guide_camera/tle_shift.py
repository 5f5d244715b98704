"""Make a truth TLE that is off from the one the VSS is given, as real elements are.

A LEO's elements are typically wrong by a time along the track (drag, a manoeuvre
since the epoch) and by a little across it. `shifted_tle` moves a satellite:

* along-track by `along_s` seconds: its mean anomaly grows by n·along_s, so the
  truth satellite is where the given elements put it about `along_s` later in its
  orbit. Seen from the ground that is not quite a time shift of the observed track:
  the site has turned with the Earth meanwhile (≈ 285 m/s at 52°), so 2 s of mean
  anomaly on the ISS look like ≈ 2.09 s along and up to ±25″ across, varying over
  the pass — as a real along-track error would;
* across-track by `across_arcsec` as seen from the site at `at_us` (e.g. the
  culmination): the orbit plane is tilted by β = across·ρ/r (ρ the range, r the
  geocentric radius) about the in-plane axis 90° before the satellite's argument
  of latitude u₀ there, so the displacement is largest at `at_us` and falls as
  cos(u − u₀) away from it (≥ 0.94 over a ten-minute LEO pass). A tilt about that
  axis is δi = β·cos(u₀ − 90°) about the line of nodes plus δΩ·sin i = β·sin(u₀ − 90°);
  the δΩ·cos i it brings along the track is taken back out of the mean anomaly.
  Positive: to the left of the direction of travel, as the VSS's `transverse`.

Both are then corrected by what `measure_offsets` (skyfield) sees from the site at
`at_us` until *there and then* the truth is `along_s` along (to 10 µs) and `across_arcsec`
across (to 0.01″); elsewhere on the pass it differs as a real error does. (What a move
is seen as depends on both offsets: 2 s of mean anomaly alone look like ≈ 2.09 s along
and tens of arcseconds across. Each round moves the elements by the miss through
Broyden's running estimate of that dependence; three to five rounds converge.) The
result is written as TLE text with `sgp4.exporter` (angles to 1e-4°: the time to 2 ms,
the across offset to about an arcsecond).
"""

from __future__ import annotations

import math
import time
from datetime import UTC, datetime

import numpy as np

from .exceptions import CameraConfigError
from .truth import CameraSite

__all__ = ["measure_offsets", "shifted_elements", "shifted_tle"]

MINUTES_PER_S = 1.0 / 60.0
# shifted_elements corrects its move until it is seen this close (10 µs: ≤ 0.04″ at 1°/s)
ALONG_TOLERANCE_S = 1e-5
ACROSS_TOLERANCE_ARCSEC = 0.01
MAX_ROUNDS = 8
RATE_STEP_US = 100_000  # the direction of travel: the track from 50 ms before to 50 ms after


def _satrec(line1: str, line2: str):
    from sgp4.api import Satrec

    try:
        return Satrec.twoline2rv(line1.strip(), line2.strip())
    except (ValueError, IndexError) as exc:
        raise CameraConfigError(f"cannot read the TLE: {exc}") from None


def _with_elements(sat, *, d_incl: float = 0.0, d_node: float = 0.0, d_mean: float = 0.0):
    from sgp4.api import WGS72, Satrec

    out = Satrec()
    epoch = sat.jdsatepoch + sat.jdsatepochF - 2433281.5
    out.sgp4init(WGS72, "i", sat.satnum, epoch, sat.bstar, sat.ndot, sat.nddot, sat.ecco,
                 sat.argpo, sat.inclo + d_incl, (sat.mo + d_mean) % (2 * math.pi),
                 sat.no_kozai, (sat.nodeo + d_node) % (2 * math.pi))
    out.classification = sat.classification
    out.intldesg = sat.intldesg
    out.elnum = sat.elnum
    out.revnum = sat.revnum
    return out


def _teme_at(sat, t_us: int) -> tuple[np.ndarray, np.ndarray]:
    from sgp4.api import jday

    s = t_us / 1e6
    whole = math.floor(s)
    tm = time.gmtime(whole)
    jd, fr = jday(tm.tm_year, tm.tm_mon, tm.tm_mday, tm.tm_hour, tm.tm_min,
                  tm.tm_sec + (s - whole))
    err, r, v = sat.sgp4(jd, fr)
    if err:
        raise CameraConfigError(f"SGP4 cannot propagate the TLE to {t_us} µs (error {err})")
    return np.array(r), np.array(v)


def shifted_elements(line1: str, line2: str, *, along_s: float, across_arcsec: float,
                     at_us: int, site: CameraSite):
    """Return the elements (an sgp4 `Satrec`, full precision) of the satellite moved along
    and across its track, so that seen from `site` at `at_us` it is `along_s` later along
    the track and `across_arcsec` across it (in rounds: what a move of the elements looks
    like from the ground is measured with `measure_offsets` and the rest moved again, until
    it is within ALONG_TOLERANCE_S and ACROSS_TOLERANCE_ARCSEC)."""
    if not (math.isfinite(along_s) and math.isfinite(across_arcsec)):
        raise CameraConfigError("along_s and across_arcsec must be finite")
    sat = _satrec(line1, line2)
    if not along_s and not across_arcsec:
        return sat
    from .truth import SatelliteTruth

    nominal = SatelliteTruth.from_satrec(sat, _plain_site(site))  # its places once, not per round
    target = np.array([along_s, across_arcsec])
    moved = target.copy()  # what the elements are moved by (seconds, arcsec)
    jac = np.eye(2)  # d(seen)/d(moved): Broyden's estimate, updated each round
    out = _move(sat, *moved, at_us, site)
    before = None  # (moved, seen) of the round before
    for _ in range(MAX_ROUNDS):
        seen = np.array([float(x[0]) for x in measure_offsets(nominal, out, np.array([at_us]),
                                                               site)])
        miss = target - seen
        if abs(miss[0]) <= ALONG_TOLERANCE_S and abs(miss[1]) <= ACROSS_TOLERANCE_ARCSEC:
            break
        if before is not None:
            d_moved, d_seen = moved - before[0], seen - before[1]
            jac += np.outer(d_seen - jac @ d_moved, d_moved) / (d_moved @ d_moved)
        before = (moved, seen)
        moved = moved + np.linalg.solve(jac, miss)
        out = _move(sat, *moved, at_us, site)
    return out


def shifted_tle(line1: str, line2: str, *, along_s: float, across_arcsec: float,
                at_us: int, site: CameraSite) -> tuple[str, str]:
    """`shifted_elements` written as TLE lines (angles to 1e-4°: near a LEO's culmination
    the across offset is then only good to a few arcseconds; use the elements)."""
    from sgp4.exporter import export_tle

    return export_tle(shifted_elements(line1, line2, along_s=along_s,
                                       across_arcsec=across_arcsec, at_us=at_us, site=site))


def _move(sat, along_s: float, across_arcsec: float, at_us: int, site: CameraSite):
    """Move the elements: `along_s` of mean anomaly, a plane tilt of `across_arcsec` at the
    range of `at_us` (the orbit's view; what the ground sees differs a little)."""
    from skyfield.api import EarthSatellite, wgs84

    from .truth import _skyfield

    n_rad_s = sat.no_kozai * MINUTES_PER_S  # mean motion, rad/s
    d_mean = n_rad_s * along_s
    d_incl = d_node = 0.0
    if across_arcsec:
        r, v = _teme_at(sat, at_us)
        # argument of latitude: angle from the ascending node to the satellite, in the plane
        h = np.cross(r, v)
        node = np.cross([0.0, 0.0, 1.0], h)
        node /= np.linalg.norm(node)
        u0 = math.atan2(np.dot(np.cross(node, r), h) / np.linalg.norm(h), np.dot(node, r))
        ts, _ = _skyfield()
        t = ts.from_datetime(datetime.fromtimestamp(at_us / 1e6, UTC))
        es = EarthSatellite.from_satrec(sat, ts)
        rho_km = float((es - wgs84.latlon(site.lat_deg, site.lon_deg, site.height_m)).at(t)
                       .distance().km)
        beta = math.radians(across_arcsec / 3600.0) * rho_km / float(np.linalg.norm(r))
        u_axis = u0 - math.pi / 2
        # seen from the ground, looking up, "left of travel" is toward −h: tilt that way
        # (tests/guide_camera measure +across for a +across here)
        d_incl = -beta * math.cos(u_axis)
        sin_i = math.sin(sat.inclo)
        d_node = -beta * math.sin(u_axis) / sin_i if abs(sin_i) > 1e-6 else 0.0
        d_mean -= d_node * math.cos(sat.inclo)
    return _with_elements(sat, d_incl=d_incl, d_node=d_node, d_mean=d_mean)


def measure_offsets(nominal, truth, t_us: np.ndarray,
                    site: CameraSite) -> tuple[np.ndarray, np.ndarray]:
    """Return (along seconds, across arcsec) of `truth` relative to `nominal` at times.

    Each is (line1, line2), an sgp4 `Satrec` or a `SatelliteTruth`. From skyfield's
    apparent places: the along offset τ solves truth(t) ≈ nominal(t + τ) along the track
    (Newton steps), the across offset is what is left, positive to the left of the
    direction of travel (x = az·cos E right, y = el up). The truth's places are computed
    at `t_us` exactly (a new truth each round of `shifted_elements`: a whole grid chunk
    for one instant would cost ~100 times more); the nominal's, which the Newton steps
    ask for again and again near `t_us`, from its grid.
    """
    from .truth import SatelliteTruth

    where = _plain_site(site)
    nom, tru = (x if isinstance(x, SatelliteTruth) else SatelliteTruth.of(x, where)
                for x in (nominal, truth))
    t = np.asarray(t_us, np.int64)
    t_az, t_el = tru.exact(t)
    tau = np.zeros(len(t))
    for _ in range(4):
        x, y, ux, uy, rate = _relative(nom, t, tau, t_az, t_el)
        tau += (x * ux + y * uy) / rate
    x, y, ux, uy, _ = _relative(nom, t, tau, t_az, t_el)
    return tau, (-x * uy + y * ux)


def _plain_site(site: CameraSite) -> CameraSite:
    return CameraSite(site.lat_deg, site.lon_deg, site.height_m)


def _relative(nom, t, tau, t_az, t_el):
    shifted = t + np.round(tau * 1e6).astype(np.int64)
    az, el = nom.place(shifted)
    # the direction of travel *at* the nominal place: a central difference (a forward one
    # gives it 50 ms on, turned by up to 0.3° near a LEO's culmination, where the az/el
    # axes themselves turn at the azimuth rate × sin E: 0.2″ along for 40″ across)
    az1, el1 = nom.place(shifted - RATE_STEP_US // 2)
    az2, el2 = nom.place(shifted + RATE_STEP_US // 2)
    step_s = RATE_STEP_US / 1e6
    x = np.remainder(t_az - az + math.pi, 2 * math.pi) - math.pi
    x = x * np.cos(el) * 206264.80624709636
    y = (t_el - el) * 206264.80624709636
    vx = np.remainder(az2 - az1 + math.pi, 2 * math.pi) - math.pi
    vx = vx * np.cos(el) * 206264.80624709636 / step_s
    vy = (el2 - el1) * 206264.80624709636 / step_s
    rate = np.hypot(vx, vy)
    return x, y, vx / rate, vy / rate, rate
