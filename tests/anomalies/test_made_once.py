"""made_once, the session cache of the anomaly tests' recordings: built once, shared by
every caller, and a wait for another builder that cannot hang."""

from __future__ import annotations

import fcntl
import time

import pytest
from anomaly_helpers import made_once


class _Factory:
    """tmp_path_factory's two methods that made_once uses, under one test's tmp_path."""

    def __init__(self, root):
        self.root = root

    def getbasetemp(self):
        return self.root / "worker"

    def mktemp(self, name):
        path = self.root / "own" / name
        path.mkdir(parents=True)
        return path


@pytest.fixture
def factory(tmp_path, monkeypatch):
    monkeypatch.delenv("PYTEST_XDIST_WORKER", raising=False)
    (tmp_path / "worker").mkdir()
    return _Factory(tmp_path)


def test_a_value_is_built_once_and_then_read_by_every_caller(factory):
    builds = []

    def build(directory):
        builds.append(directory)
        (directory / "store").write_text("samples")
        return {"store": str(directory / "store")}

    first = made_once(factory, "night", build)
    second = made_once(factory, "night", build)
    assert first == second and len(builds) == 1
    assert (builds[0] / "store").read_text() == "samples"


@pytest.mark.timeout(60)  # a wait that did not end would fail here
def test_a_wait_for_a_builder_that_never_finishes_ends_with_a_copy_of_its_own(factory):
    # another worker holds the lock (a separate open file: flock excludes it even here)
    directory = factory.getbasetemp() / "made-once" / "night"
    directory.mkdir(parents=True)
    with open(directory / "lock", "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        start = time.monotonic()
        with pytest.warns(UserWarning, match="still held after"):
            value = made_once(factory, "night", lambda d: str(d), wait_s=0.5)
        waited_s = time.monotonic() - start
    assert waited_s >= 0.5  # it did wait for the builder first
    assert value.startswith(str(factory.root / "own"))  # built privately ...
    assert not (directory / "value.json").exists()  # ... and not published as the shared one
