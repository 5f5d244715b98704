"""Execute a plan block by block through the VSS API, re-planning after a block goes wrong.

The runner knows the VSS only through a `RunApi` (its commands, mount time, the mount's
place, and a way to re-plan), so the same code runs inside the server (`run_plan`) and
in tests. Per block:

* a sidereal block: `track` its target once its slew can still land by the block's
  start (`slew_s` + `setup_s` before it), so the mount tracks from the start;
  a satellite block: `track` the TLE after the block before has ended (the server
  waits for the pass at its pre-position);
* then wait until the block's end, or until the operation ends first (a fault, the
  target leaving the limits, a stop);
* record what happened: when tracking began and ended and how late (`delay_s`), the
  slew, and over the block the error on target (the boresight against the target's true
  place: RMS, peak, time off target), the deviation the VSS planned (a keyhole, guide
  offsets: shown apart), the mount's following error and the on-sky error; and the
  outcome: `done`; `degraded` (off target for longer than `degraded_s`); `late`
  (tracking began more than `late_s` after the block's start); `missed` (it could not
  begin within `give_up_s`), `faulted` or `stopped`. A satellite block ends at its planned
  end (the track is stopped there, where the plan put the mount for the next block).

After a late, missed or faulted block, the rest of the night is planned again from the
mount's place and the current time, without the blocks already done; after a mount
fault the faults are reset first. A target that faults twice is given up. A degraded
block keeps its place in the plan (its time is spent; the next blocks are not moved).
A stop (the runner cancelled: `stop`, another client's motion command, a shutdown)
ends the run at once; `resume` starts a new run that counts the blocks a previous run
finished.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from virtualstar.astro import iso_utc

from .program import Program
from .scheduler import Block, Plan

__all__ = ["BlockRecord", "ProgramRunner", "RunApi", "run_summary"]

LATE_S = 10.0  # tracking that begins later than this after a block's start makes it late
GIVE_UP_S = 60.0  # a block that cannot begin within this of its start is missed
DEGRADED_S = 1.0  # a block off target for longer than this (mount seconds) is degraded
MAX_FAULTS_PER_TARGET = 2
RESET_TRIES, RESET_PAUSE_S = 3, 5.0  # after a mount fault: reset, and again if it persists
REPLAN_LEAD_S = 60.0  # a new plan starts this long after now (time to plan and to slew)


class RunApi(Protocol):
    """What the runner needs from a VSS."""

    async def call(self, cmd: str, params: dict[str, Any]) -> Any:
        """Run a VSS command; raise an exception with a `.code` when it is refused."""

    async def now_us(self) -> int:
        """Mount time now."""

    async def sleep_until(self, t_us: int) -> None:
        """Return once mount time has reached t_us."""

    async def place_deg(self) -> tuple[float, float]:
        """The mount's azimuth (in the cable wrap) and elevation now."""

    async def replan(self, program: Program, start_us: int, end_us: int,
                     place_deg: tuple[float, float]) -> Plan:
        """Plan `program` between two mount times, starting from a mount place."""


