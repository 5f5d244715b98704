"""What every test session needs once, started as the session starts: astropy's IERS table read
into the session's cache (virtualstar.astro.earth_orientation), and numba's compiled kernels
(cache=True: the emulator's tick loop, the server's error kernels, SGP4's topocentric
rotation) compiled into numba's cache beside their sources.

tests/conftest.py runs this script in a child process while the pytest-xdist workers start and
collect (~6 s of CPU each). Nothing waits for it: whoever needs a kernel or the table before
it is written makes it, as without it (numba's cache files and the IERS cache are written
whole or not at all), only later than the warm-up would. In a clean clone this saves each
worker, and each server a test starts early, its own compile (~9 s of CPU apiece) and each
worker its own IERS read (~2 s).

    python tests/session_warmup.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository's packages


def warm_up() -> None:
    """Fill the IERS cache and compile (or load from numba's cache) every kernel."""
    from catalogs import load_tle_file, sample_tle_path, select_satellite
    from mount_emulator.model import MountModel
    from virtualstar.astro import UtcTimes, load_site
    from virtualstar.astro.earth_orientation import EarthOrientation
    from virtualstar.astro.satellites import Satellite
    from virtualstar.server import on_target, tracking_errors

    EarthOrientation.from_astropy_iers_data()
    MountModel(start_us=1_716_061_200_000_000).run(10)
    tracking_errors.warm_up()
    on_target.warm_up()
    iss = select_satellite(load_tle_file(sample_tle_path("stations")), "ISS")
    Satellite.from_tle(iss.line1, iss.line2).observe(
        UtcTimes.from_iso(["2024-05-18T19:55:00Z", "2024-05-18T19:55:01Z"]), load_site())


if __name__ == "__main__":
    warm_up()
