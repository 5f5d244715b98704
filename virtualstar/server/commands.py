"""The VSS commands: one parameter dataclass and one handler per command, in a table.

`COMMANDS[name] = Command(params_class, handler, doc)`. Parameters are checked
against the dataclass fields (unknown keys and wrong types are refused with the
list of valid ones) before the handler runs; handlers are thin calls into the
`Telescope`. docs/vss-api.md lists the same table for client authors.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import typing
import warnings
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from virtualstar.astro.constants import SIDEREAL_RATE_ARCSEC_S

from .exceptions import BadRequest, TargetUnreachable, UnknownCommand, VssError
from .operations import Phase
from .targets import parse_target
from .telescope import Operation, Telescope

__all__ = ["COMMANDS", "Command", "dispatch"]


@dataclass(frozen=True)
class NoParams:
    pass


@dataclass(frozen=True)
class TargetParams:
    radec: str | None = None
    ra_deg: float | None = None
    dec_deg: float | None = None
    star: str | None = None
    altaz: str | None = None
    az_deg: float | None = None
    el_deg: float | None = None
    allow_sun: bool = False  # operators only: ignore the Sun/Moon zones for this operation
    answer_on_accept: bool = False  # answer once the checks passed and the operation began

    @property
    def target_fields(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(TargetParams)
                if f.name not in ("allow_sun", "answer_on_accept")}


@dataclass(frozen=True)
class TrackParams(TargetParams):
    tle: str | None = None
    sat: str | None = None
    duration_s: float | None = None
    wait: bool = False
    max_wait_s: float | None = None
    closed_loop: bool = False  # guided by the guide camera (needs the server's --camera)


@dataclass(frozen=True)
class SampleParams(TargetParams):
    settle_s: float = 2.0


@dataclass(frozen=True)
class MoveParams:
    az_rate_deg_s: float = 0.0
    el_rate_deg_s: float = 0.0
    allow_sun: bool = False


#: ASCOM's default guide rate: half the sidereal rate (arcseconds of sky per second).
DEFAULT_GUIDE_RATE_ARCSEC_S = 0.5 * SIDEREAL_RATE_ARCSEC_S


@dataclass(frozen=True)
class GuideParams:
    north_arcsec: float = 0.0
    east_arcsec: float = 0.0
    rate_arcsec_s: float = DEFAULT_GUIDE_RATE_ARCSEC_S


@dataclass(frozen=True)
class OffsetParams:
    axis: str  # ra, dec, az, el, path, transverse (or all, with op=reset)
    op: str = "add"  # add, set, rate, reset
    arcsec: float | None = None  # arcsec (rate: arcsec/s)
    seconds: float | None = None  # path only: seconds of time (rate: s/s)


@dataclass(frozen=True)
class StopParams:
    reset_faults: bool = False


@dataclass(frozen=True)
class ParkParams:
    wait: bool = True


@dataclass(frozen=True)
class ModeParams:
    mode: str


@dataclass(frozen=True)
class ModelParams:
    path: str


@dataclass(frozen=True)
class ErrorsParams:
    from_us: int | None = None
    to_us: int | None = None
    series: bool = False
    max_points: int = 2000


@dataclass(frozen=True)
class WaitParams:
    id: int | None = None


@dataclass(frozen=True)
class RunPlanParams:
    plan: dict  # as `vs plan --json` writes it
    done: list | None = None  # the records of a run this one resumes
    wait: bool = False


@dataclass(frozen=True)
class Command:
    params: type
    handler: Callable[[Telescope, Any], Awaitable[Any]]
    doc: str


def _check(cls: type, params: dict[str, Any], cmd: str) -> Any:
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(params) - set(fields))
    if unknown:
        raise BadRequest(f"{cmd}: unknown parameters {unknown}; valid: {sorted(fields) or 'none'}")
    hints = typing.get_type_hints(cls)
    values = {}
    for name, f in fields.items():
        if name not in params:
            if f.default is dataclasses.MISSING:
                raise BadRequest(f"{cmd}: parameter {name!r} is required")
            continue
        value = params[name]
        hint = hints[name]
        allowed = typing.get_args(hint) or (hint,)
        if value is None and type(None) in allowed:
            values[name] = None
            continue
        if float in allowed and isinstance(value, int | float) and not isinstance(value, bool):
            if not math.isfinite(value):
                raise BadRequest(f"{cmd}: {name}={value!r} must be a finite number")
            values[name] = float(value) if int not in allowed else value
        elif _plain_match(value, allowed):
            values[name] = value
        else:
            expected = " or ".join(t.__name__ for t in allowed if t is not type(None))
            raise BadRequest(f"{cmd}: {name}={value!r} has the wrong type; expected {expected}")
    return cls(**values)


class OperationFailed(VssError):
    """An operation a request waited for ended in failure; carries the failure's code."""

    def __init__(self, message: str, code: str) -> None:
        super().__init__(message)
        self.code = code


