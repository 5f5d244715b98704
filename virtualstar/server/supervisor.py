"""The one owner of the mount: every command that moves it passes through here.

Rules (each a test in tests/vss):

* At most one operation is alive. A new command takes the supervisor's lock,
  ends the running operation *and waits until its task has ended* (its feeder
  and every request it had in flight included), and only then starts the new
  one. `stop` does the same, then brings the mount to rest; after it nothing
  moves until the next command, because nothing of the old operation is left
  and resuming is decided inside the operation's own task.
* Every operation's `begun` and `done` futures are resolved exactly once,
  whatever ends it: its procedure, a fault, a lost mount, a newer command, a
  stop, a shutdown, or a cancellation before it even ran (a done-callback on the
  task makes sure).
* An interrupted procedure (lost mount, buffer underrun) is run again or not as
  `operations.resume_decision` says, within the same operation and task; waiting
  for the mount to come back is bounded by `resume_timeout_s` (wall seconds).
* After an operation fails for any reason but a fault or a lost mount, the mount
  is brought to rest by the operation's own task.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from .exceptions import (
    InternalError,
    MountFault,
    MountUnavailable,
    OperationAborted,
    VssError,
)
from .link_interface import MountBackend
from .motion import Motion
from .operations import Operation, Phase, Resume, current_operation, resume_decision

__all__ = ["Procedure", "Supervisor", "operations_of_tasks"]

log = logging.getLogger("virtualstar.server")

Procedure = Callable[[Operation], Awaitable[dict[str, Any]]]
DEFAULT_RESUME_TIMEOUT_S = 60.0
TASK_PREFIX = "vss-op-"  # an operation's tasks: vss-op-ID (its driver), vss-op-ID-attempt-N


def operations_of_tasks(task_names) -> set[str]:
    """The operations (``vss-op-ID``) that the named tasks belong to: a check that never
    more than one operation is alive (tests, the concurrency benchmark)."""
    return {n.split("-attempt")[0] for n in task_names if n.startswith(TASK_PREFIX)}


class Supervisor:
    """Run operations one at a time on a mount; emit ``operation`` events as they change."""

    def __init__(self, link: MountBackend, motion: Motion, *,
                 emit: Callable[[str, dict[str, Any]], None],
                 resume_timeout_s: float = DEFAULT_RESUME_TIMEOUT_S) -> None:
        self.link = link
        self.motion = motion
        self.emit = emit
        self.resume_timeout_s = resume_timeout_s
        self.op: Operation | None = None
        self._lock = asyncio.Lock()
        self._ids = itertools.count(1)
        self.operations_started = 0

    # ------------------------------------------------------------------ commands
    async def start(self, kind: str, target: str, procedure: Procedure, *,
                    resumable: bool = False,
                    check: Callable[[], Awaitable[None]] | None = None,
                    steer: Callable[[Operation | None], Awaitable[bool]] | None = None
                    ) -> Operation:
        """End the running operation, wait for it, then start `procedure`; return the new one.

        `check` runs first, in the order the commands arrived (under the lock): if it
        raises, the command is refused and the running operation goes on untouched.
        `steer(current operation or None)` then may hand the command to the running
        operation instead (a hand pad's new rates): when it returns True, that operation
        is returned and goes on; when it raises, the command is refused.
        A command must reach here without awaiting anything else, or a `stop` sent after
        it could overtake it.
        """
        async with self._lock:
            if check is not None:
                await check()
            if steer is not None and await steer(self.op):
                return self.op  # type: ignore[return-value]
            await self._end_running(OperationAborted(f"replaced by a new {kind} ({target})"))
            loop = asyncio.get_running_loop()
            op = Operation(next(self._ids), kind, target, resumable=resumable,
                           begun=loop.create_future(), done=loop.create_future())
            self.op = op
            self.operations_started += 1
            op.task = loop.create_task(self._drive(op, procedure), name=f"{TASK_PREFIX}{op.id}")
            op.task.add_done_callback(lambda _task: self._close(op))
            self.emit("operation", op.as_dict())
            return op

    async def stop(self, reason: str | OperationAborted, *,
                   then: Callable[[], Awaitable[Any]] | None = None) -> None:
        """End the running operation, wait for it, then run `then` (bring to rest), all under the lock."""
        async with self._lock:
            await self._end_running(reason if isinstance(reason, OperationAborted)
                                    else OperationAborted(reason))
            if then is not None:
                await then()

    def interrupt(self, error: VssError) -> None:
        """End the running procedure with `error` (a fault, a lost mount); the operation decides."""
        op = self.op
        if op is not None and op.attempt is not None and not op.attempt.done():
            op.interruption = error
            op.attempt.cancel()

    @property
    def busy(self) -> bool:
        return self.op is not None and not self.op.finished

    # ------------------------------------------------------------------ the operation's task
    async def _end_running(self, reason: VssError) -> None:
        op = self.op
        if op is None or op.task is None or op.task.done():
            return
        op.end_reason = reason
        op.task.cancel()
        # the task ends promptly: a cancelled request stops waiting for its reply, and the
        # procedure's feeder is cancelled and awaited with it
        await asyncio.wait({op.task})

    async def _drive(self, op: Operation, procedure: Procedure) -> None:
        current_operation.set(op.id)  # this task's context, copied into every task it starts
        try:
            while True:
                op.attempt = asyncio.get_running_loop().create_task(
                    procedure(op), name=f"{TASK_PREFIX}{op.id}-attempt-{op.resumes}")
                try:
                    await asyncio.wait({op.attempt})
                except asyncio.CancelledError:
                    op.attempt.cancel()
                    await asyncio.wait({op.attempt})
                    raise
                error = self._attempt_error(op)
                if error is None:
                    op.info.update(op.attempt.result())
                    self._finish(op, Phase.DONE)
                    return
                decision = resume_decision(error, resumable=op.resumable, resumes=op.resumes)
                if decision is Resume.NO:
                    await self._fail(op, error)
                    return
                try:
                    await self._before_resuming(op, error, decision)
                except VssError as lost:  # the mount did not come back in time
                    await self._fail(op, lost)
                    return
        except asyncio.CancelledError:
            reason = op.end_reason or OperationAborted("cancelled")
            self._finish(op, Phase.ABORTED, _error_dict(reason))
            raise
        except Exception as exc:  # a bug in the supervision itself: report, never hang a client
            log.exception("operation %s (%s): supervision failed", op.id, op.kind)
            self._finish(op, Phase.FAILED, _error_dict(InternalError(f"{type(exc).__name__}: {exc}")))

    def _attempt_error(self, op: Operation) -> VssError | None:
        attempt = op.attempt
        assert attempt is not None
        if attempt.cancelled():
            error = op.interruption or op.end_reason or OperationAborted("cancelled")
            op.interruption = None
            return error
        exc = attempt.exception()
        if exc is None:
            return None
        if isinstance(exc, VssError):
            return exc
        log.error("operation %s (%s) failed with a bug", op.id, op.kind, exc_info=exc)
        return InternalError(f"{type(exc).__name__}: {exc}")

    async def _fail(self, op: Operation, error: VssError) -> None:
        aborted = isinstance(error, OperationAborted | MountUnavailable)
        if not isinstance(error, MountFault | MountUnavailable) and self.link.connected:
            halt_error = await self.motion.halt_quietly()
            if halt_error:
                op.info["halt_error"] = halt_error
        self._finish(op, Phase.ABORTED if aborted else Phase.FAILED, _error_dict(error))

    async def _before_resuming(self, op: Operation, error: VssError, decision: Resume) -> None:
        op.resumes += 1
        connects = self.link.connects
        op.advance(Phase.INTERRUPTED, interrupted=_error_dict(error), resumes=op.resumes)
        self.emit("operation", op.as_dict())
        log.warning("operation %s (%s %s) interrupted: %s; %s", op.id, op.kind, op.target,
                    error, "re-acquiring" if decision is Resume.NOW else "waiting for the mount")
        if decision is Resume.WHEN_CONNECTED:
            # a new connection, not the one that just failed (its loss may not be noticed yet)
            await self.link.wait_reconnected(connects, self.resume_timeout_s)
        op.advance(Phase.PREPARING)
        self.emit("resumed", op.as_dict())

    def _finish(self, op: Operation, phase: Phase, error: dict[str, str] | None = None) -> None:
        if op.finished:
            return
        if error is not None:
            op.info["error"] = error
        op.advance(phase)
        op.info.pop("seconds_left", None)
        self._resolve(op)
        self.emit("operation", op.as_dict())

    def _close(self, op: Operation) -> None:
        """Task done-callback: an operation whose task ended without finishing it still ends, once."""
        if not op.finished:  # cancelled before its first step
            reason = op.end_reason or OperationAborted("cancelled before it started")
            op.info["error"] = _error_dict(reason)
            op.phase = Phase.ABORTED
            self.emit("operation", op.as_dict())
        self._resolve(op)

    @staticmethod
    def _resolve(op: Operation) -> None:
        for fut in (op.begun, op.done):
            if fut is not None and not fut.done():
                fut.set_result(op)

    def begun(self, op: Operation) -> None:
        """Tell clients waiting for the operation's start that it has begun."""
        if op.begun is not None and not op.begun.done():
            op.begun.set_result(op)

    def phase(self, op: Operation, phase: Phase, **info: Any) -> None:
        """Move `op` to `phase` and tell the clients."""
        op.advance(phase, **info)
        self.emit("operation", op.as_dict())


def _error_dict(error: VssError) -> dict[str, Any]:
    doc: dict[str, Any] = {"code": error.code, "message": str(error)}
    if getattr(error, "stopped", False):  # a client's stop: asked for, not a failure
        doc["stopped"] = True
    return doc
