"""Lockstep simulated time: one virtual clock for the VSS and the embedded emulator.

In lockstep the mount's time is not driven by the wall clock but by the work the
program has left to do. Every task that waits for mount time sleeps on a
`LockstepClock`; when *nothing* on the event loop can run (every task waits for
mount time, a reply, or outside I/O), the clock advances to the earliest mount
time some task waits for (in steps of at most `max_step_us`), the emulator
computes every tick up to it, and the sleepers due are woken. So mount time
advances only when the VSS has done the work due by then: a slow or busy host
makes a run slower, never different, and a run is as fast as the CPU allows.

"Nothing can run" is learnt from the event loop itself: `LockstepEventLoop` is an
ordinary `asyncio.SelectorEventLoop` whose selector, asked to wait (which the loop
does only when no callback is ready), first polls outside I/O without waiting and,
finding none, lets the clock step instead. Wall-clock timers (`asyncio.sleep`,
`wait_for` timeouts, heartbeats) keep their wall meaning; only sleeps on the clock
are virtual. Parts that must be deterministic talk to each other without sockets
(the VSS reaches the emulator through an in-memory ASTCom connection); clients on
sockets are served as they come.

    clock = LockstepClock(start_us)
    clock.add_driver(emulator.run_until)        # computes every tick up to a mount time
    result = run_lockstep(main(clock), clock)    # or LockstepEventLoop(clock) by hand

`pace` optionally caps the clock at that many mount seconds per wall second
(lockstep, but never faster than ×pace). `idle_pace` is the pace while nobody waits
for mount time to pass: a server that clients drive by hand (`vs server --emulator
--speed max`) runs as fast as the CPU allows only while some request waits for an
operation to land or end (`with clock.awaited(): ...`), and at real time otherwise, so
the sky a user is about to ask for is still there when the command is typed. A test can
also `freeze()` the clock,
so that time passes only inside `advance(s)`, and wait for `settled()`: the
moment nothing on the loop can run.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import logging
import math
import selectors
import time
from collections.abc import Callable, Coroutine, Iterator
from typing import Any, TypeVar

__all__ = ["LockstepClock", "LockstepEventLoop", "run_lockstep"]

log = logging.getLogger("virtualstar.lockstep")

T = TypeVar("T")

TICK_US = 100  # the emulator's loop period: mount time advances in whole ticks
DEFAULT_MAX_STEP_US = 1_000_000  # at most this much mount time per step: streams flow, I/O is polled
_MAX_PACE_WAIT_S = 0.05  # a paced clock re-checks outside I/O at least this often
_PACE_SLIP_S = 0.25  # behind its pace by more than this (a stalled host): re-anchor, no burst


class LockstepClock:
    """Virtual mount time (µs since 1970 UTC) shared by everything on one event loop.

    ``speed`` is 1.0 (the VSS plans in mount seconds and is never late) and
    ``lockstep`` is True: the same interface as the VSS's wall-paced clock.
    """

    lockstep = True
    speed = 1.0  # the VSS's margins: those of real time

    def __init__(self, start_us: int, *, max_step_us: int = DEFAULT_MAX_STEP_US,
                 pace: float | None = None, tick_us: int = TICK_US,
                 idle_pace: float | None = None) -> None:
        for name, value in (("pace", pace), ("idle_pace", idle_pace)):
            if value is not None and not value > 0:
                raise ValueError(f"{name}={value}: expected mount seconds per wall second > 0, "
                                 "or None")
        self.tick_us = int(tick_us)
        self.busy_pace = pace  # the pace while a request waits (all the time without idle_pace)
        self.idle_pace = idle_pace
        self._awaited = 0
        self.now_us = int(start_us) // self.tick_us * self.tick_us
        self.max_step_us = max(self.tick_us, int(max_step_us))
        self.pace = pace
        self._sleepers: list[tuple[int, int, asyncio.Future[None]]] = []
        self._seq = itertools.count()
        self._drivers: list[Callable[[int], Any]] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._step_scheduled = False
        self._anchor: tuple[float, int] | None = None  # (wall monotonic s, mount µs) for pacing
        self.error: BaseException | None = None
        self.frozen = False
        self._settled: list[asyncio.Future[None]] = []
        if idle_pace is not None:
            self.pace = idle_pace

    # ------------------------------------------------------------------ for tasks
    def add_driver(self, driver: Callable[[int], Any]) -> None:
        """Call `driver(t_us)` at every step: it must compute everything up to mount time `t_us`."""
        self._drivers.append(driver)

    async def sleep_until_us(self, t_us: int) -> None:
        """Return when mount time has reached `t_us` (at once, after one yield, if it has)."""
        if self.error is not None:
            raise RuntimeError(f"the lockstep clock stopped: {self.error}") from self.error
        if t_us <= self.now_us:
            await asyncio.sleep(0)
            return
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[None] = loop.create_future()
        heapq.heappush(self._sleepers, (int(t_us), next(self._seq), fut))
        try:
            await fut
        finally:
            if not fut.done():
                fut.cancel()  # a cancelled sleeper is skipped when its time comes

    async def sleep(self, mount_s: float) -> None:
        """Sleep `mount_s` seconds of mount time (at least one tick)."""
        step = max(self.tick_us, math.ceil(mount_s * 1e6)) if mount_s > 0 else self.tick_us
        await self.sleep_until_us(self.now_us + step)

    def freeze(self) -> None:
        """Stop mount time: tasks run, but nothing that waits for mount time is woken."""
        self.frozen = True

    def thaw(self) -> None:
        self.frozen = False

    @contextlib.contextmanager
    def awaited(self) -> Iterator[None]:
        """Within the block a client waits for mount time to pass: with an `idle_pace`, the
        clock runs at its busy pace (`pace`) until no such block is open."""
        self._awaited += 1
        self._pace_for_waiters()
        try:
            yield
        finally:
            self._awaited -= 1
            self._pace_for_waiters()

    def _pace_for_waiters(self) -> None:
        if self.idle_pace is None:
            return
        pace = self.busy_pace if self._awaited else self.idle_pace
        if pace != self.pace:
            self.set_pace(pace)

    def set_pace(self, pace: float | None) -> None:
        """Change the cap (mount seconds per wall second; None: as fast as the CPU allows)."""
        if pace is not None and not pace > 0:
            raise ValueError(f"pace={pace}: expected mount seconds per wall second > 0, or None")
        self.pace = pace
        self._anchor = None  # the new pace counts from now

    async def advance(self, mount_s: float) -> None:
        """Let `mount_s` of mount time pass (thawed), then freeze the clock again."""
        self.thaw()
        try:
            await self.sleep(mount_s)
        finally:
            self.freeze()

    async def settled(self) -> None:
        """Return once nothing on the event loop can run (all wait for time, replies or I/O)."""
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._settled.append(fut)
        await fut

    # ------------------------------------------------------------------ for the loop
    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        if self._loop is not None and self._loop is not loop:
            raise RuntimeError("a LockstepClock drives one event loop")
        self._loop = loop

    def on_idle(self) -> float | None:
        """Called by the selector when nothing is ready to run.

        Returns 0.0 when a step was scheduled (the loop must not wait), a positive
        number of wall seconds to wait for the pace, or None when no task waits for
        mount time (the loop may wait for outside I/O as it likes).
        """
        if self._step_scheduled:
            return 0.0
        if self._settled:
            waiting, self._settled = self._settled, []
            for fut in waiting:
                if not fut.done():
                    fut.set_result(None)
            return 0.0
        heap = self._sleepers
        while heap and heap[0][2].done():
            heapq.heappop(heap)
        if not heap or self._loop is None or self.error is not None or self.frozen:
            return None
        target = min(heap[0][0], self.now_us + self.max_step_us)
        target = -(-target // self.tick_us) * self.tick_us
        if self.pace is not None:
            wait_s = self._pace_wait_s(target)
            if wait_s > 0:
                return wait_s
        self._step_scheduled = True
        self._loop.call_soon(self._step, target)
        return 0.0

    def _pace_wait_s(self, target_us: int) -> float:
        wall = time.monotonic()
        if self._anchor is None:
            self._anchor = (wall, self.now_us)
        wall0, mount0 = self._anchor
        due_wall = wall0 + (target_us - mount0) / 1e6 / self.pace
        if wall - due_wall > _PACE_SLIP_S:  # the host stalled: keep the pace from here
            self._anchor = (wall, self.now_us)
            due_wall = wall + (target_us - self.now_us) / 1e6 / self.pace
        return min(max(due_wall - wall, 0.0), _MAX_PACE_WAIT_S)

    def _step(self, target_us: int) -> None:
        self._step_scheduled = False
        try:
            for driver in self._drivers:
                driver(target_us)
        except Exception as exc:  # a broken emulator must not spin the loop: stop the clock
            log.exception("lockstep driver failed at mount time %d", target_us)
            self.error = exc
            for _, _, fut in self._sleepers:
                if not fut.done():
                    fut.set_exception(RuntimeError(f"the lockstep clock stopped: {exc}"))
            self._sleepers.clear()
            return
        self.now_us = target_us
        heap = self._sleepers
        while heap and heap[0][0] <= target_us:
            _, _, fut = heapq.heappop(heap)
            if not fut.done():
                fut.set_result(None)


class _LockstepSelector(selectors.DefaultSelector):  # type: ignore[misc,valid-type]
    """The loop's selector: when the loop would wait, let the clock step instead."""

    def __init__(self, clock: LockstepClock) -> None:
        super().__init__()
        self._clock = clock

    def select(self, timeout: float | None = None):
        if timeout is not None and timeout <= 0:
            return super().select(timeout)
        ready = super().select(0)
        if ready:
            return ready
        wait_s = self._clock.on_idle()
        if wait_s is None:
            return super().select(timeout)
        if wait_s <= 0:
            return []
        return super().select(wait_s if timeout is None else min(wait_s, timeout))


class LockstepEventLoop(asyncio.SelectorEventLoop):
    """An asyncio loop whose idle moments advance a `LockstepClock`."""

    def __init__(self, clock: LockstepClock) -> None:
        super().__init__(_LockstepSelector(clock))
        self.clock = clock
        clock.bind(self)


def run_lockstep(main: Coroutine[Any, Any, T], clock: LockstepClock) -> T:
    """Run `main` to completion on a new `LockstepEventLoop` driven by `clock`."""
    with asyncio.Runner(loop_factory=lambda: LockstepEventLoop(clock)) as runner:
        return runner.run(main)
