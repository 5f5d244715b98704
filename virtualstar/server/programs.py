"""Observation programs run by the server (`run_plan`), so every client sees the same run.

One program at most runs at a time, as the mount's one owner besides direct commands:
a `stop`, or any other client's command that moves the mount, ends the program first
(`stop` is final: nothing of the program moves the mount afterwards). The runner
itself (`virtualstar.planning.runner`) calls the commands through `execute`, which
does not end the program. Progress goes out as `program` events.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from .exceptions import BadRequest

if TYPE_CHECKING:
    from .station import Station

__all__ = ["ProgramControl"]

Execute = Callable[[str, dict[str, Any]], Awaitable[Any]]


class _TelescopeApi:
    """The runner's view of the server: commands, mount time, place, re-planning."""

    def __init__(self, t: Station, execute: Execute) -> None:
        self.t = t
        self.execute = execute

    async def call(self, cmd: str, params: dict[str, Any]) -> Any:
        return await self.execute(cmd, params)

    async def now_us(self) -> int:
        return await self.t.motion.mount_time_us()

    async def sleep_until(self, t_us: int) -> None:
        await self.t.motion.wait_until(t_us)

    async def place_deg(self) -> tuple[float, float]:
        pos = await self.t.motion.position()
        return math.degrees(pos.az_rad), math.degrees(pos.el_rad)

    async def replan(self, program, start_us: int, end_us: int, place_deg):
        from virtualstar.planning import PlanRequest, plan_program

        t = self.t
        req = PlanRequest(program, start_us, end_us, t.config.site, t.safety.zones(),
                          limits=t.limits, start_place_deg=place_deg,
                          mount_geometry=t.link.capabilities.geometry or "altaz")
        if t.clock.lockstep:  # mount time stands still while this loop computes
            return plan_program(req, t.eop)
        return await asyncio.to_thread(plan_program, req, t.eop)  # the feeder keeps running


class ProgramControl:
    """Start, follow and end the server's program run."""

    def __init__(self, telescope: Station, emit: Callable[[str, dict[str, Any]], None]) -> None:
        self.t = telescope
        self.emit = emit
        self.runner = None
        self.task: asyncio.Task | None = None

    @property
    def running(self) -> bool:
        return self.task is not None and not self.task.done()

    async def start(self, plan_doc: dict[str, Any], done: list[dict[str, Any]] | None,
                    execute: Execute) -> dict[str, Any]:
        """Start running a plan (vs plan's JSON); `done`: a previous run's records."""
        from virtualstar.planning import PlanningError
        from virtualstar.planning.program import Program
        from virtualstar.planning.runner import BlockRecord, ProgramRunner
        from virtualstar.planning.scheduler import Plan

        if self.running:
            raise BadRequest("a program is already running: stop it first (stop), or follow "
                             "it (program)")
        try:
            plan = Plan.from_dict(plan_doc)
            program = Program.from_dict(plan.program_spec)
            names = {t.name for t in program.targets}
            unknown = sorted({b.target for b in plan.blocks} - names)
            if unknown:
                raise BadRequest(f"run_plan: blocks for {unknown} but the plan's program has no "
                                 "such targets")
            history = [BlockRecord.from_dict(r) for r in done or []]
        except PlanningError as exc:
            raise BadRequest(f"run_plan: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise BadRequest(f"run_plan: done: a previous run's records expected ({exc})") \
                from None
        self.t.check_can_move()
        runner = ProgramRunner(plan, program, _TelescopeApi(self.t, execute),
                               on_change=self._changed, done_before=history,
                               degraded_s=self.t.config.degraded_after_s)
        runner.as_dict()  # what the answer holds can be written, before anything starts
        self.runner = runner
        self.task = asyncio.get_running_loop().create_task(self._run(runner),
                                                           name="vss-program")
        await asyncio.sleep(0)  # let it take its start time
        return runner.as_dict()

    async def _run(self, runner) -> None:
        try:
            await runner.run()
        except asyncio.CancelledError:
            runner.state = "stopped"
            self._changed(runner.progress())

    async def wait(self) -> dict[str, Any]:
        if self.task is not None:
            await asyncio.shield(self.task)
        return self.status()

    async def cancel(self, reason: str) -> None:
        """End the running program (if any) now; its state says why."""
        if not self.running:
            return
        assert self.task is not None and self.runner is not None
        self.runner.error = {"code": "stopped", "message": reason}
        self.task.cancel()
        await asyncio.wait({self.task})

    def status(self) -> dict[str, Any]:
        if self.runner is None:
            return {"state": "none"}
        return self.runner.as_dict()

    def _changed(self, progress: dict[str, Any]) -> None:
        self.emit("program", progress)
