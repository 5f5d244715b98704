"""Run a plan on the embedded emulator in lockstep simulated time (`vs run --emulator`).

The emulator, the VSS and the program run share one `LockstepClock`: the night takes as
long as the CPU needs, the same on every host, and the mount is never late. The run
goes through the VSS API (`run_plan`), exactly as against a real server.

Variants of a run (`Branches`: the same night with a fault injected here or there) are
forked off it at a mount time instead of being simulated again from the start: until
then they would move exactly as the run (virtualstar/forking.py).
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
from virtualstar.forking import ForkError, Forks, HeldWriter

from .exceptions import PlanningError
from .scheduler import Plan

if TYPE_CHECKING:
    from virtualstar.recorder.subscriber import Connector, Recorder

    from .recording import RunRecording  # the recorder (pyarrow) loads only to record

__all__ = ["EMULATOR_LEAD_S", "Branch", "Branches", "TimedWrite", "run_plan_on_emulator"]

EMULATOR_LEAD_S = 120.0  # the emulator starts this long before the plan: time to unpark


@dataclass(frozen=True)
class TimedWrite:
    """A parameter of the emulator written at a mount time (µs since 1970 UTC), exact to the
    tick: a fault injection (docs/mount-emulator.md, "Fault injection") during a run."""

    t_us: int
    name: str
    value: float


@dataclass(frozen=True)
class Branch:
    """What a variant forked off a run (`Branches`) does from its fork on: the run, plus
    its own `writes` (each at or after the fork), stopped at `until_us` if given (instead
    of the run's `until_us`), and its recording (the run's until the fork) written to
    `record_to` (store specs; required when the run records)."""

    writes: Sequence[TimedWrite] = ()
    until_us: int | None = None
    record_to: tuple[str, ...] = ()

    def as_doc(self) -> dict[str, Any]:
        return {"writes": [[w.t_us, w.name, w.value] for w in self.writes],
                "until_us": self.until_us, "record_to": list(self.record_to)}

    @classmethod
    def from_doc(cls, d: dict[str, Any]) -> Branch:
        return cls(tuple(TimedWrite(int(t), str(n), float(v)) for t, n, v in d["writes"]),
                   d["until_us"], tuple(d["record_to"]))


@dataclass(frozen=True)
class Branches:
    """`count` variants of the run, forked off it (os.fork) at mount time `at_us`.

    Each waits there, costing no CPU, until the run has ended; `orders(result)` (called
    with the run's result, the run's recording written) then says what each does
    (`count` Branch), and they run on in parallel. The run's result gains `branches`:
    theirs, in order (each with `forked_at_us`). A variant moves exactly as the run until
    its first own write (the run is deterministic; tests/anomalies/test_forked_runs.py
    compares one with a variant simulated whole). Linux only; a recording is held in
    memory until its end.

    `standby_us`: later mount times where one more variant waits each. An order runs in
    the variant forked last at or before its start (its first write, or its stop), so
    that it simulates again only from there: a run whose fault moments are known only at
    its end (read from its own recording) can still fork each fault close to its moment.
    The variants given no order exit."""

    at_us: int
    count: int
    orders: Callable[[dict[str, Any]], Sequence[Branch]]
    standby_us: Sequence[int] = ()

    def points(self) -> list[tuple[int, int]]:
        """(mount time, variants forked there), in time order."""
        later = sorted(t for t in self.standby_us if t > self.at_us)
        return [(self.at_us, self.count)] + [(t, 1) for t in later]


class _HeldRecording:
    """A RunRecording whose recorder writes through a HeldWriter (`held`, once made):
    the process may fork while it records. `stores` may be changed before the end."""

    def __init__(self, recording: RunRecording) -> None:
        self.recording = recording
        self.stores = recording.stores
        self.held: HeldWriter | None = None  # made with the recorder

    def recorder(self, connect: Connector, source: str, *,
                 event_sources: list | None = None) -> Recorder:
        from virtualstar.recorder.subscriber import Recorder

        self.held = HeldWriter(lambda: self.recording.writer(self.stores))
        r = self.recording
        return Recorder(connect, list(r.names), r.rate_hz, self.held, source=source,
                        event_sources=event_sources)

    def summary(self, recorder: Recorder) -> dict[str, Any]:
        doc = recorder.summary.as_dict()
        doc["store"] = ", ".join(self.stores)
        return doc


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
                         until_us: int | None = None,
                         branches: Branches | None = None) -> dict[str, Any]:
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
    runs exactly as the whole night); branches: variants forked off the run (Branches;
    the result gains `branches`). The result gains `wall_s`.
    """
    from virtualstar.launcher import embedded_vss
    from virtualstar.lockstep import LockstepClock, run_lockstep

    plan = Plan.from_dict(plan_doc)
    t0 = time.perf_counter()
    clock = LockstepClock(start_us if start_us is not None
                          else plan.start_us - int(EMULATOR_LEAD_S * 1e6), pace=speed)

    recording = _HeldRecording(record) if branches and record is not None else record
    forks = Forks()

    async def main() -> dict[str, Any]:
        async with embedded_vss(clock=clock, site=site or _plan_site(plan)) as vss:
            # writes, stops, the branch point: cancelled at the end, their errors raised
            helpers = await _helpers(vss, writes, until_us)
            if branches is not None:
                helpers.append(asyncio.ensure_future(fork_at(vss, helpers)))
            try:
                if recording is None:
                    return await follow(vss)
                return await recorded(vss)
            finally:
                for task in helpers:
                    task.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await task  # a stop or a write refused raises here

    stoppers: list[asyncio.Future] = []

    async def _helpers(vss, writes, until_us) -> list[asyncio.Future]:
        tasks = [await _start_writes(vss, clock, writes)] if writes else []
        if until_us is not None:
            for old in stoppers:
                old.cancel()  # a branch's stop replaces the run's
            stoppers.append(asyncio.ensure_future(_stop_at(vss, clock, until_us)))
            tasks.append(stoppers[-1])
        return tasks

    forked_at: list[int] = []  # in the parent: each child's fork point, in the order forked

    async def fork_at(vss, helpers: list[asyncio.Future]) -> None:
        assert branches is not None
        for at_us, count in branches.points():
            await clock.sleep_until_us(at_us)
            await clock.settled()  # a quiet moment: nothing half done is copied
            for _ in range(count):
                doc = forks.fork(asyncio.get_running_loop())
                if doc is not None:  # this process is the variant from here on
                    order = Branch.from_doc(doc)
                    if isinstance(recording, _HeldRecording):
                        recording.stores = order.record_to
                    helpers += await _helpers(vss, order.writes, order.until_us)
                    forked_at.append(at_us)
                    return
                forked_at.append(at_us)

    async def recorded(vss) -> dict[str, Any]:
        from virtualstar.eventlog import VssEventSource

        from .recording import record_beside

        async def connect():
            return await vss.emulator.connect_in_memory(name="vs-run-recorder")

        assert recording is not None
        result, summary = await record_beside(
            recording, connect, "embedded emulator", follow(vss),
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

    with forks.guard():
        result = run_lockstep(main(), clock)
    result["wall_s"] = time.perf_counter() - t0
    if forks.in_child:
        result["forked_at_us"] = forked_at[-1]
        forks.end_child(result=result)
    if branches is not None:
        try:
            result["branches"] = _run_branches(branches, forks, forked_at, result,
                                               record is not None)
        finally:
            forks.abandon()
    return result


def _run_branches(branches: Branches, forks: Forks, forked_at: list[int],
                  result: dict[str, Any], recorded: bool) -> list[dict[str, Any]]:
    """Send the variants waiting at the branch points their orders (each to the one forked
    last at or before its start; the others are dismissed); return their results, in the
    order of the orders."""
    if len(forked_at) < branches.count:
        raise PlanningError(f"the run ended before its branch point (mount time "
                            f"{branches.at_us}): no variant was forked")
    orders = list(branches.orders(result))
    if len(orders) != branches.count:
        raise PlanningError(f"{len(orders)} branch orders for {branches.count} forked "
                            "variants")
    for b in orders:
        if any(w.t_us < branches.at_us for w in b.writes) or (
                b.until_us is not None and b.until_us < branches.at_us):
            raise PlanningError(f"a branch forked at mount time {branches.at_us} cannot "
                                "write or stop before it")
        if recorded and not b.record_to:
            raise PlanningError("a branch of a recorded run needs stores of its own "
                                "(record_to)")
    child_of = _assign(orders, forked_at, branches.at_us)
    docs: list[dict[str, Any] | None] = [None] * len(forked_at)
    for k, child in enumerate(child_of):
        docs[child] = orders[k].as_doc()
    forks.send(docs)
    try:
        results = forks.wait()
    except ForkError as exc:
        raise PlanningError(str(exc)) from None
    by_child = dict(zip(sorted(child_of), results, strict=True))
    return [by_child[child] for child in child_of]


def _assign(orders: Sequence[Branch], forked_at: list[int], at_us: int) -> list[int]:
    """The child (index into `forked_at`, the fork points in the order forked) each order
    runs in: the latest free one forked at or before the order's start. The latest starts
    choose first; the `count` children at `at_us` leave every order one."""
    def start(b: Branch) -> int:
        times = [w.t_us for w in b.writes] + ([b.until_us] if b.until_us is not None else [])
        return min(times, default=at_us)

    free = sorted(range(len(forked_at)), key=lambda c: forked_at[c])
    child_of = [0] * len(orders)
    for k in sorted(range(len(orders)), key=lambda k: -start(orders[k])):
        child = max((c for c in free if forked_at[c] <= start(orders[k])),
                    key=lambda c: forked_at[c])
        free.remove(child)
        child_of[k] = child
    return child_of


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