@dataclass
class BlockRecord:
    """What happened to one planned block (times: mount µs; errors: arcseconds)."""

    target: str
    kind: str
    repeat: int
    priority: float
    planned_start_us: int
    planned_end_us: int
    outcome: str = "pending"  # done, degraded, late, missed, faulted, stopped
    start_us: int | None = None  # tracking began
    end_us: int | None = None
    slew_s: float | None = None
    delay_s: float | None = None  # tracking began this long after the planned start
    on_target_rms_arcsec: float | None = None  # the boresight against the target's true place
    on_target_peak_arcsec: float | None = None
    off_target_s: float | None = None  # mount seconds farther than the threshold from it
    planned_deviation_peak_arcsec: float | None = None  # the demand against the true place
    planned_deviation: list[str] = field(default_factory=list)  # what it was planned for
    encoder_rms_arcsec: float | None = None  # the mount's following error (encoders vs demand)
    encoder_peak_arcsec: float | None = None
    on_sky_rms_arcsec: float | None = None  # on target with the clock term
    on_sky_peak_arcsec: float | None = None
    samples: int = 0
    operation_id: int | None = None
    error: dict[str, str] | None = None

    @property
    def counts(self) -> bool:
        """Whether the block was observed (done, late or degraded: its time was spent on it)."""
        return self.outcome in ("done", "late", "degraded")

    @property
    def on_target_s(self) -> float:
        """Mount seconds observed on target (observed time less the time off target)."""
        if self.start_us is None or self.end_us is None:
            return 0.0
        return max(0.0, (self.end_us - self.start_us) / 1e6 - (self.off_target_s or 0.0))

    def as_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        for key in ("planned_start", "planned_end", "start", "end"):
            t = d[f"{key}_us"]
            d[f"{key}_utc"] = None if t is None else iso_utc(t)
        d["observed_s"] = (None if self.start_us is None or self.end_us is None
                           else (self.end_us - self.start_us) / 1e6)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BlockRecord:
        """A record from a previous run's JSON (a client's or a file's: checked; TypeError
        or ValueError naming the field otherwise)."""
        if not isinstance(d, dict):
            raise TypeError("a record is a table")
        rec = cls(**{k: d[k] for k in cls.__dataclass_fields__ if k in d})
        for name in ("target", "kind", "outcome"):
            if not isinstance(getattr(rec, name), str):
                raise TypeError(f"{name}: text expected")
        for name in ("planned_start_us", "planned_end_us", "start_us", "end_us"):
            t = getattr(rec, name)
            if t is None and name in ("start_us", "end_us"):
                continue
            if isinstance(t, bool) or not isinstance(t, int) or not 0 <= t < 2**62:
                raise ValueError(f"{name} = {str(t)[:40]!r}: expected integer µs since 1970")
        for f in dataclasses.fields(cls):
            v = getattr(rec, f.name)
            if f.name.endswith(("_s", "_arcsec")) or f.name in ("priority", "repeat", "samples"):
                if v is None and f.default is None:
                    continue
                if (isinstance(v, bool) or not isinstance(v, (int, float))
                        or not abs(v) < 1e12):  # NaN fails too
                    raise ValueError(f"{f.name} = {str(v)[:40]!r}: expected a finite number")
        if not isinstance(rec.planned_deviation, list) or not (
                rec.error is None or isinstance(rec.error, dict)):
            raise TypeError("planned_deviation: a list, error: a table expected")
        return rec


