"""Fork a simulated run at a mount time: the variants of `run_plan_on_emulator(branches=)`
and `run_sine_experiment(branches=)`.

A simulated run is deterministic: a variant that differs from it only from mount time T
on (a fault injected at T) moves exactly as the run until T. Instead of simulating that
prefix again, the run's process forks at T (`os.fork`): the child is the whole world
(emulator, VSS, recorder, their tasks) as it stands at T, and goes on as the variant.

Two things of a running process do not survive a fork as they are:

* the event loop's epoll instance and wake-up socket pair are shared with the parent
  (the kernel's objects, not copies), so either process could consume the other's
  wake-ups; and asyncio ties "the running loop" to the PID. `own_loop_after_fork` gives
  the child a selector and a wake-up pipe of its own and makes the loop its running loop.
* a store writer's open files and writer thread (ParquetStoreWriter journals from a
  thread into files whose offsets parent and child would share). `HeldWriter` therefore
  holds the recording in memory, opens nothing and starts no thread, and writes the whole
  store only when it is closed, into the store the process (parent or child) names then.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import select
import selectors
import signal
import tempfile
import traceback
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, NoReturn

if TYPE_CHECKING:
    from virtualstar.recorder.subscriber import StoreWriter

__all__ = ["ForkError", "Forks", "HeldWriter", "own_loop_after_fork"]


class ForkError(RuntimeError):
    """A run could not be forked, or a forked variant failed (the message says which)."""


class HeldWriter:
    """A store writer that keeps the session in memory and writes it at `close`.

    `open_target()` makes the real writer (any StoreWriter) at close; change it before
    then to send the recording elsewhere (a forked variant's own store). The store it
    writes holds the same samples, gaps and events, in the same order, as one written live.
    Memory: the samples themselves (a 30-minute night of 8 signals at 1 kHz: ~130 MB).
    """

    def __init__(self, open_target: Callable[[], StoreWriter]) -> None:
        self.open_target = open_target
        self.session = ""
        self._ops: list[tuple[str, Any]] = []
        self._begin: tuple[list, dict[str, Any]] | None = None

    def begin(self, signals, *, source: str = "", rate_hz: float = 0.0,
              period_us: float = 0.0) -> str:
        if self._begin is None:
            from virtualstar.recorder.background import new_session_id

            self._begin = (list(signals), {"source": source, "rate_hz": rate_hz,
                                           "period_us": period_us})
            self.session = new_session_id()
        return self.session

    def write(self, block) -> None:
        if len(block):
            self._ops.append(("write", block))

    def write_gap(self, gap) -> None:
        self._ops.append(("gap", gap))

    def write_events(self, events: list) -> None:
        if events:
            self._ops.append(("events", list(events)))

    def replay(self, blocks: Callable[[Any], None], events: Callable[[list], None]) -> None:
        """Hand what is held so far, in the order it was written, to `blocks` (each sample
        block) and `events` (each batch of events): a watcher switched on after the start
        (a forked variant's live detectors) catches up on the recording."""
        for op, arg in self._ops:
            if op == "write":
                blocks(arg)
            elif op == "events":
                events(arg)

    def close(self) -> None:
        """Write the held session into `open_target()`'s store; raise what it raises."""
        if self._begin is None:
            return
        ops, self._ops = self._ops, []
        target = self.open_target()
        signals, options = self._begin
        session = target.begin(signals, **options)
        try:
            write_events = getattr(target, "write_events", None)
            for op, arg in ops:
                if op == "write":
                    target.write(arg)
                elif op == "gap":
                    if arg.session == self.session:
                        arg = type(arg)(arg.after_t_us, arg.before_t_us, arg.lost_samples,
                                        arg.reason, session)
                    target.write_gap(arg)
                elif write_events is not None:
                    write_events(arg)
        finally:
            target.close()


def own_loop_after_fork(loop: asyncio.AbstractEventLoop) -> None:
    """In the child of an `os.fork()` made while `loop` runs: give `loop` an epoll
    instance and a wake-up socket pair of the child's own, and make it the running loop
    again (asyncio ties the running loop to the PID). Raises ForkError on a loop that
    is not a selector loop on epoll (Linux)."""
    sel = getattr(loop, "_selector", None)
    if not isinstance(sel, selectors.EpollSelector):
        raise ForkError("forking a run needs asyncio's selector loop on epoll (Linux)")
    fresh = select.epoll()
    for key in sel.get_map().values():
        fresh.register(key.fd, (select.EPOLLIN if key.events & selectors.EVENT_READ else 0)
                       | (select.EPOLLOUT if key.events & selectors.EVENT_WRITE else 0))
    sel._selector.close()  # the child's descriptor only: the parent's instance stays
    sel._selector = fresh
    loop._close_self_pipe()  # closes the child's copies; the parent keeps its pair
    loop._make_self_pipe()
    if getattr(loop, "_signal_handlers", None):
        signal.set_wakeup_fd(loop._csock.fileno())
    asyncio.events._set_running_loop(loop)


class Forks:
    """The children forked off this process at branch points (in the parent), or which
    one this process is (in a child: `in_child`).

    A child never returns into the code that started the run (a test runner, a CLI):
    it leaves its result for the parent with `end_child` and exits. Orders and results
    are JSON."""

    def __init__(self) -> None:
        self.children: list[tuple[int, int, str]] = []  # (pid, order pipe or -1, result file)
        self.result_path: str | None = None  # set in a child

    @property
    def in_child(self) -> bool:
        return self.result_path is not None

    def fork(self, loop: asyncio.AbstractEventLoop, orders: Any = None) -> Any:
        """Fork one child of the running `loop`. Return None in the parent; in the child
        its orders: `orders` if given (it runs on at once), else those the parent `send`s
        later (it waits for them, costing nothing; told nothing, it exits)."""
        fd, path = tempfile.mkstemp(prefix="vs-fork-", suffix=".json")
        os.close(fd)
        r, w = os.pipe() if orders is None else (-1, -1)
        pid = os.fork()
        if pid:
            if r >= 0:
                os.close(r)
            self.children.append((pid, w, path))
            return None
        try:  # the child: a failure here must not return into the caller's code
            self.result_path = path
            for fd_ in (w, *(c[1] for c in self.children)):
                if fd_ >= 0:
                    os.close(fd_)  # the parent's ends, and an earlier sibling's orders
            self.children = []
            own_loop_after_fork(loop)
            if r >= 0:
                doc = read_all(r)
                os.close(r)
                if not doc:
                    os._exit(0)  # the run failed in the parent: no variant to run
                orders = json.loads(doc)
        except BaseException:
            self.end_child(error=traceback.format_exc())
        return orders

    def send(self, orders: list[Any]) -> None:
        """In the parent: hand each waiting child its orders, in the order forked; a child
        whose orders are None is dismissed (it exits at once, and is reaped here)."""
        waiting = [c for c in self.children if c[1] >= 0]
        if len(orders) != len(waiting):
            raise ForkError(f"{len(orders)} orders for {len(waiting)} waiting variants")
        dismissed = []
        for child, doc in zip(waiting, orders, strict=True):
            if doc is None:
                dismissed.append(child)
            else:
                write_all(child[1], json.dumps(doc).encode())
            os.close(child[1])
        for pid, _, path in dismissed:
            os.waitpid(pid, 0)
            with contextlib.suppress(OSError):
                os.unlink(path)
        gone = {pid for pid, _, _ in dismissed}
        self.children = [(pid, -1, path) for pid, _, path in self.children
                         if pid not in gone]

    def wait(self) -> list[Any]:
        """In the parent: wait for every child; return their results in the order forked.
        Raises ForkError when one failed (its traceback in the message)."""
        out, errors = [], []
        while self.children:
            pid, order_fd, path = self.children.pop(0)
            if order_fd >= 0:
                os.close(order_fd)  # never sent: the child exits
            os.waitpid(pid, 0)
            try:
                with open(path) as f:
                    doc = json.load(f)
            except (OSError, ValueError):
                doc = {"error": f"variant process {pid} died without a result"}
            finally:
                with contextlib.suppress(OSError):
                    os.unlink(path)
            out.append(doc.get("result"))
            if doc.get("error"):
                errors.append(doc["error"])
        if errors:
            raise ForkError(f"{len(errors)} forked variant(s) failed; the first: {errors[0]}")
        return out

    @contextlib.contextmanager
    def guard(self) -> Iterator[None]:
        """Around a run that may fork: if it fails, a child leaves its traceback for the
        parent and exits (it never returns into the caller's code), and the parent ends
        and reaps its children before the error goes on."""
        try:
            yield
        except BaseException:
            if self.in_child:
                self.end_child(error=traceback.format_exc())
            self.abandon()
            raise

    def end_child(self, *, result: Any = None, error: str = "") -> NoReturn:
        """In a child: leave its result (or error) for the parent and exit."""
        code = 1
        try:
            with open(self.result_path, "w") as f:  # type: ignore[arg-type]
                json.dump({"error": error} if error else {"result": result}, f, default=str)
            code = 1 if error else 0
        finally:
            os._exit(code)

    def abandon(self) -> None:
        """In the parent, when the run failed: end and reap every child."""
        for pid, order_fd, path in self.children:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
            with contextlib.suppress(OSError):
                if order_fd >= 0:
                    os.close(order_fd)
            with contextlib.suppress(OSError):
                os.waitpid(pid, 0)
            with contextlib.suppress(OSError):
                os.unlink(path)
        self.children = []


def write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def read_all(fd: int) -> bytes:
    """Read `fd` to its end (blocking)."""
    chunks = []
    while chunk := os.read(fd, 1 << 16):
        chunks.append(chunk)
    return b"".join(chunks)
