"""The test element sets (tests/astro/data/sats_2024.tle) as Satellite objects."""

from pathlib import Path

from virtualstar.astro.satellites import Satellite

TLE_PATH = Path(__file__).parent / "data" / "sats_2024.tle"


def load_test_satellites() -> dict[str, Satellite]:
    lines = [ln.rstrip() for ln in TLE_PATH.read_text().splitlines() if ln.strip()]
    return {lines[i]: Satellite.from_tle(lines[i + 1], lines[i + 2], lines[i])
            for i in range(0, len(lines), 3)}
