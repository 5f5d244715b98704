"""One emulator + VSS rig for the tests of this folder: Poznań, 2024-05-18 19:40 UTC, x20."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from vss_rig import Rig  # noqa: E402

from virtualstar.astro import UtcTimes, load_site  # noqa: E402

RIG_START = "2024-05-18T19:40:00Z"  # Vega at ~30 deg, evening twilight, ISS TLE epoch + 1 day


@pytest.fixture(scope="session")
def rig():
    start_us = int(UtcTimes.from_iso([RIG_START]).to_unix_us()[0])
    r = Rig(start_us=start_us, site=load_site()).start()
    yield r
    r.close()
