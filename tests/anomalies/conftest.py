"""Recordings shared by the anomaly tests (each made once per session, whatever the
workers: ~5 s apiece)."""

from __future__ import annotations

from pathlib import Path

import pytest
from anomaly_helpers import CASES, made_once, record


def _recorded(tmp_path_factory, name: str, injections) -> tuple[Path, int]:
    def build(directory: Path):
        store, t0 = record(directory, injections)
        return str(store), t0

    store, t0 = made_once(tmp_path_factory, name, build)
    return Path(store), t0


@pytest.fixture(scope="session")
def clean_recording(tmp_path_factory):
    """A 30-minute sine recording with nothing injected: (store, trajectory start µs)."""
    return _recorded(tmp_path_factory, "sine-clean", ())


@pytest.fixture(scope="session", params=sorted(CASES))
def faulty_recording(request, tmp_path_factory):
    """(case name, store, trajectory start µs) of each fault case."""
    injections, _ = CASES[request.param]
    store, t0 = _recorded(tmp_path_factory, "sine-" + request.param.replace(" ", "-"),
                          injections)
    return request.param, store, t0
