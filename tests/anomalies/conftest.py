"""Recordings shared by the anomaly tests (made once per session, whatever the workers):
the clean 30-minute sine recording, ~5 s of CPU, and the fault cases forked off it at
their injections (virtualstar/forking.py), ~2 s each. LIVE_CASE's variant runs the
detectors live: they are switched on in its process at the fork, catch up on the clean
recording until then and see the rest as it comes (the clean recording does not run them:
they would cost it 2.5 s, and each other case, which would fit them anew, 2 s more)."""

from __future__ import annotations

from pathlib import Path

import pytest
from anomaly_helpers import AT_S, CASES, LIVE_CASE, STOP_MINUTES, made_once, record

from virtualstar.recorder.experiment import SineBranch


def _slug(name: str) -> str:
    return name.replace(" ", "-").replace(",", "")


FORKED = sorted(CASES)


@pytest.fixture(scope="session")
def sine_recordings(tmp_path_factory) -> dict[str, tuple[Path, int]]:
    """{"clean" or a case name of CASES: (store, trajectory start µs)}: the clean
    recording, and each case forked off it at AT_S and stopped at STOP_MINUTES (LIVE_CASE
    with the detectors live)."""

    def build(directory: Path):
        result = record(directory / "clean", (), branches=tuple(
            SineBranch(AT_S, CASES[name][0], str(directory / _slug(name)),
                       STOP_MINUTES[name] * 60, detect=name == LIVE_CASE)
            for name in FORKED))
        made = {"clean": [str(result.store), result.trajectory_t0_us]}
        for name, branch in zip(FORKED, result.branches, strict=True):
            made[name] = [branch["store"], branch["trajectory_t0_us"]]
        return made

    made = made_once(tmp_path_factory, "sine", build)
    return {name: (Path(store), t0) for name, (store, t0) in made.items()}


@pytest.fixture(scope="session")
def live_recording(sine_recordings) -> tuple[Path, int]:
    """(store, trajectory start µs) of LIVE_CASE, whose variant ran the detectors live."""
    return sine_recordings[LIVE_CASE]


@pytest.fixture(scope="session")
def clean_recording(sine_recordings):
    """A 30-minute sine recording with nothing injected: (store, trajectory start µs)."""
    return sine_recordings["clean"]


@pytest.fixture(scope="session", params=sorted(CASES))
def faulty_recording(request, sine_recordings, tmp_path_factory):
    """(case name, store, trajectory start µs) of each fault case (STOP_MINUTES long)."""
    return (request.param, *sine_recordings[request.param])
