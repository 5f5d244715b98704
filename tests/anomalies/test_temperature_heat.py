"""The temperature detector against the heat the winding's current explains.

A synthetic winding written out from the emulator's thermal law (τ·dT/dt = I²·R·R_th +
P_injected·R_th − (T − T_ambient), R = 1.6 Ω, R_th = 0.8 K/W, τ = 900 s: 5.12 K/h per A²
at ambient), its current switching between a light and a heavy load every 4 minutes (an
elevation axis holding the tube at high and then low elevations): the temperature's
trend swings by ±1.2 K/h with the load, so the reference's usual trend alone has a wide
limit; the detector takes the current's heat out of the trend first.
"""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_store import write_store

from virtualstar.anomalies import detect_anomalies

T0_US = 1_772_395_200_000_000
RATE_HZ = 1000.0
NIGHT_S = 2400.0
FAULT_S = 1200.0
R_OHM, RTH_K_W, TAU_S, AMBIENT_C = 1.6, 0.8, 900.0, 15.0
HEAT_K_H_PER_A2 = R_OHM * RTH_K_W / TAU_S * 3600.0  # 5.12
LIGHT_A, HEAVY_A, BLOCK_S = 0.1, 0.7, 240.0


def _night(path, *, heat_growth_w_h: float = 0.0):
    ts = np.arange(round(NIGHT_S * RATE_HZ)) / RATE_HZ
    current = np.where(np.floor(ts / BLOCK_S) % 2 == 0, LIGHT_A, HEAVY_A)
    injected = heat_growth_w_h / 3600.0 * np.clip(ts - FAULT_S, 0.0, None)
    # the thermal law integrated exactly per 1-ms step (the drive is constant within one)
    k = np.exp(-1.0 / (RATE_HZ * TAU_S))
    target = AMBIENT_C + (current ** 2 * R_OHM + injected) * RTH_K_W
    temp = np.empty_like(ts)
    t_now = AMBIENT_C
    for j0 in range(0, len(ts), 1000):  # a second at a time: the drive hardly moves
        j1 = min(j0 + 1000, len(ts))
        n = np.arange(1, j1 - j0 + 1)
        temp[j0:j1] = target[j0] + (t_now - target[j0]) * k ** n
        t_now = temp[j1 - 1]
    rng = np.random.default_rng(8)
    temp = temp + rng.normal(0.0, 0.002, len(ts))
    current = current + rng.normal(0.0, 2e-4, len(ts))
    position = 0.7 + 5e-5 * ts  # a sidereal track throughout
    sig = {"axis.el.position": position, "axis.el.current": current,
           "axis.el.temperature": temp}
    reader = write_store(path, T0_US, ts, sig, RATE_HZ)
    first, last = reader.time_range()
    return detect_anomalies(reader, first, last + 1)


def _temperature(report):
    check = next(c for c in report.checks if c.detector == "temperature" and c.axis == "el")
    flags = [x for x in report.anomalies if x.kind == "temperature" and x.axis == "el"]
    return check, flags


@pytest.fixture(scope="module")
def clean_report(tmp_path_factory):
    return _night(tmp_path_factory.mktemp("clean_heat") / "s")


def test_the_heat_of_the_current_is_fitted_and_leaves_the_floor_as_the_limit(clean_report):
    check, flags = _temperature(clean_report)
    assert flags == []
    assert "axis.el.current" in check.signals
    heating = float(check.reason.split("heating ")[1].split(" K/h")[0])
    # the window slopes hold the cooling towards ambient too (up to 0.6 K warm here):
    # the fitted heating is the law's within a third
    assert heating == pytest.approx(HEAT_K_H_PER_A2, rel=0.35)
    # about the floor (3 K/h), not 8 σ of the load's swing of the trend
    assert float(check.reason.split("±")[1].split(" K/h")[0]) < 3.5
    trace = next(t for t in clean_report.traces if t.name == "el temperature")
    assert np.nanmax(trace.score) < 0.6


def test_a_heat_growth_smaller_than_the_loads_swing_is_found(tmp_path):
    # 12 W/h: after 9 minutes the winding warms ≈ 4 K/h faster, less than the load's
    # swing of the trend (≈ 2.5 K/h peak to peak, ≈ 10 K/h as 8 robust σ), above the floor
    _, flags = _temperature(_night(tmp_path / "s", heat_growth_w_h=12.0))
    assert flags
    first = min(x.start_us for x in flags)
    assert T0_US + FAULT_S * 1e6 <= first <= T0_US + (FAULT_S + 720.0) * 1e6