def _plain_match(value: Any, allowed: tuple) -> bool:
    if isinstance(value, bool):
        return bool in allowed
    return any(kind in allowed and isinstance(value, kind) for kind in (int, str, dict, list))


async def _result(op: Operation, *, wait_done: bool, accepted: bool = False) -> dict[str, Any]:
    if accepted:  # the checks passed under the supervisor's lock: the operation is under way
        return op.as_dict()
    fut = op.done if wait_done else op.begun
    await asyncio.shield(fut)
    if op.phase in (Phase.FAILED, Phase.ABORTED):
        err = op.info.get("error", {})
        raise OperationFailed(err.get("message", "the operation failed"),
                              err.get("code", "internal"))
    return op.as_dict()


async def _ping(t: Telescope, p: NoParams) -> Any:
    return {"pong": True}


async def _status(t: Telescope, p: NoParams) -> Any:
    return await t.status()


async def _slew(t: Telescope, p: TargetParams) -> Any:
    target, name, fixed = parse_target(p.target_fields)
    if fixed is not None:
        op = await t.slew_altaz(*fixed, allow_sun=p.allow_sun)
    else:
        op = await t.follow_target(target, name, kind="slew", allow_sun=p.allow_sun)
    return await _result(op, wait_done=False, accepted=p.answer_on_accept)


async def _track(t: Telescope, p: TrackParams) -> Any:
    if p.duration_s is not None and not p.duration_s > 0:
        raise BadRequest(f"track: duration_s={p.duration_s} must be positive (seconds)")
    if p.tle is not None:
        if any(getattr(p, k) is not None for k in ("radec", "ra_deg", "star", "altaz", "az_deg")):
            raise BadRequest("track: give either a TLE or a sky target, not both")
        sat = _satellite(p.tle, p.sat)
        op = await t.track_satellite(sat, max_wait_s=p.max_wait_s, allow_sun=p.allow_sun,
                                     closed_loop=p.closed_loop)
        return await _result(op, wait_done=p.wait, accepted=p.answer_on_accept)
    if p.sat is not None:
        raise BadRequest("track: 'sat' selects a satellite inside 'tle'; no TLE was given")
    target, name, fixed = parse_target(p.target_fields)
    if fixed is not None:
        raise BadRequest("track: a fixed az/el does not move; use slew for it")
    op = await t.follow_target(target, name, kind="track", duration_s=p.duration_s,
                               allow_sun=p.allow_sun, closed_loop=p.closed_loop)
    return await _result(op, wait_done=p.wait, accepted=p.answer_on_accept)


def _satellite(tle: str, name: str | None):
    from catalogs import parse_tle_text
    from catalogs.exceptions import CatalogError
    from virtualstar.astro import Satellite
    from virtualstar.astro.exceptions import AstroError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            records = parse_tle_text(tle, "the TLE text")
    except CatalogError as exc:
        raise BadRequest(str(exc)) from None
    if not records:
        raise BadRequest("the TLE text holds no satellite: expected a name line and two "
                         "element lines (1 ..., 2 ...)")
    if name is not None:
        key = name.strip().lower()
        chosen = [r for r in records if r.name.strip().lower() == key] or \
                 [r for r in records if key in r.name.strip().lower()]
        if not chosen:
            raise TargetUnreachable(f"no satellite named {name!r} in the TLE; it holds: "
                                    f"{', '.join(r.name.strip() for r in records[:20])}")
        record = chosen[0]
    else:
        record = records[0]
    try:
        return Satellite.from_record(record)
    except AstroError as exc:
        raise BadRequest(str(exc)) from None


