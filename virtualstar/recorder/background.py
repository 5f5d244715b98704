"""Run a store's writes on one background thread, with a bounded queue of pending writes.

The recorder's stream loop must never wait on a disk or a database; each store hands its
batches to one writer thread instead, and learns of a failed write at its next hand-over.
"""

from __future__ import annotations

import secrets
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from datetime import UTC, datetime

__all__ = ["BackgroundWriter", "new_session_id"]


def new_session_id() -> str:
    """Return a recording session id: its UTC start second and a random suffix."""
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%S") + "-" + secrets.token_hex(3)


class BackgroundWriter:
    """Queue writes to one thread; at most `max_pending` wait, so memory stays bounded.

    `to_error(exc)` turns a failure of the writer thread into the exception the caller
    raises (return `exc` itself to raise it unchanged).
    """

    def __init__(self, name: str, max_pending: int,
                 to_error: Callable[[BaseException], BaseException]) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        self._pending: deque[Future[None]] = deque()
        self._max_pending = max_pending
        self._to_error = to_error

    def submit(self, fn: Callable[..., None], *args: object) -> None:
        """Queue `fn(*args)` once fewer than `max_pending` writes wait; raise an earlier failure."""
        self.wait(self._max_pending - 1)
        self._pending.append(self._pool.submit(fn, *args))

    def wait(self, keep: int = 0) -> None:
        """Wait until at most `keep` writes are pending; raise the first failure among them."""
        while len(self._pending) > keep:
            exc = self._pending.popleft().exception()
            if exc is not None:
                error = self._to_error(exc)
                if error is exc:
                    raise exc
                raise error from exc

    def shutdown(self) -> None:
        """Let the queued writes finish and stop the thread."""
        self._pool.shutdown(wait=True)
