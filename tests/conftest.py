"""Settings for every test: offline astropy, a private cache directory, and what every session
needs once (tests/session_warmup.py), made before the first test.

astropy never downloads (the IERS tables come from astropy-iers-data); virtualstar's cache
of the Earth-orientation table (virtualstar.astro.earth_orientation) goes to a directory of
this test session, not the user's: each session reads the table once, as a fresh machine does.
The pytest-xdist workers share their session's directory (they inherit it from the process
that started them).
"""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

_OWNER_VAR = "VIRTUALSTAR_TEST_CACHE_OWNER"  # the pid of the process that made the directory
if os.environ.get(_OWNER_VAR) and os.path.isdir(os.environ.get("VIRTUALSTAR_CACHE_DIR", "")):
    _CACHE = os.environ["VIRTUALSTAR_CACHE_DIR"]  # an xdist worker: its session's directory
else:
    _CACHE = tempfile.mkdtemp(prefix="virtualstar-test-cache-")
    os.environ["VIRTUALSTAR_CACHE_DIR"] = _CACHE  # before any test (or subprocess) reads it
    os.environ[_OWNER_VAR] = str(os.getpid())
_WARMUP_LOCK = os.path.join(_CACHE, "warmup.lock")
_warmup: subprocess.Popen | None = None


def pytest_configure(config) -> None:
    global _warmup
    from astropy.utils import iers

    iers.conf.auto_download = False
    if hasattr(config, "workerinput") or _warmup is not None:
        return  # an xdist worker: the process that started it started the warm-up
    _warmup = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("session_warmup.py")), _WARMUP_LOCK],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
    _warmup.stdout.readline()  # it holds the lock (or has died) before any worker can ask


def pytest_collection_finish(session) -> None:
    """Wait for the warm-up before the first test (a hook: no test's timeout counts it)."""
    with open(_WARMUP_LOCK, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        fcntl.flock(lock, fcntl.LOCK_UN)


def pytest_unconfigure(config) -> None:
    if _warmup is not None:
        if _warmup.poll() is None:
            _warmup.kill()
        _warmup.wait()
        _warmup.stdout.close()
    if os.environ.get(_OWNER_VAR) == str(os.getpid()):
        shutil.rmtree(_CACHE, ignore_errors=True)