@dataclass
class ProgramRunner:
    """Run one plan; `state` and `records` are what the API's `program` command shows."""

    plan: Plan
    program: Program
    api: RunApi
    on_change: Callable[[dict[str, Any]], None] = lambda doc: None  # a progress() each change
    done_before: list[BlockRecord] = field(default_factory=list)  # a resumed run's history
    late_s: float = LATE_S
    give_up_s: float = GIVE_UP_S
    degraded_s: float = DEGRADED_S
    state: str = "starting"  # running, done, stopped, failed
    records: list[BlockRecord] = field(default_factory=list)
    replans: list[dict[str, Any]] = field(default_factory=list)
    current: Block | None = None
    error: dict[str, str] | None = None
    started_us: int | None = None
    ended_us: int | None = None
    _faults: Counter = field(default_factory=Counter)

    # ------------------------------------------------------------------ the run
    async def run(self) -> dict[str, Any]:
        """Run to the end of the plan (or a stop); return the final `as_dict()`."""
        self.started_us = await self.api.now_us()
        self.state = "running"
        try:
            if self.done_before:
                await self._replan("resumed: the blocks done before are left out")
            else:
                self._changed()
            queue = list(self.plan.blocks)
            while queue:
                block = queue.pop(0)
                record = await self._run_block(block)
                self.records.append(record)
                self.current = None
                self._changed()
                if record.outcome not in ("done", "degraded"):
                    if record.error and record.error.get("code") == "mount_fault":
                        await self._reset_faults()
                    await self._replan(f"{block.target} #{block.repeat} {record.outcome}"
                                       + (f": {record.error['message']}" if record.error else ""))
                    now = await self.api.now_us()
                    queue = [b for b in self.plan.blocks if b.start_us >= now]
            self.state = "done"
            with contextlib.suppress(Exception):
                await self.api.call("stop", {})  # the mount comes to rest at the end
        except asyncio.CancelledError:
            self.state = "stopped"
            if self.current is not None:
                self.records.append(BlockRecord(
                    self.current.target, self.current.kind, self.current.repeat,
                    self.current.priority, self.current.start_us, self.current.end_us,
                    outcome="stopped"))
                self.current = None
            self.ended_us = None
            self._changed()
            raise
        except Exception as exc:  # noqa: BLE001 - a run ends with its reason, never silently
            self.state = "failed"
            self.error = {"code": getattr(exc, "code", "internal"), "message": str(exc)}
        with contextlib.suppress(Exception):
            self.ended_us = await self.api.now_us()
        self.current = None
        self._changed()
        return self.as_dict()

    async def _run_block(self, block: Block) -> BlockRecord:
        rec = BlockRecord(block.target, block.kind, block.repeat, block.priority,
                          block.start_us, block.end_us)
        self.current = block
        self._changed()
        target = self._target(block.target)
        if self._faults[block.target] >= MAX_FAULTS_PER_TARGET:
            rec.outcome, rec.error = "missed", {"code": "given_up", "message": (
                f"{block.target} faulted {MAX_FAULTS_PER_TARGET} times: left out")}
            return rec
        if block.kind != "satellite":
            go_us = block.start_us - int((block.slew_s + self.plan.setup_s) * 1e6)
            if await self.api.now_us() < go_us:
                await self.api.sleep_until(go_us)
        now = await self.api.now_us()
        if now > block.start_us + int(self.give_up_s * 1e6) or now >= block.end_us:
            rec.outcome = "missed"
            rec.error = {"code": "late", "message": f"could not begin before "
                         f"{iso_utc(block.start_us + int(self.give_up_s * 1e6))}: the mount was "
                         f"busy until {iso_utc(now)}"}
            return rec
        params = self._track_params(block, target, now)
        try:
            op = await self.api.call("track", params)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - the VSS refused: the block faulted
            return self._faulted(rec, exc)
        rec.operation_id = op.get("id")
        ended = await self._until(block.end_us, rec.operation_id)
        return await self._finish(rec, block, ended)

    def _track_params(self, block: Block, target, now_us: int) -> dict[str, Any]:
        loop = {"closed_loop": True} if target.closed_loop else {}
        if block.kind == "satellite":
            from .sky import target_tle_text

            wait_s = max(0.0, (block.start_us - now_us) / 1e6) + 300.0
            return {"tle": target_tle_text(target), "sat": target.spec, "max_wait_s": wait_s,
                    **loop}
        key = "radec" if block.kind == "radec" else "star"
        return {key: target.spec, **loop}

    async def _until(self, end_us: int, op_id: int | None) -> Exception | None:
        """Wait until mount time `end_us`; return the error if the operation ended first."""
        waiting = asyncio.ensure_future(self.api.call("wait", {"id": op_id}))
        timer = asyncio.ensure_future(self.api.sleep_until(end_us))
        try:
            await asyncio.wait({waiting, timer}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in (waiting, timer):
                task.cancel()
            await asyncio.wait({waiting, timer})
        if waiting.done() and not waiting.cancelled():
            exc = waiting.exception()
            return exc if exc is not None else _EndedEarly("the operation ended before the "
                                                           "block's end")
        return None

    async def _finish(self, rec: BlockRecord, block: Block, ended: Exception | None
                      ) -> BlockRecord:
        status = await self.api.call("status", {})
        op = status.get("operation") or {}
        info = op.get("info", {}) if op.get("id") == rec.operation_id else {}
        began = info.get("tracking_from_us") or info.get("pass_start_us")
        rec.slew_s = info.get("slew_time_s")
        now = await self.api.now_us()
        rec.end_us = min(now, block.end_us) if ended is None else min(
            info.get("tracking_to_us") or now, block.end_us)
        if (isinstance(ended, _EndedEarly) and op.get("phase") == "done"
                and block.end_us - rec.end_us <= self.late_s * 1e6):
            ended = None  # it ended by itself at the block's end (a pass setting, a zone)
        if began is not None:
            rec.start_us = max(int(began), block.start_us)
            rec.delay_s = max(0.0, (int(began) - block.start_us) / 1e6)
        rec.planned_deviation = list(info.get("planned_deviation") or [])
        if ended is None and block.kind == "satellite" and op.get("id") == rec.operation_id:
            # the block ends here (its constraints do): the next block was planned from here
            await self.api.call("stop", {})
        if rec.start_us is not None and rec.end_us > rec.start_us:
            errors = await self.api.call("errors", {"from_us": rec.start_us,
                                                    "to_us": rec.end_us})
            self._figures(rec, errors["stats"])
        if ended is not None:
            if getattr(ended, "code", "") == "aborted":
                raise asyncio.CancelledError  # another client's command took the mount
            return self._faulted(rec, ended)
        late = (rec.start_us or block.end_us) - block.start_us
        if (rec.off_target_s or 0.0) > self.degraded_s:
            rec.outcome = "degraded"
        else:
            rec.outcome = "late" if late > self.late_s * 1e6 else "done"
        return rec

    @staticmethod
    def _figures(rec: BlockRecord, s: dict[str, Any]) -> None:
        """The block's error figures from the server's statistics over its window."""
        rec.samples = int(s.get("n") or 0)
        rec.on_target_rms_arcsec = s.get("on_target_rms_arcsec")
        rec.on_target_peak_arcsec = s.get("on_target_peak_arcsec")
        rec.off_target_s = s.get("off_target_s")
        rec.planned_deviation_peak_arcsec = s.get("planned_deviation_peak_arcsec")
        rec.encoder_rms_arcsec, rec.encoder_peak_arcsec = s.get("rms_arcsec"), s.get("peak_arcsec")
        rec.on_sky_rms_arcsec = s.get("on_sky_rms_arcsec")
        rec.on_sky_peak_arcsec = s.get("on_sky_peak_arcsec")

    async def _reset_faults(self) -> None:
        """Clear the mount's latched faults; a fault that is still there is tried again
        a few mount seconds later (a glitch passes), then left to the next block."""
        for attempt in range(RESET_TRIES):
            try:
                result = await self.api.call("reset_faults", {})
                if (result or {}).get("mount_state") != "fault":
                    return
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # noqa: BLE001 - the fault is still there: wait, retry
                if getattr(exc, "code", "") != "mount_fault" or attempt == RESET_TRIES - 1:
                    raise
            await self.api.sleep_until(await self.api.now_us() + int(RESET_PAUSE_S * 1e6))

    def _faulted(self, rec: BlockRecord, exc: BaseException) -> BlockRecord:
        rec.outcome = "faulted"
        rec.error = {"code": getattr(exc, "code", "internal"), "message": str(exc)}
        self._faults[rec.target] += 1
        return rec

    async def _replan(self, reason: str) -> None:
        done = Counter(r.target for r in [*self.done_before, *self.records] if r.counts)
        given_up = {t for t, n in self._faults.items() if n >= MAX_FAULTS_PER_TARGET}
        targets = []
        for t in self.program.targets:
            left = t.repeats - done[t.name]
            if left > 0 and t.name not in given_up:
                targets.append(dataclasses.replace(t, repeats=left))
        now = await self.api.now_us()
        start = now + int(REPLAN_LEAD_S * 1e6)
        if not targets or start >= self.plan.end_us:
            self.plan = dataclasses.replace(self.plan, blocks=[])
        else:
            program = dataclasses.replace(self.program, targets=tuple(targets))
            new = await self.api.replan(program, start, self.plan.end_us,
                                        await self.api.place_deg())
            self.plan = dataclasses.replace(new, program_spec=self.plan.program_spec)
        self.replans.append({"at_us": now, "at_utc": iso_utc(now), "reason": reason,
                             "blocks": len(self.plan.blocks)})
        self._changed()

    def _target(self, name: str):
        for t in self.program.targets:
            if t.name == name:
                return t
        raise KeyError(f"the plan's block {name!r} is not in its program")

    # ------------------------------------------------------------------ reporting
    def as_dict(self) -> dict[str, Any]:
        return {"state": self.state, "program": self.plan.program,
                "started_us": self.started_us, "ended_us": self.ended_us,
                "started_utc": None if self.started_us is None else iso_utc(self.started_us),
                "ended_utc": None if self.ended_us is None else iso_utc(self.ended_us),
                "current": None if self.current is None else self.current.as_dict(),
                "records": [r.as_dict() for r in self.records],
                "done_before": [r.as_dict() for r in self.done_before],
                "replans": self.replans, "error": self.error,
                "plan": self.plan.as_dict(), "summary": run_summary(self.records)}

    def progress(self) -> dict[str, Any]:
        """What changed, in short (the `program` event): not the plan or every record."""
        return {"state": self.state, "program": self.plan.program,
                "current": None if self.current is None else self.current.as_dict(),
                "last": self.records[-1].as_dict() if self.records else None,
                "replans": len(self.replans), "summary": run_summary(self.records),
                "error": self.error}

    def _changed(self) -> None:
        self.on_change(self.progress())


class _EndedEarly(RuntimeError):
    code = "ended_early"


def run_summary(records: list[BlockRecord]) -> dict[str, Any]:
    """Counts per outcome, hours observed and on target, priority-weighted hours on target,
    worst tracking figures."""
    by = Counter(r.outcome for r in records)
    observed = [r for r in records if r.counts and r.start_us is not None and r.end_us]
    hours = sum((r.end_us - r.start_us) / 3.6e9 for r in observed)
    on_target = sum(r.on_target_s / 3600.0 for r in observed)
    weighted = sum(r.priority * r.on_target_s / 3600.0 for r in observed)

    def worst(key: str) -> float | None:
        values = [getattr(r, key) for r in observed if getattr(r, key) is not None]
        return max(values) if values else None

    return {"blocks": len(records),
            **{k: by.get(k, 0) for k in ("done", "degraded", "late", "missed", "faulted",
                                         "stopped")},
            "observed_hours": hours, "on_target_hours": on_target,
            "priority_weighted_hours": weighted,
            "worst_on_target_rms_arcsec": worst("on_target_rms_arcsec"),
            "worst_encoder_rms_arcsec": worst("encoder_rms_arcsec"),
            "worst_on_sky_rms_arcsec": worst("on_sky_rms_arcsec")}