async def _pointing_sample(t: Telescope, p: SampleParams) -> Any:
    target, name, fixed = parse_target(p.target_fields)
    if fixed is not None:
        from virtualstar.astro import FixedAltAz

        target = FixedAltAz(fixed[0] % 360.0, fixed[1])
    op = await t.pointing_sample(target, name, settle_s=p.settle_s, allow_sun=p.allow_sun)
    done = await _result(op, wait_done=True)
    return {"id": done["id"], **done["info"]["sample"]}


async def _move(t: Telescope, p: MoveParams) -> Any:
    op = await t.move(p.az_rate_deg_s, p.el_rate_deg_s, allow_sun=p.allow_sun)
    return await _result(op, wait_done=False)


async def _guide(t: Telescope, p: GuideParams) -> Any:
    return await t.guide(p.north_arcsec, p.east_arcsec, p.rate_arcsec_s)


async def _offset(t: Telescope, p: OffsetParams) -> Any:
    return await t.steering.offset(p.axis, p.op, arcsec=p.arcsec, seconds=p.seconds)


async def _stop(t: Telescope, p: StopParams) -> Any:
    return await t.stop(reset_faults=p.reset_faults)


async def _reset(t: Telescope, p: NoParams) -> Any:
    return await t.stop(reset_faults=True)


async def _park(t: Telescope, p: ParkParams) -> Any:
    op = await t.park()
    return await _result(op, wait_done=p.wait) if p.wait else op.as_dict()


async def _mode(t: Telescope, p: ModeParams) -> Any:
    return await t.set_mode(p.mode)


async def _load(t: Telescope, p: ModelParams) -> Any:
    return t.load_model(p.path)


async def _unload(t: Telescope, p: NoParams) -> Any:
    return t.unload_model()


async def _errors(t: Telescope, p: ErrorsParams) -> Any:
    out: dict[str, Any] = {"stats": t.errors.stats(p.from_us, p.to_us).as_dict(),
                           "samples": t.errors.samples}
    if p.series:
        out["series"] = t.errors.series(p.from_us, p.to_us, max(1, p.max_points))
    return out


async def _wait(t: Telescope, p: WaitParams) -> Any:
    op = t.op
    if op is None or (p.id is not None and op.id != p.id):
        raise BadRequest(f"no running operation {p.id if p.id is not None else ''}".strip()
                         + (f"; the current one is {op.id}" if op else "; nothing is running"))
    return await _result(op, wait_done=True)


async def _run_plan(t: Telescope, p: RunPlanParams) -> Any:
    doc = await t.programs.start(p.plan, p.done, lambda cmd, params: execute(t, cmd, params))
    return await t.programs.wait() if p.wait else doc


async def _program(t: Telescope, p: NoParams) -> Any:
    return t.programs.status()


@dataclass(frozen=True)
class LogParams:
    since: int = 0  # the last seq the client has seen
    limit: int = 1000


async def _log(t: Telescope, p: LogParams) -> Any:
    if p.since < 0 or not 1 <= p.limit <= 10_000:
        raise BadRequest(f"log: since must be >= 0 and limit 1..10000, got since={p.since}, "
                         f"limit={p.limit}")
    events = t.log.since(p.since)[: p.limit]
    return {"events": [e.as_dict() for e in events], "last_seq": t.log.last_seq}


