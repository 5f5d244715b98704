"""Settings for every test: offline astropy, and a private cache directory.

astropy never downloads (the IERS tables come from astropy-iers-data); virtualstar's cache
of the Earth-orientation table (virtualstar.astro.earth_orientation) goes to a directory of
this test session, not the user's: each session reads the table once, as a fresh machine does.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_CACHE = tempfile.mkdtemp(prefix="virtualstar-test-cache-")
os.environ["VIRTUALSTAR_CACHE_DIR"] = _CACHE  # before any test (or subprocess) reads it


def pytest_configure(config) -> None:
    from astropy.utils import iers

    iers.conf.auto_download = False


def pytest_unconfigure(config) -> None:
    shutil.rmtree(_CACHE, ignore_errors=True)
