"""Settings for every test: offline astropy, a private cache directory, a warm-up of what every
session needs once (tests/session_warmup.py), the session's fork server for the pytest-xdist
workers and the `vs`, emulator and device processes the tests start (tests/forkserver.py), and
the longest modules first.

astropy never downloads (the IERS tables come from astropy-iers-data); virtualstar's cache
of the Earth-orientation table (virtualstar.astro.earth_orientation) goes to a directory of
this test session, not the user's: each session reads the table once, as a fresh machine does.
The pytest-xdist workers share their session's directory (they inherit it from the process
that started them).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

# OpenBLAS's threads, one per core, before numpy loads it here or in any process the suite
# starts (xdist workers and `vs` subprocesses inherit the environment). The suite runs more
# worker processes than the host has cores, and the threads a worker's matrix product starts
# spin while they wait for a core: the current model's friction search with its cogging
# terms took 0.43 s of CPU with two threads on a loaded 2-core host and 0.02 s with one,
# and tests/anomalies 76 s instead of 83 s (benchmarks/bench_suite.py, 2 workers). A user's
# own setting stays.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import forkserver  # noqa: E402
from session_order import longest_first  # noqa: E402

_OWNER_VAR = "VIRTUALSTAR_TEST_CACHE_OWNER"  # the pid of the process that made the directory
if os.environ.get(_OWNER_VAR) and os.path.isdir(os.environ.get("VIRTUALSTAR_CACHE_DIR", "")):
    _CACHE = os.environ["VIRTUALSTAR_CACHE_DIR"]  # an xdist worker: its session's directory
else:
    _CACHE = tempfile.mkdtemp(prefix="virtualstar-test-cache-")
    os.environ["VIRTUALSTAR_CACHE_DIR"] = _CACHE  # before any test (or subprocess) reads it
    os.environ[_OWNER_VAR] = str(os.getpid())
# how long the workers wait for the fork server to serve before they start fresh instead (it
# takes 1–3 s of CPU; a loaded host may take several times that)
FORKSERVER_START_S = 60.0
_warmup: subprocess.Popen | None = None
_forkserver: subprocess.Popen | None = None


def pytest_configure(config) -> None:
    global _warmup, _forkserver
    from astropy.utils import iers

    iers.conf.auto_download = False
    if hasattr(config, "workerinput") or _warmup is not None:
        return  # an xdist worker: the process that started it started the warm-up
    _warmup = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("session_warmup.py"))],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    # the session's fork server (tests/forkserver.py), found by the workers through the
    # environment they inherit; until it serves, forkserver.popen starts fresh interpreters
    # (as it always does with VIRTUALSTAR_TEST_FORKSERVER=off)
    if os.environ.get(forkserver.SOCKET_ENV_VAR) == "off":
        return
    socket_path = os.path.join(_CACHE, "forkserver.sock")
    os.environ[forkserver.SOCKET_ENV_VAR] = socket_path
    _forkserver = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("forkserver.py")), socket_path],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    _fork_the_workers(_forkserver, socket_path)


def _fork_the_workers(server: subprocess.Popen, socket_path: str) -> None:
    """Start pytest-xdist's workers as forks of the fork server too: they would otherwise each
    import pytest, astropy, scipy and our packages again as they start and collect
    (forkserver.FOR_WORKERS). execnet starts a worker as `python -u -c BOOTSTRAP` with piped
    standard input and output (execnet.gateway_io.Popen2IOMaster); this starts that same
    command through forkserver.popen, once the server serves (it imports for a second or two
    as the session starts, while the warm-up runs), or fresh as before if it never does."""
    from execnet import gateway_io

    def start(io: gateway_io.Popen2IOMaster, args: list[str], execmodel) -> None:
        forkserver.wait_serving(socket_path, FORKSERVER_START_S, server)
        io.popen = forkserver.popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        super(gateway_io.Popen2IOMaster, io).__init__(io.popen.stdin, io.popen.stdout,
                                                      execmodel=execmodel)

    gateway_io.Popen2IOMaster.__init__ = start


def pytest_collection_modifyitems(session, config, items) -> None:
    """The longest modules first (tests/session_order.py)."""
    longest_first(items)


def pytest_unconfigure(config) -> None:
    for helper in (_warmup, _forkserver):
        if helper is not None:
            if helper.poll() is None:
                helper.kill()
            helper.wait()
    if os.environ.get(_OWNER_VAR) == str(os.getpid()):
        shutil.rmtree(_CACHE, ignore_errors=True)
