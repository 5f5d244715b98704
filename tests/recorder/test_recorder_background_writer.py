"""The stores' writer thread: failures reach the caller, and the queue stays bounded."""

from __future__ import annotations

import threading

import pytest

from virtualstar.recorder.background import BackgroundWriter, new_session_id
from virtualstar.recorder.exceptions import StoreError


def _as_store_error(exc: BaseException) -> BaseException:
    return exc if isinstance(exc, StoreError) else StoreError(f"write failed: {exc}")


def test_a_failed_write_is_raised_at_the_next_hand_over_as_the_store_error():
    writer = BackgroundWriter("test-writer", 4, _as_store_error)
    writer.submit(lambda: 1 / 0)
    with pytest.raises(StoreError, match="write failed: division by zero") as info:
        writer.wait(0)
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    writer.shutdown()


def test_a_store_error_from_the_thread_is_raised_unchanged():
    original = StoreError("disk full")

    def fail() -> None:
        raise original

    writer = BackgroundWriter("test-writer", 4, _as_store_error)
    writer.submit(fail)
    with pytest.raises(StoreError) as info:
        writer.wait(0)
    assert info.value is original
    writer.shutdown()


def test_submit_waits_until_fewer_than_max_pending_writes_are_queued():
    gate = threading.Event()
    started = []
    writer = BackgroundWriter("test-writer", 2, _as_store_error)
    writer.submit(gate.wait)                 # occupies the thread
    writer.submit(started.append, "second")  # queued: two pending now
    third = threading.Thread(target=writer.submit, args=(started.append, "third"))
    third.start()
    third.join(0.2)
    assert third.is_alive()                  # held back: the queue is full
    gate.set()
    third.join(5)
    writer.wait(0)
    writer.shutdown()
    assert started == ["second", "third"]


def test_session_ids_are_unique_and_start_with_the_utc_second():
    ids = {new_session_id() for _ in range(50)}
    assert len(ids) == 50
    assert all(len(i) == 22 and i[8] == "T" and i[15] == "-" for i in ids)
