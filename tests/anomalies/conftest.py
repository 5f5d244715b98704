"""Recordings shared by the anomaly tests (each made once per session: ~5 s apiece)."""

from __future__ import annotations

import pytest
from anomaly_helpers import CASES, record


@pytest.fixture(scope="session")
def clean_recording(tmp_path_factory):
    """A 30-minute sine recording with nothing injected: (store, trajectory start µs)."""
    return record(tmp_path_factory.mktemp("clean"), ())


@pytest.fixture(scope="session", params=sorted(CASES))
def faulty_recording(request, tmp_path_factory):
    """(case name, store, trajectory start µs) of each fault case."""
    injections, _ = CASES[request.param]
    store, t0 = record(tmp_path_factory.mktemp("fault"), injections)
    return request.param, store, t0
