"""The rate loop's join: the run-up meets the path with its place *and* its rate.

A rate-driven mount joins a path from a run-up line at the path's rate at the join
(rate_loop's module doc). On main the run-up ran at half that rate: the path's rate was
a central difference around the join, and a finite path (a pass cut to one side of the
meridian) stands still before its start, so half the difference was lost. The mount
then met a rate step of half the path's rate (~900″/s for an ISS pass) at the join,
which the loop could only remove after it (an INDI pass judged from 2 s after the join
failed once at 350″ → 1″). Truth: the path's own spline derivative (alt-az: the native
axes are the path's), and for RA/Dec the rate of the same place function well inside
the path.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from virtualstar.astro import EarthOrientation, Site
from virtualstar.server import Points, TablePath
from virtualstar.server.link_interface import MountCapabilities
from virtualstar.server.rate_loop import NativeFrame, _run_up_points

ARCSEC = math.pi / 180 / 3600


def a_pass(start_us: int = 1_750_000_000_000_000, seconds: float = 60.0) -> TablePath:
    """A fast curved path (up to ~1°/s) in az/el, as the VSS's pass paths are: a table."""
    t = start_us + np.arange(0, int(seconds * 1e6) + 1, 500_000, dtype=np.int64)
    s = (t - start_us) / 1e6
    w, f = 0.03, 0.5
    az = 1.0 + 0.3 * np.sin(w * s + f)
    el = 0.8 + 0.2 * np.cos(w * s + f)
    return TablePath(Points(t, az, el, 0.3 * w * np.cos(w * s + f),
                            -0.2 * w * np.sin(w * s + f)))


def test_the_native_rate_at_the_start_of_a_finite_path_is_the_paths_own():
    path = a_pass()
    frame = NativeFrame(MountCapabilities(backend="alpaca", geometry="altaz", rate_axes=True),
                        None, None)
    t = np.array([path.start_us, path.start_us + 30_000_000, path.end_us], np.int64)
    got = frame.sample(path, t)
    exact = path.sample(t)
    # a difference over 0.2 s, one-sided at the ends: off by at most accel × 0.1 s
    accel = 0.3 * 0.03**2 * 0.1
    assert got.az_rate_rad_s == pytest.approx(exact.az_rate_rad_s, abs=accel)
    assert got.el_rate_rad_s == pytest.approx(exact.el_rate_rad_s, abs=accel)


@pytest.mark.parametrize("geometry", ["altaz", "german"])
def test_the_run_up_meets_the_path_with_its_rate(geometry):
    path = a_pass()
    caps = MountCapabilities(backend="indi", geometry=geometry, rate_axes=True)
    site = Site(lat_deg=48.0, lon_deg=11.0, height_m=500.0)
    frame = NativeFrame(caps, site, EarthOrientation.from_astropy_iers_data())
    join, run_up = path.start_us, 2_000_000
    # the demand 1 ms either side of the join: run-up line, then the path
    t = np.array([join - 1_000, join + 1_000], np.int64)
    p = _run_up_points(frame, path, join, run_up, t)
    # the path's rate at the join: its native place 2 ms apart, just after the join
    a = frame.place(path, np.array([join, join + 2_000], np.int64))
    ref = [(a[0][1] - a[0][0]) / 0.002, (a[1][1] - a[1][0]) / 0.002]
    speed = math.hypot(*ref)
    assert speed > 500 * ARCSEC  # a fast path (the test can fail)
    for rates, r in ((p.az_rate_rad_s, ref[0]), (p.el_rate_rad_s, ref[1])):
        # the demand's rate either side of the join is the path's (off by its acceleration,
        # < 0.01 °/s², over the 0.1-s difference); on main the run-up had half of it
        assert abs(rates[0] - r) < 0.01 * speed, (rates / ARCSEC, r / ARCSEC)
        assert abs(rates[1] - r) < 0.01 * speed, (rates / ARCSEC, r / ARCSEC)
    # and the place is continuous: 2 ms at the path's rate apart, no step
    step = np.hypot(p.az_rad[1] - p.az_rad[0], p.el_rad[1] - p.el_rad[0])
    assert step < 0.002 * speed * 1.05
