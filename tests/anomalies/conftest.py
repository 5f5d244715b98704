"""Recordings shared by the anomaly tests (each made once per session, whatever the
workers: ~8 s of CPU apiece)."""

from __future__ import annotations

from pathlib import Path

import pytest
from anomaly_helpers import CASES, FAULT_MINUTES, LIVE_CASE, MINUTES, made_once, record


def _recorded(tmp_path_factory, name: str, injections, *, minutes: float = MINUTES,
              detect: bool = False) -> tuple[Path, int]:
    def build(directory: Path):
        store, t0 = record(directory, injections, minutes=minutes, detect=detect)
        return str(store), t0

    store, t0 = made_once(tmp_path_factory, name, build)
    return Path(store), t0


def _case(tmp_path_factory, name: str) -> tuple[Path, int]:
    return _recorded(tmp_path_factory, "sine-" + name.replace(" ", "-").replace(",", ""),
                     CASES[name][0], minutes=FAULT_MINUTES, detect=name == LIVE_CASE)


@pytest.fixture(scope="session")
def clean_recording(tmp_path_factory):
    """A 30-minute sine recording with nothing injected: (store, trajectory start µs)."""
    return _recorded(tmp_path_factory, "sine-clean", ())


@pytest.fixture(scope="session", params=sorted(CASES))
def faulty_recording(request, tmp_path_factory):
    """(case name, store, trajectory start µs) of each fault case (FAULT_MINUTES long)."""
    return (request.param, *_case(tmp_path_factory, request.param))


@pytest.fixture(scope="session")
def live_recording(tmp_path_factory):
    """(store, trajectory start µs) of LIVE_CASE, recorded with the detectors live."""
    return _case(tmp_path_factory, LIVE_CASE)