COMMANDS: dict[str, Command] = {
    "ping": Command(NoParams, _ping, "Answer at once (liveness)."),
    "status": Command(NoParams, _status, "Positions, RA/Dec, states, errors, mount time."),
    "slew": Command(TargetParams, _slew, "Slew to a target; sky targets are then tracked. "
                    "Answers when landed."),
    "track": Command(TrackParams, _track, "Track a sky target or a satellite pass; answers "
                     "when tracking has begun (satellite: when the pass is planned), or at the "
                     "end with wait=true."),
    "pointing_sample": Command(SampleParams, _pointing_sample, "Point at a target, hold, and "
                               "measure the star's offset with the guide camera (needs the "
                               "guide_measure role); answers with star, encoder, offset and "
                               "on-axis places."),
    "move": Command(MoveParams, _move, "Turn the axes at az_rate_deg_s / el_rate_deg_s (a hand "
                    "pad) until stop, another command, or just before a limit or zone; answers "
                    "once moving."),
    "guide": Command(GuideParams, _guide, "A guide pulse: offset the sky target being tracked "
                     "by north_arcsec / east_arcsec at rate_arcsec_s; answers with when the pulse "
                     "runs (mount µs) and the total offset."),
    "offset": Command(OffsetParams, _offset, "Offset the running track (PWI4-style): axis ra, "
                      "dec, az, el (arcsec), path (seconds of time, or arcsec along the track), "
                      "transverse (arcsec across it); op add, set, rate (per second) or reset; "
                      "applied gradually within the offset limits from 20 ms after acceptance "
                      "(replace_from); answers with from_us, reached_us, lead_ms and the "
                      "offsets."),
    "stop": Command(StopParams, _stop, "Stop the operation, bring the mount to rest; "
                    "reset_faults=true also clears latched faults."),
    "reset_faults": Command(NoParams, _reset, "Stop and clear the mount's latched faults."),
    "park": Command(ParkParams, _park, "Slew to the park position and power off."),
    "set_mode": Command(ModeParams, _mode, "mode=active (commands move the mount) or passive "
                        "(watch only)."),
    "load_model": Command(ModelParams, _load, "Load a pointing model: JSON or a TPOINT .mod file (server side path)."),
    "unload_model": Command(NoParams, _unload, "Drop the pointing model."),
    "errors": Command(ErrorsParams, _errors, "Tracking-error RMS and peak over a mount-time "
                      "window; series=true adds per-bin values."),
    "wait": Command(WaitParams, _wait, "Wait until the running operation ends; return its summary."),
    "run_plan": Command(RunPlanParams, _run_plan, "Run a plan (vs plan's JSON) block by block, "
                        "re-planning after a missed, late or faulted block; answers when it "
                        "has begun, or at its end with wait=true."),
    "program": Command(NoParams, _program, "The program run: state, current block, the "
                       "blocks done with their tracking figures, re-plans, the plan."),
    "log": Command(LogParams, _log, "The server's event log after seq `since` (at most "
                   "`limit`): operations and phases, faults, safety actions, commands with "
                   "their client and role, connections; {events, last_seq}."),
}

# Commands that move the mount or change who drives it: they end a running program first.
ENDS_PROGRAM = frozenset({"slew", "track", "stop", "reset_faults", "park", "pointing_sample",
                          "set_mode", "move"})


async def dispatch(telescope: Telescope, cmd: str, params: dict[str, Any], *,
                   ends_program: bool = True) -> Any:
    """Check parameters and run one command; raise VssError subclasses for the client.

    A client's command that moves the mount ends a running program first; the program's
    own commands (`execute`) do not.
    """
    command = COMMANDS.get(cmd)
    if command is None:
        raise UnknownCommand(f"unknown command {cmd!r}; valid commands: {', '.join(COMMANDS)}")
    checked = _check(command.params, params, cmd)
    if ends_program and cmd in ENDS_PROGRAM and telescope.programs.running:
        await telescope.programs.cancel(f"ended by a client's {cmd}")
    return await command.handler(telescope, checked)


async def execute(telescope: Telescope, cmd: str, params: dict[str, Any]) -> Any:
    """Run a command for the server's own program run (it does not end the program)."""
    return await dispatch(telescope, cmd, params, ends_program=False)
