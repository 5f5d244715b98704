"""Constants and helpers shared by the mount emulator tests."""

from __future__ import annotations

import math

import numpy as np

from mount_emulator.model import MountModel

START_US = 1_767_225_600_000_000  # 2026-01-01T00:00:00Z in µs since 1970
ONE_ARCSEC = math.pi / 180 / 3600  # radians
SIDEREAL_RATE = 7.2921159e-5  # rad/s, Earth rotation


def ticks(seconds: float) -> int:
    """Return the number of 100 µs ticks in ``seconds``."""
    return int(round(seconds * 10_000))


def star_altaz(ha_rad, dec_rad: float, lat_rad: float):
    """Return (azimuth from north through east, elevation) of a star, radians.

    Plain spherical trigonometry, written here independently of the emulator.
    """
    ha = np.asarray(ha_rad)
    sin_el = np.sin(lat_rad) * np.sin(dec_rad) + np.cos(lat_rad) * np.cos(dec_rad) * np.cos(ha)
    el = np.arcsin(sin_el)
    y = -np.cos(dec_rad) * np.sin(ha)
    x = np.sin(dec_rad) * np.cos(lat_rad) - np.cos(dec_rad) * np.cos(ha) * np.sin(lat_rad)
    return np.arctan2(y, x), el


def holding_mount() -> MountModel:
    """Return a powered mount that has held still for 1 s."""
    m = MountModel(start_us=START_US)
    m.power_on()
    m.run(ticks(1.0))
    return m


def push_smooth_ramp(m: MountModel, rate: float, accel: float, seconds: float,
                     spacing_s: float = 0.1) -> float:
    """Push a ramp on both axes: 0.1 s at rest, accelerate at ``accel`` to ``rate``, then constant.

    Returns the time (s after now) of the last point. Positions are relative to the
    current references; rates are given with the points.
    """
    t_acc = rate / accel
    t0 = m.mount_time_us
    n = int(round(seconds / spacing_s))
    t = t0 + np.arange(1, n + 1) * int(spacing_s * 1e6)
    s = np.maximum((t - t0) * 1e-6 - 0.1, 0.0)
    pos = np.where(s < t_acc, 0.5 * accel * s**2, rate * (s - t_acc / 2))
    vel = np.where(s < t_acc, accel * s, rate)
    az0 = m.state[m_index(0)]
    el0 = m.state[m_index(1)]
    assert m.traj_push(t, az0 + pos, el0 + pos, vel, vel) == n
    return n * spacing_s


def m_index(axis: int) -> int:
    from mount_emulator import layout as L

    return L.state_index(axis, L.A_REF)
