"""Run a plan on the embedded emulator in lockstep simulated time (`vs run --emulator`).

The emulator, the VSS and the program run share one `LockstepClock`: the night takes as
long as the CPU needs, the same on every host, and the mount is never late. The run
goes through the VSS API (`run_plan`), exactly as against a real server.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from virtualstar.astro import Site, load_site

from .scheduler import Plan

if TYPE_CHECKING:
    from .recording import RunRecording  # the recorder (pyarrow) loads only to record

__all__ = ["EMULATOR_LEAD_S", "run_plan_on_emulator"]

EMULATOR_LEAD_S = 120.0  # the emulator starts this long before the plan: time to unpark


def run_plan_on_emulator(plan_doc: dict[str, Any], *, speed: float | None = None,
                         start_us: int | None = None, site: Site | None = None,
                         done: list[dict[str, Any]] | None = None,
                         on_event: Callable[[str, dict[str, Any]], None] = lambda k, d: None,
                         record: RunRecording | None = None) -> dict[str, Any]:
    """Run the plan on a fresh emulator + VSS; return the run (as the `program` command).

    speed: None runs as fast as the CPU allows, else at most ×speed real time;
    start_us: the mount time to start at (default: EMULATOR_LEAD_S before the plan);
    record: signals recorded from the emulator for the whole run (the result gains
    `recording`, the recorder's summary). The result gains `wall_s`.
    """
    from virtualstar.launcher import embedded_vss
    from virtualstar.lockstep import LockstepClock, run_lockstep

    plan = Plan.from_dict(plan_doc)
    t0 = time.perf_counter()
    clock = LockstepClock(start_us if start_us is not None
                          else plan.start_us - int(EMULATOR_LEAD_S * 1e6), pace=speed)

    async def main() -> dict[str, Any]:
        async with embedded_vss(clock=clock, site=site or _plan_site(plan)) as vss:
            if record is None:
                return await follow(vss)

            from .recording import record_beside

            async def connect():
                return await vss.emulator.connect_in_memory(name="vs-run-recorder")

            result, summary = await record_beside(record, connect, "embedded emulator",
                                                  follow(vss))
            result["recording"] = summary
            return result

    async def follow(vss) -> dict[str, Any]:
        events = vss.server.subscribe(maxsize=100_000)
        task = asyncio.ensure_future(vss.server.call(
            "run_plan", {"plan": plan_doc, "done": done, "wait": True}))
        while not task.done():
            getter = asyncio.ensure_future(events.get())
            await asyncio.wait({task, getter}, return_when=asyncio.FIRST_COMPLETED)
            if getter.done():
                on_event(*getter.result())
            else:
                getter.cancel()
        while not events.empty():
            on_event(*events.get_nowait())
        vss.server.unsubscribe(events)
        return task.result()

    result = run_lockstep(main(), clock)
    result["wall_s"] = time.perf_counter() - t0
    return result


def _plan_site(plan: Plan) -> Site:
    """The site the plan was made for (a plan written by vs plan carries it)."""
    if not plan.site:
        return load_site()
    return Site.from_dict(plan.site)
