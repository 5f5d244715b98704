"""Earth satellites from TLE or OMM elements: SGP4 to observed az/el for arrays of times.

Pipeline per time t (all vectorised over times):

1. SGP4 (`Satrec.sgp4_array`, UTC Julian dates) gives position and velocity in
   TEME, a quasi-inertial frame.
2. TEME → ITRS at t: rotation by GMST (IAU 1982, `erfa.gmst82` of UT1, the
   frame SGP4 is defined in) then polar motion (`erfa.pom00`, IERS x, y).
   Both position and *inertial* velocity are expressed in these axes, i.e. in
   the inertial frame momentarily aligned with the ITRS at t.
3. Light time: the satellite is seen where it was at t − τ, τ = |ρ|/c, solved
   by iteration on ρ = r_sat − v_sat·τ − r_site (the ½aτ² term is < 1 mm).
4. Diurnal aberration: the site moves at ω × r_site (≈ 0.3 km/s) through
   that inertial frame (`erfa.ab`). Annual aberration and the Earth's orbital
   motion during τ cancel for a geocentric object, so neither is applied.
5. ITRS → local north/east/up of the WGS84 site; refraction as for stars.

Sizes for a LEO pass (issue 4): light time + aberration up to ~5″, polar
motion ~4″, UT1−UTC ~6″; the tests compare with skyfield at 0.01″.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import erfa
import numba
import numpy as np
from sgp4 import omm
from sgp4.api import SGP4_ERRORS, Satrec

from .constants import C_M_S, DAY_S, UNIX_EPOCH_JD
from .earth_orientation import EarthOrientation
from .exceptions import SatelliteError
from .observed import Observation, observe_enu
from .site import Site
from .timescales import UtcTimes, day_length_s

#: Rate of the Earth rotation angle, rad per UT1 second (IERS 2010, eq. 5.15 via ERA).
ERA_RATE_RAD_S = 2.0 * math.pi * 1.00273781191135448 / DAY_S
#: Spacing of the Earth-orientation nodes (must divide a day: nodes sit on UTC hours).
_NODE_S = 3600.0


@dataclass(frozen=True)
class SatelliteState:
    """Topocentric apparent direction of a satellite in the site's horizon frame.

    enu: (N,3) unit vectors (north, east, up), unrefracted; enu_rate: their
    time derivatives (1/s); range_m: distance site → satellite at emission.
    """

    enu: np.ndarray
    enu_rate: np.ndarray
    range_m: np.ndarray


@dataclass(frozen=True)
class Satellite:
    """An Earth satellite propagated with SGP4 (elements from a TLE or OMM)."""

    name: str
    satrec: Satrec

    @classmethod
    def from_tle(cls, line1: str, line2: str, name: str = "") -> Satellite:
        """Build from the two TLE lines (checksums are the loader's job: catalogs)."""
        try:
            satrec = Satrec.twoline2rv(line1.rstrip(), line2.rstrip())
        except ValueError as exc:
            raise SatelliteError(f"bad TLE for {name or 'satellite'}: {exc}") from None
        return cls(name or f"NORAD {satrec.satnum}", satrec)

    @classmethod
    def from_omm(cls, fields: Mapping[str, Any]) -> Satellite:
        """Build from one OMM record (CelesTrak JSON/CSV keys such as MEAN_MOTION)."""
        satrec = Satrec()
        try:
            omm.initialize(satrec, dict(fields))
        except (KeyError, ValueError) as exc:
            raise SatelliteError(f"bad OMM record: missing or invalid {exc}") from None
        return cls(str(fields.get("OBJECT_NAME", f"NORAD {satrec.satnum}")), satrec)

    @classmethod
    def from_record(cls, record: Any) -> Satellite:
        """Build from a catalogs TleRecord (OMM records keep their full precision)."""
        return cls(record.name.strip(), record.satrec())

    @property
    def epoch(self) -> UtcTimes:
        """Return the epoch of the elements (UTC; SGP4 counts it continuously, POSIX-like)."""
        whole = math.floor(self.satrec.jdsatepoch - 0.5) + 0.5  # 0h of the epoch's day
        sec = ((self.satrec.jdsatepoch - whole) + self.satrec.jdsatepochF) * DAY_S
        return UtcTimes.from_posix_days(np.array([round(whole - UNIX_EPOCH_JD)]), np.array([sec]))

    def teme_km(self, times: UtcTimes) -> tuple[np.ndarray, np.ndarray]:
        """Return SGP4 TEME position (km) and velocity (km/s), each (N,3).

        Raises SatelliteError when SGP4 fails at any of the times (decay, ...).
        """
        # SGP4 counts UTC continuously (POSIX-like, as skyfield feeds it): on a day that ends
        # in a leap second ERFA's quasi-JD would run 1/86 400 slow all day
        jd, fraction = times.posix_jd()
        err, r, v = self.satrec.sgp4_array(np.ascontiguousarray(jd, dtype=float),
                                           np.ascontiguousarray(fraction, dtype=float))
        if err.any():
            bad = np.flatnonzero(err)
            code = int(err[bad[0]])
            raise SatelliteError(
                f"SGP4 failed for {self.name} at {len(bad)} of {len(err)} times, first at "
                f"{times[bad[0]].iso()[0]}: {SGP4_ERRORS.get(code, code)}", code)
        return r, v

    def topocentric(self, times: UtcTimes, site: Site,
                    eop: EarthOrientation | None = None) -> SatelliteState:
        """Return the unrefracted topocentric apparent direction, rates and range."""
        eop = eop or EarthOrientation.from_astropy_iers_data()
        r_km, v_km_s = self.teme_km(times)
        return teme_to_topocentric(r_km, v_km_s, times, site, eop)

    def observe(self, times: UtcTimes, site: Site,
                eop: EarthOrientation | None = None) -> Observation:
        """Return observed az/el and rates (refraction per the site)."""
        state = self.topocentric(times, site, eop)
        return observe_enu(state.enu, state.enu_rate, site)


def teme_to_topocentric(r_km: np.ndarray, v_km_s: np.ndarray, times: UtcTimes, site: Site,
                        eop: EarthOrientation) -> SatelliteState:
    """Turn TEME states (km, km/s; (N,3)) into topocentric apparent directions.

    See the module docstring for the chain of corrections.
    """
    # Earth orientation on hourly nodes aligned to UTC hours: UT1-UTC and polar motion
    # are linear between the daily IERS values, so GMST (linear in UT1 to 1e-15 rad over
    # an hour) and the polar-motion matrix are linear between the nodes too.
    # Nodes and times are placed in elapsed SI seconds: the Earth turns through a leap
    # second too, so the last hour of 2016-12-31 is 3 601 s of rotation (POSIX seconds
    # put 23:30 half a second, 23:59 a whole second of rotation off).
    days, sec_of_day = times[0].posix_days()
    hour_s = np.floor(np.minimum(sec_of_day, DAY_S - 1.0) / 3600.0) * 3600.0
    ref = UtcTimes.from_posix_days(days, hour_s)  # a UTC hour
    sec = times.si_seconds_since(float(ref.jd1[0]), float(ref.jd2[0]))
    k1 = max(math.ceil(float(sec.max()) / _NODE_S), 1)
    k0 = min(math.floor(float(sec.min()) / _NODE_S), k1 - 1)
    node_s = np.arange(k0, k1 + 1) * _NODE_S
    nodes = ref.si_shifted(node_s)
    dut1, xp, yp = eop.interpolate(nodes.jd1, nodes.jd2)
    # ERFA's utcut1 keeps UT1 right on a day that ends in a leap second
    node_theta = np.unwrap(erfa.gmst82(*nodes.ut1(dut1)))
    sp = erfa.sp00(nodes.jd1, nodes.jd2)
    enu_m = site.enu_matrix()
    node_mats = np.ascontiguousarray(enu_m @ erfa.pom00(xp, yp, sp))  # PEF → ITRS → ENU
    site_itrs = site.itrs_position_m()
    site_enu = enu_m @ site_itrs
    omega_itrs = np.array([0.0, 0.0, ERA_RATE_RAD_S])
    site_vel = enu_m @ np.cross(omega_itrs, site_itrs)
    # (north, east, up) is a left-handed frame: there, ω × r = -(ω_enu × r_enu).
    minus_omega_enu = -(enu_m @ omega_itrs)
    unit, rate, dist = _topocentric_kernel(
        np.ascontiguousarray(r_km), np.ascontiguousarray(v_km_s), sec, float(node_s[0]),
        _NODE_S, node_theta, node_mats, site_enu, minus_omega_enu, C_M_S,
        _since_leap_second_s(times))
    beta = site_vel / C_M_S
    apparent = erfa.ab(unit, beta, 1.0, math.sqrt(1.0 - beta @ beta))
    return SatelliteState(enu=apparent, enu_rate=rate, range_m=dist)


#: `_since_leap_second_s` for an instant with no leap second within a day of it.
_NO_LEAP_S = -1e9


def _since_leap_second_s(times: UtcTimes) -> np.ndarray:
    """Return SI seconds since the start of the leap second of the instant's day or the
    day before (negative before it), or _NO_LEAP_S when neither day ends in one.

    SGP4's count holds through a leap second (UtcTimes.posix_jd), so the satellite's
    motion during the light time is the held count's motion, not the real seconds'.
    """
    days, sec = times.posix_days()
    jd = UNIX_EPOCH_JD + days.astype(float)
    if np.ndim(day_length_s(np.concatenate([jd - 1.0, jd]))) == 0:
        return np.full(len(times), _NO_LEAP_S)  # no leap second near: the fast path
    today = np.asarray(day_length_s(jd)) > DAY_S
    yesterday = np.asarray(day_length_s(jd - 1.0)) > DAY_S
    return np.where(today, sec - DAY_S, np.where(yesterday, sec + 1.0, _NO_LEAP_S))


@numba.njit(cache=True, fastmath=False, nogil=True)
def _held_s(u, tau):  # pragma: no cover - compiled
    """SGP4's count between u - tau and u (u: SI seconds since a leap second began):
    the count stands still for the leap second's one SI second."""
    a = u if u < 0.0 else (0.0 if u < 1.0 else u - 1.0)
    b = u - tau
    b = b if b < 0.0 else (0.0 if b < 1.0 else b - 1.0)
    return a - b


@numba.njit(cache=True, fastmath=False, nogil=True)
def _topocentric_kernel(r_km, v_km_s, sec, node0_s, node_step_s, node_theta, node_mats,
                        site_enu, omega_enu, c_m_s, leap_u):  # pragma: no cover - compiled
    """Rotate TEME by GMST and apply polar motion (both linear between the hourly nodes),
    move to site ENU axes, correct light time; return unit vectors, their Earth-fixed
    rates (1/s) and distances (m)."""
    # omega_enu is the Earth's rotation vector with the sign that makes omega_enu x r the
    # ENU components of the ITRS velocity omega x r (see the caller).
    n = r_km.shape[0]
    last = node_mats.shape[0] - 2
    unit = np.empty((n, 3))
    rate = np.empty((n, 3))
    dist = np.empty(n)
    pef = np.empty(3)
    vpef = np.empty(3)
    for i in range(n):
        u = (sec[i] - node0_s) / node_step_s
        k = min(max(int(math.floor(u)), 0), last)
        f = u - k
        theta = node_theta[k] + f * (node_theta[k + 1] - node_theta[k])
        c = math.cos(theta)
        s = math.sin(theta)
        x, y, z = r_km[i, 0] * 1e3, r_km[i, 1] * 1e3, r_km[i, 2] * 1e3
        vx, vy, vz = v_km_s[i, 0] * 1e3, v_km_s[i, 1] * 1e3, v_km_s[i, 2] * 1e3
        pef[0] = c * x + s * y
        pef[1] = c * y - s * x
        pef[2] = z
        vpef[0] = c * vx + s * vy
        vpef[1] = c * vy - s * vx
        vpef[2] = vz
        p0 = p1 = p2 = w0 = w1 = w2 = 0.0
        for j in range(3):
            m0 = node_mats[k, 0, j] + f * (node_mats[k + 1, 0, j] - node_mats[k, 0, j])
            m1 = node_mats[k, 1, j] + f * (node_mats[k + 1, 1, j] - node_mats[k, 1, j])
            m2 = node_mats[k, 2, j] + f * (node_mats[k + 1, 2, j] - node_mats[k, 2, j])
            p0 += m0 * pef[j]
            p1 += m1 * pef[j]
            p2 += m2 * pef[j]
            w0 += m0 * vpef[j]
            w1 += m1 * vpef[j]
            w2 += m2 * vpef[j]
        r0 = p0 - site_enu[0]
        r1 = p1 - site_enu[1]
        r2 = p2 - site_enu[2]
        tau = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) / c_m_s
        for _ in range(2):
            dt = _held_s(leap_u[i], tau)
            a0 = r0 - w0 * dt
            a1 = r1 - w1 * dt
            a2 = r2 - w2 * dt
            tau = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2) / c_m_s
        dt = _held_s(leap_u[i], tau)
        r0 -= w0 * dt
        r1 -= w1 * dt
        r2 -= w2 * dt
        d = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        dist[i] = d
        unit[i, 0] = r0 / d
        unit[i, 1] = r1 / d
        unit[i, 2] = r2 / d
        # Earth-fixed velocity = inertial velocity - omega x position.
        rate[i, 0] = (w0 - (omega_enu[1] * p2 - omega_enu[2] * p1)) / d
        rate[i, 1] = (w1 - (omega_enu[2] * p0 - omega_enu[0] * p2)) / d
        rate[i, 2] = (w2 - (omega_enu[0] * p1 - omega_enu[1] * p0)) / d
    return unit, rate, dist
