"""Run a plan on the embedded emulator in lockstep simulated time (`vs run --emulator`).

The emulator, the VSS and the program run share one `LockstepClock`: the night takes as
long as the CPU needs, the same on every host, and the mount is never late. The run
goes through the VSS API (`run_plan`), exactly as against a real server.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from astcom_client import AstcomError
from virtualstar.astro import Site, load_site

from .exceptions import PlanningError
from .scheduler import Plan

if TYPE_CHECKING:
    from .recording import RunRecording  # the recorder (pyarrow) loads only to record

__all__ = ["EMULATOR_LEAD_S", "TimedWrite", "run_plan_on_emulator"]

EMULATOR_LEAD_S = 120.0  # the emulator starts this long before the plan: time to unpark


@dataclass(frozen=True)
class TimedWrite:
    """A parameter of the emulator written at a mount time (µs since 1970 UTC), exact to the
    tick: a fault injection (docs/mount-emulator.md, "Fault injection") during a run."""

    t_us: int
    name: str
    value: float


class _ServerLog:
    """The in-process VSS's `log` command as a recorder event source needs it (no queue of
    broadcast events, which a fast lockstep night would fill)."""

    def __init__(self, server: Any) -> None:
        self.server = server

    async def request(self, cmd: str, params: dict[str, Any]) -> Any:
        return await self.server.call(cmd, params)


def run_plan_on_emulator(plan_doc: dict[str, Any], *, speed: float | None = None,
                         start_us: int | None = None, site: Site | None = None,
                         done: list[dict[str, Any]] | None = None,
                         on_event: Callable[[str, dict[str, Any]], None] = lambda k, d: None,
                         record: RunRecording | None = None,
                         writes: Sequence[TimedWrite] = (),
                         until_us: int | None = None) -> dict[str, Any]:
    """Run the plan on a fresh emulator + VSS; return the run (as the `program` command).

    speed: None runs as fast as the CPU allows, else at most ×speed real time;
    start_us: the mount time to start at (default: EMULATOR_LEAD_S before the plan);
    record: signals recorded from the emulator for the whole run (the result gains
    `recording`, the recorder's summary); the store keeps the emulator's and the VSS's
    event logs beside them (the VSS's phases tell `vs data anomalies` what the mount did);
    writes: emulator parameters written at their mount times (fault injections), by an
    operator client of their own; an unknown parameter raises PlanningError before the
    run; until_us: stop the run at this mount time, as an operator's `stop` does (a
    rehearsal whose faults are in and found need not run the night out: until then it
    runs exactly as the whole night). The result gains `wall_s`.
    """
    from virtualstar.launcher import embedded_vss
    from virtualstar.lockstep import LockstepClock, run_lockstep

    plan = Plan.from_dict(plan_doc)
    t0 = time.perf_counter()
    clock = LockstepClock(start_us if start_us is not None
                          else plan.start_us - int(EMULATOR_LEAD_S * 1e6), pace=speed)

    async def main() -> dict[str, Any]:
        async with embedded_vss(clock=clock, site=site or _plan_site(plan)) as vss:
            writer = await _start_writes(vss, clock, writes) if writes else None
            stopper = (asyncio.ensure_future(_stop_at(vss, clock, until_us))
                       if until_us is not None else None)
            try:
                if record is None:
                    return await follow(vss)
                return await recorded(vss)
            finally:
                if stopper is not None:
                    stopper.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await stopper  # a stop the server refused raises here
                if writer is not None:
                    if not writer.done():
                        writer.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await writer  # a write the emulator refused raises here

    async def recorded(vss) -> dict[str, Any]:
        from virtualstar.eventlog import VssEventSource

        from .recording import record_beside

        async def connect():
            return await vss.emulator.connect_in_memory(name="vs-run-recorder")

        assert record is not None
        result, summary = await record_beside(
            record, connect, "embedded emulator", follow(vss),
            event_sources=[VssEventSource(_ServerLog(vss.server))])
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


async def _start_writes(vss, clock, writes: Sequence[TimedWrite]) -> asyncio.Task:
    """Check that every parameter exists and may be written; start writing them in time."""
    client = await vss.emulator.connect_in_memory(name="vs-run-writes")
    infos = {i.name: i for i in await client.list()}
    bad = [w.name for w in writes if w.name not in infos or infos[w.name].kind != "parameter"]
    if bad:
        await client.close()
        raise PlanningError(f"the emulator has no parameter {', '.join(sorted(set(bad)))} to "
                            "write (docs/mount-emulator.md lists them)")

    async def write_in_time() -> None:
        try:
            for w in sorted(writes, key=lambda w: w.t_us):
                await clock.sleep_until_us(w.t_us)
                try:
                    await client.write({w.name: float(w.value)})
                except AstcomError as exc:
                    raise PlanningError(f"writing {w.name}={w.value:g}: {exc}") from None
        finally:
            await client.close()

    return asyncio.ensure_future(write_in_time())


async def _stop_at(vss, clock, t_us: int) -> None:
    """Stop the running program at mount time `t_us` (the VSS's own `stop` command)."""
    await clock.sleep_until_us(t_us)
    await vss.server.call("stop", {})


def _plan_site(plan: Plan) -> Site:
    """The site the plan was made for (a plan written by vs plan carries it)."""
    if not plan.site:
        return load_site()
    return Site.from_dict(plan.site)
