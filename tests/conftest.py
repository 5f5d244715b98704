"""Settings for every test: offline astropy, and a private cache directory.

astropy never downloads (the IERS tables come from astropy-iers-data); virtualstar's cache
of the Earth-orientation table (virtualstar.astro.earth_orientation) goes to a directory of
this test session, not the user's: each session reads the table once, as a fresh machine does.
The pytest-xdist workers share their session's directory (they inherit it from the process
that started them), and the first of them to need the table reads it while the others wait.

numba's compiled kernels (cache=True: the emulator's tick loop, the server's error kernels,
SGP4's topocentric rotation) are compiled once before the first test, under a lock: in a
clean clone the workers and the servers they start would otherwise each compile them again
(~9 s of CPU apiece) until one of them had written numba's cache.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import tempfile

import pytest

_OWNER_VAR = "VIRTUALSTAR_TEST_CACHE_OWNER"  # the pid of the process that made the directory
if os.environ.get(_OWNER_VAR) and os.path.isdir(os.environ.get("VIRTUALSTAR_CACHE_DIR", "")):
    _CACHE = os.environ["VIRTUALSTAR_CACHE_DIR"]  # an xdist worker: its session's directory
else:
    _CACHE = tempfile.mkdtemp(prefix="virtualstar-test-cache-")
    os.environ["VIRTUALSTAR_CACHE_DIR"] = _CACHE  # before any test (or subprocess) reads it
    os.environ[_OWNER_VAR] = str(os.getpid())


def pytest_configure(config) -> None:
    from astropy.utils import iers

    iers.conf.auto_download = False


@pytest.fixture(scope="session", autouse=True)
def _earth_orientation_read_once_per_session():
    """Read astropy's IERS table into the session's cache once, whatever the workers (each
    reading costs ~2 s of CPU); later processes, servers included, load the cached arrays."""
    from virtualstar.astro.earth_orientation import EarthOrientation

    with open(os.path.join(_CACHE, "fill.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            EarthOrientation.from_astropy_iers_data()
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _compile_numba_kernels() -> None:
    """Compile (or load from numba's cache) every kernel the suite's processes use."""
    from catalogs import load_tle_file, sample_tle_path, select_satellite
    from mount_emulator.model import MountModel
    from virtualstar.astro import UtcTimes, load_site
    from virtualstar.astro.satellites import Satellite
    from virtualstar.server import on_target, tracking_errors

    MountModel(start_us=1_716_061_200_000_000).run(10)
    tracking_errors.warm_up()
    on_target.warm_up()
    iss = select_satellite(load_tle_file(sample_tle_path("stations")), "ISS")
    Satellite.from_tle(iss.line1, iss.line2).observe(
        UtcTimes.from_iso(["2024-05-18T19:55:00Z", "2024-05-18T19:55:01Z"]), load_site())


@pytest.fixture(scope="session", autouse=True)
def _numba_kernels_compiled_once_per_session():
    with open(os.path.join(_CACHE, "numba.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            _compile_numba_kernels()
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def pytest_unconfigure(config) -> None:
    if os.environ.get(_OWNER_VAR) == str(os.getpid()):
        shutil.rmtree(_CACHE, ignore_errors=True)
